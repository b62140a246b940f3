"""Fixtures shared by the tests: the cells and their roadmaps."""

import os
from pathlib import Path

import pytest

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.roadmap.cache import load_or_build

CELL_DIR = Path(__file__).resolve().parent / 'support' / 'cells'
CELL_FILES = {'default': default_cell_path(), 'pillar': CELL_DIR / 'pillar.yaml',
              'notched': CELL_DIR / 'notched.yaml'}


def pytest_configure(config):
    """
    Give each pytest-xdist worker a DDS domain of its own, for every node it starts.

    Without workers, ``isolate_dds`` picks one domain (10..89) for the run; each worker takes
    its own in that range, so that the nodes of two workers never meet. The second domains a
    few files choose (130.., 200..) never meet either: a file runs on one worker (loadfile).
    """
    worker = os.environ.get('PYTEST_XDIST_WORKER')
    if worker:
        count = int(os.environ['PYTEST_XDIST_WORKER_COUNT'])
        run = os.getppid() % (80 // count)  # the controller's process, shared by its workers
        os.environ['ROS_DOMAIN_ID'] = str(10 + run * count + int(worker.removeprefix('gw')))


@pytest.fixture(scope='session', params=sorted(CELL_FILES))
def cell(request) -> Cell:
    """Yield each test cell in turn."""
    return Cell.from_yaml(CELL_FILES[request.param])


@pytest.fixture(scope='session')
def default_cell_file() -> Path:
    """Return the packaged default cell file."""
    return default_cell_path()


@pytest.fixture(scope='session')
def default_cell() -> Cell:
    """Return the packaged default cell."""
    return Cell.from_yaml(default_cell_path())


@pytest.fixture(scope='session')
def roadmap_cache(tmp_path_factory) -> Path:
    """Return a roadmap cache shared by the session (each roadmap is built once)."""
    return tmp_path_factory.mktemp('roadmaps')


@pytest.fixture(scope='session')
def roadmap(cell, roadmap_cache):
    """Return the roadmap of each test cell, default settings: 1500 nodes, seed 0."""
    return load_or_build(cell, cache_dir=roadmap_cache).roadmap


@pytest.fixture(scope='session')
def default_roadmap(default_cell, roadmap_cache):
    """Return the default-settings roadmap of the default cell."""
    return load_or_build(default_cell, cache_dir=roadmap_cache).roadmap


@pytest.fixture(scope='session')
def default_planner(default_cell, default_roadmap):
    """Return the default cell's planner (its default limit set: loaded)."""
    return Planner(default_cell, default_roadmap)


@pytest.fixture(scope='session')
def station_move(default_planner):
    """Return the loaded move loadport1 -> loadlock2 of the default cell, verified."""
    return default_planner.plan('loadport1', 'loadlock2')


@pytest.fixture(scope='module')
def harness(roadmap_cache, tmp_path_factory):
    """Yield a running node on the default cell (roadmap from the session cache), per module."""
    from node_harness import Harness, isolate_dds  # ROS only for the tests that use it
    isolate_dds(tmp_path_factory.mktemp('dds'))
    running = Harness({'roadmap.cache_dir': str(roadmap_cache), 'planning.timeout': 30.0,
                       'recording.directory': str(tmp_path_factory.mktemp('recordings'))})
    yield running
    running.close()


@pytest.fixture(autouse=True)
def _parameters_restored(request):
    """Put back, after each test on the shared node, every parameter the test changed."""
    if 'harness' not in request.fixturenames:
        yield
        return
    from rclpy.parameter import Parameter
    from wafer_planner_ros.service.settings import PARAMETERS
    node = request.getfixturevalue('harness').node
    before = {p.name: node.get_parameter(p.name).value for p in PARAMETERS}
    yield  # whether the test passed or failed: a failure must not spill into the next test
    changed = [Parameter(name, value=value) for name, value in before.items()
               if node.get_parameter(name).value != value]
    if changed:
        assert all(r.successful for r in node.set_parameters(changed))
