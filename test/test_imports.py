"""One-way imports: the layers and the ROS-free core, as setup.cfg's contracts state them."""

from pathlib import Path

from importlinter.cli import lint_imports

SETUP_CFG = Path(__file__).resolve().parents[1] / 'setup.cfg'


def test_import_contracts_are_kept(capsys):
    # An upward import, rclpy or a message package imported by the core, or numba imported
    # anywhere but in kernels (which imports it when a kernel is first called) breaks one.
    code = lint_imports(config_filename=str(SETUP_CFG), no_cache=True, no_logo=True)
    out = capsys.readouterr().out
    assert code == 0, out
    assert 'Contracts: 3 kept, 0 broken.' in out
