"""Compiled kernels loaded on first use: the node reads its cell without numba, same answers."""

import logging
import os
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

from wafer_planner_ros import kernels
from wafer_planner_ros.geometry import clearance
from wafer_planner_ros.kernels import kernel, objmode
from wafer_planner_ros.node import startup
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings

ROOT = Path(__file__).resolve().parents[2]


@kernel(nogil=True)
def _inner(x):
    return 2.0 * x


@kernel
def _outer(values):
    total = 0.0
    for v in values:
        with objmode(bumped='float64'):
            bumped = float(v) + 0.5  # Python in compiled code, as predicates.orient does
        total += _inner(bumped)
    return total


def test_a_kernel_calls_kernels_compiled_and_interpreted_alike():
    values = np.array([1.0, 2.5, -4.0])
    assert _outer(values) == _outer.interpreted(values) == 2.0 * (values + 0.5).sum()
    assert type(_outer.compiled).__name__ == 'CPUDispatcher'
    assert kernels.loaded()


def test_reading_the_cell_and_loading_the_roadmap_need_no_numba(default_cell, tmp_path):
    # The node is ready once its cell is read and its roadmap loaded: none of that may wait
    # for numba (0.3 s to import and load its first kernel).
    load_or_build(default_cell, RoadmapSettings(nodes=60), 0, tmp_path)
    script = (
        'import sys\n'
        'from wafer_planner_ros.node import planner_node\n'
        'from wafer_planner_ros.cell.document import read_cell_file\n'
        'from wafer_planner_ros.cell.model import Cell, default_cell_path\n'
        'from wafer_planner_ros.planner import Planner, PlannerSettings\n'
        'from wafer_planner_ros.roadmap.cache import load_or_build\n'
        'from wafer_planner_ros.roadmap.graph import RoadmapSettings\n'
        'cell = Cell.from_text(read_cell_file(default_cell_path()), "cell")\n'
        f'cached = load_or_build(cell, RoadmapSettings(nodes=60), 0, {str(tmp_path)!r})\n'
        'Planner(cell, cached.roadmap, PlannerSettings())\n'
        'print(cached.status.value, *sorted(m for m in sys.modules\n'
        '                                   if m.split(".")[0] in ("numba", "scipy")))\n')
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, '-c', script], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    status, *loaded = out.stdout.split()
    assert status == 'hit'
    assert not [m for m in loaded if m == 'numba' or m.startswith('scipy.optimize')], loaded


def test_station_clearances_interpreted_equal_compiled(default_cell):
    model = default_cell.clearance_model
    rng = np.random.default_rng(3)
    low, high = default_cell.robot.limits.position.T
    q = np.ascontiguousarray(rng.uniform(low, high, size=(7, 3)))
    args = (q, np.asarray(model.arm.base, float), np.asarray(model.arm.link_lengths, float),
            model.edge_start, model.edge_end, model._edge_len_sq, model._base_dist)
    for per_edge in (False, True):
        compiled = clearance._spine_distances(*args, per_edge)
        interpreted = clearance._spine_distances.interpreted(*args, per_edge)
        assert np.array_equal(compiled, interpreted)


def test_kernels_being_compiled_are_announced_with_progress(monkeypatch, caplog):
    @kernel(cache=False)  # never cached: compiled whenever it is first called
    def fresh(x):
        return np.sin(x) * np.cos(x) + x ** 3

    monkeypatch.setattr(startup, 'ANNOUNCE_AFTER', 0.0)
    monkeypatch.setattr(startup, 'ANNOUNCE_EVERY', 0.01)
    logger = logging.getLogger('test_kernels')
    with caplog.at_level(logging.INFO, logger='test_kernels'):
        with startup.kernels_announced(logger):
            assert fresh(0.5) == np.sin(0.5) * np.cos(0.5) + 0.125
            time.sleep(0.2)  # the rest of the loading, while progress is logged
        with startup.kernels_announced(logger):
            fresh(0.25)  # compiled already: only loaded
    lines = [r.getMessage() for r in caplog.records]
    assert any(line.startswith('compiling the planning kernels for this machine')
               for line in lines), lines
    assert any(line.startswith('compiling the planning kernels: 1 compiled so far, ')
               for line in lines), lines
    assert any(line.startswith('planning kernels compiled: 1 in ') for line in lines), lines
    assert lines[-1].startswith('planning kernels loaded in ')
