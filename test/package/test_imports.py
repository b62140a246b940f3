"""One-way imports as setup.cfg's contracts state them (layers, a ROS-free core); small modules."""

from pathlib import Path

from importlinter.cli import lint_imports
import pytest

SETUP_CFG = Path(__file__).resolve().parents[2] / 'setup.cfg'


@pytest.mark.linter
def test_import_contracts_are_kept(capsys):
    # An upward import, rclpy or a message package imported by the core, or numba imported
    # anywhere but in kernels (which imports it when a kernel is first called) breaks one.
    code = lint_imports(config_filename=str(SETUP_CFG), no_cache=True, no_logo=True)
    out = capsys.readouterr().out
    assert code == 0, out
    assert 'Contracts: 3 kept, 0 broken.' in out


MAX_MODULE_LINES = 450
"""A module past this is holding more than one job: split it along a concept."""


@pytest.mark.linter
def test_no_module_is_longer_than_one_job_needs():
    package = SETUP_CFG.parent / 'wafer_planner_ros'
    long = {str(path.relative_to(package.parent)): lines
            for path in sorted(package.rglob('*.py'))
            if (lines := len(path.read_text().splitlines())) > MAX_MODULE_LINES}
    assert not long, f'modules over {MAX_MODULE_LINES} lines: {long}'
