"""Every module the package imports is declared for a standard ROS install, with the pins of CI."""

import ast
from pathlib import Path
import re
import sys
import xml.etree.ElementTree as ElementTree

ROOT = Path(__file__).resolve().parents[2]
# The module each package.xml key or requirements-ros.txt entry provides.
PROVIDES = {
    'rclpy': ['rclpy'], 'std_msgs': ['std_msgs'], 'std_srvs': ['std_srvs'],
    'trajectory_msgs': ['trajectory_msgs'], 'visualization_msgs': ['visualization_msgs'],
    'diagnostic_msgs': ['diagnostic_msgs'], 'geometry_msgs': ['geometry_msgs'],
    'sensor_msgs': ['sensor_msgs'],
    'builtin_interfaces': ['builtin_interfaces'], 'rcl_interfaces': ['rcl_interfaces'],
    'tf2_msgs': ['tf2_msgs'], 'ament_index_python': ['ament_index_python'],
    'launch': ['launch'], 'launch_ros': ['launch_ros'], 'python3-numpy': ['numpy'],
    'python3-scipy': ['scipy'], 'python3-numba': ['numba'], 'python3-yaml': ['yaml'],
    'python3-matplotlib': ['matplotlib'], 'python3-pil': ['PIL'],
    'mcap-ros2-support': ['mcap', 'mcap_ros2'], 'python3-pytest': ['pytest'],
    'python3-hypothesis': ['hypothesis'], 'python3-websockets': ['websockets'],
    'python3-rosbags-pip': ['rosbags'], 'python-fcl-pip': ['fcl'],
    'ament_flake8': ['ament_flake8'], 'ament_pep257': ['ament_pep257'],
    'daqp': ['daqp'], 'ruckig': ['ruckig'], 'threadpoolctl': ['threadpoolctl'],
    'shapely': ['shapely'],
    'import-linter': ['importlinter'], 'foxglove-sdk': ['foxglove'], 'websockets': ['websockets'],
    'python-fcl': ['fcl'], 'mcap': ['mcap'], 'rosbags': ['rosbags'],
    'tf2_ros': [], 'ray': ['ray'], 'optuna': ['optuna'],
}


def _pins(path: Path) -> dict:
    pins = {}
    for line in path.read_text().splitlines():
        match = re.match(r'^([A-Za-z0-9_.\[\]-]+)\s*==\s*(\S+)', line.split('#')[0].strip())
        if match:
            pins[match[1].split('[')[0].lower()] = match[2]
    return pins


def _imported(folder: Path) -> set:
    names = set()
    for path in folder.rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - {'wafer_planner_ros'}


def test_requirements_for_a_ros_install_are_pinned_as_ci_tests_them():
    ci, ros = _pins(ROOT / 'requirements.txt'), _pins(ROOT / 'requirements-ros.txt')
    assert ros, 'requirements-ros.txt pins nothing'
    assert {name: pin for name, pin in ros.items() if ci.get(name) != pin} == {}


def test_every_imported_module_is_declared_for_a_ros_install():
    manifest = ElementTree.parse(ROOT / 'package.xml').getroot()
    run = {e.text for e in manifest if e.tag == 'exec_depend'}
    test = {e.text for e in manifest if e.tag == 'test_depend'}
    pip = set(_pins(ROOT / 'requirements-ros.txt'))
    unknown = (run | test | pip) - set(PROVIDES)
    assert not unknown, f'say in PROVIDES which module these give: {sorted(unknown)}'
    by_run = {m for key in run | pip for m in PROVIDES[key]}
    by_test = by_run | {m for key in test for m in PROVIDES[key]}
    local = {p.stem for p in (ROOT / 'test').rglob('*.py')}
    assert sorted(_imported(ROOT / 'wafer_planner_ros') - by_run) == []
    assert sorted(_imported(ROOT / 'launch') - by_run) == []
    assert sorted(_imported(ROOT / 'test') - by_test - local) == []
