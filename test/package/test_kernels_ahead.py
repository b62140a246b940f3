"""The kernels built ahead of time: loaded without numba, the same answers, the GIL released."""

import json
import logging
import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from wafer_planner_ros import kernels, kernels_ahead, kernels_keys, kernels_lookup
from wafer_planner_ros.node import startup
from wafer_planner_ros.service import warmup  # noqa: F401 - every kernel, as the node has them
from wafer_planner_ros.trajectory import bspline

ROOT = Path(__file__).resolve().parents[2]

_PLAN = """
import json, sys, threading, time
import numpy as np
import pytest
from wafer_planner_ros import kernels, kernels_lookup
from wafer_planner_ros.service import warmup
loaded = kernels_lookup.load_ahead() if sys.argv[1] == 'ahead' else kernels.load_cached()
from dataclasses import replace
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.trajectory import bspline
cell = Cell.from_yaml(default_cell_path())
roadmap = load_or_build(cell, RoadmapSettings(nodes=150), cache_dir=None).roadmap
found = {'loaded': loaded, 'plans': {}}
for method in ('knot-timing', 'whole-curve'):
    planner = Planner(cell, roadmap, replace(PlannerSettings(), method=method))
    for start, goal in (('loadport1', 'loadlock2'), ((-1.2, 2.4, 1.3), (1.0, -2.0, -1.0))):
        result = planner.plan(start, goal)
        found['plans'][f'{method} {start}'] = [result.trajectory.knots.tolist(),
                                               result.trajectory.control_points.tolist()]
found['numba_after_planning'] = 'numba' in sys.modules
# A small check runs the built kernel, not the kernel as Python (slower tenfold on a
# roadmap's build); one not built runs as Python while numba is not loaded.
from wafer_planner_ros.geometry import clearance, polygons
found['small_checks_compiled'] = [
    kernels.sized(1, 10)(k) is k for k in (clearance._spine_distances, polygons._inside)]
# A kernel made with nogil=True lets other threads run while it computes: this thread
# wakes from a short sleep while the kernel is still running (a held lock would keep it
# asleep until the call ends, hundreds of times longer).
big, inside, done = np.random.default_rng(0).random(20_000_000), threading.Event(), []
def run():
    inside.set()
    bspline.knots_from_intervals(big)
    done.append(True)
worker = threading.Thread(target=run)
worker.start()
inside.wait()
time.sleep(0.005)
found['woke_while_running'] = not done
worker.join()
print(json.dumps(found))
"""


def _plan(source: str) -> dict:
    out = subprocess.run([sys.executable, '-c', _PLAN, source], capture_output=True,
                         text=True, timeout=600, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.mark.slow
def test_the_build_loads_without_numba_plans_as_numba_does_and_releases_the_gil():
    # The set-up (wafer-kernels) built them for this machine.
    assert (kernels_lookup.ahead_directory() / kernels_keys.AHEAD_MANIFEST).exists(), \
        f'no build in {kernels_lookup.ahead_directory()}: run wafer-kernels'
    ahead, cached = _plan('ahead'), _plan('cached')
    assert ahead['loaded'] > 0 and cached['loaded'] > 0
    # Both methods, a station pair and a joint pair, the roadmap built: no numba at all.
    assert not ahead['numba_after_planning']
    assert cached['numba_after_planning']
    assert ahead['plans'] == cached['plans']  # the same curves, to the last bit
    assert ahead['small_checks_compiled'] == [True, False]
    assert cached['small_checks_compiled'] == [True, True]
    assert ahead['woke_while_running'] and cached['woke_while_running']


def test_a_call_of_types_not_built_runs_numba_with_the_same_answer():
    script = """
import sys
import numpy as np
import pytest
from wafer_planner_ros import kernels, kernels_keys, kernels_lookup
from wafer_planner_ros.service import warmup
from wafer_planner_ros.trajectory import bspline
assert kernels_lookup.load_ahead() > 0
intervals = np.array([0.5, 0.25, 0.75, 1.0, 0.125, 2.0])
# Built for a writeable C-ordered float64 vector only (numba's cache may hold more, which
# a build takes too): every other type is not built.
table = bspline.knots_from_intervals._ahead
key = kernels_keys.argument_types((intervals,))
bspline.knots_from_intervals._ahead = {key: table[key]}
built = bspline.knots_from_intervals(intervals)
print('numba' in sys.modules)
frozen = intervals.copy()
frozen.flags.writeable = False  # readonly: another type to numba
others = [frozen, intervals[::2], intervals.astype(np.float32)]
answers = [bspline.knots_from_intervals(a) for a in others]
print('numba' in sys.modules)
print(all(np.array_equal(a, bspline.knots_from_intervals(np.ascontiguousarray(o, float)))
          for a, o in zip(answers, others)))
print(np.array_equal(built, bspline.knots_from_intervals.interpreted(intervals)))
"""
    out = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                         timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['False', 'True', 'True', 'True']


def test_argument_types_are_exact():
    a = np.zeros((3, 2))
    frozen = a.copy()
    frozen.flags.writeable = False
    assert kernels_keys.argument_types((a, 1.0, 2, True)) == (
        ('<f8', 2, 'C', False, True), 'float64', 'int64', 'bool')
    assert kernels_keys.argument_types((a.T,))[0][2] == 'F'
    assert kernels_keys.argument_types((a[:, 0],))[0][2] == 'A'
    assert kernels_keys.argument_types((frozen,))[0][3] is True
    assert kernels_keys.argument_types((np.float32(1.0),)) is None
    assert kernels_keys.argument_types(([1.0],)) is None


def test_the_polygon_kernels_are_left_to_numba_and_the_rest_built():
    built, left = kernels_ahead.buildable(kernels.registered())
    left_names = {k.__qualname__ for k in left}
    # They reach the exact orientation test's Python slow path (objmode).
    assert {'orient', '_inside', '_first_intersection'} <= left_names
    assert {'knots_from_intervals', 'wafer_rows', '_astar', '_spine_distances'} <= {
        k.__qualname__ for k in built}


def test_a_build_of_other_kernels_or_a_broken_manifest_is_not_loaded(tmp_path, monkeypatch):
    monkeypatch.setenv('NUMBA_CACHE_DIR', str(tmp_path))
    with pytest.raises(kernels_lookup.NoBuildAhead, match='none built for this machine'):
        kernels_lookup.load_ahead()
    manifest = kernels_lookup.ahead_directory() / kernels_keys.AHEAD_MANIFEST
    manifest.parent.mkdir(parents=True)
    manifest.write_text('{not json')
    with pytest.raises(OSError, match='is not a build manifest'):
        kernels_lookup.load_ahead()
    modules = ['wafer_planner_ros.trajectory.bspline']
    manifest.write_text(json.dumps({'file': 'absent.so', 'modules': modules, 'kernels': {},
                                    'digest': kernels_lookup.kernels_digest(modules)}))
    with pytest.raises(ImportError):  # what it names is not there
        kernels_lookup.load_ahead()
    # A constant a kernel uses changed: the kernels' code is not what was built.
    monkeypatch.setattr(bspline, 'WINDOW', bspline.WINDOW + 1)
    with pytest.raises(kernels_lookup.NoBuildAhead, match='the kernels changed since the build'):
        kernels_lookup.load_ahead()
    manifest.write_text(json.dumps({'file': 'absent.so', 'modules': ['wafer_planner_ros.gone'],
                                    'kernels': {}, 'digest': ''}))
    with pytest.raises(kernels_lookup.NoBuildAhead, match='no longer has'):
        kernels_lookup.load_ahead()


def test_the_node_loads_numbas_cache_when_the_build_does_not_load(monkeypatch, caplog):
    def broken():
        raise ImportError('a build that does not load')

    monkeypatch.setattr(kernels_lookup, 'load_ahead', broken)
    loading = startup._KernelLoading()
    logger = logging.getLogger('test_kernels_ahead')
    with caplog.at_level(logging.INFO, logger='test_kernels_ahead'):
        loading.ready(logger, lambda: None)
    lines = [r.getMessage() for r in caplog.records]
    assert any('could not be loaded: a build that does not load' in line for line in lines)
    assert loading.ahead == 0 and loading.loaded > 0
    assert lines[-1].startswith('planning kernels loaded in '), lines


def test_a_module_of_kernels_added_since_a_build_has_it_built_again():
    # A build's manifest checks only the modules it lists: one added later must count.
    modules = sorted({k.__module__ for k in kernels_ahead.buildable(kernels.registered())[0]})
    assert 'wafer_planner_ros.trajectory.braking' in modules
    assert kernels_ahead.unlisted({'modules': modules}) == []
    older = [m for m in modules if m != 'wafer_planner_ros.trajectory.braking']
    assert kernels_ahead.unlisted({'modules': older}) == ['wafer_planner_ros.trajectory.braking']
