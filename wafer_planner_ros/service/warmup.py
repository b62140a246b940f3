"""
The compiled kernels made ready before anything is planned.

``compile_kernels`` runs every compiled kernel of the package on a small workload on the
packaged default cell, so that numba compiles each one for this machine and keeps it in its
cache (``kernels.cache_root``): reading a cell with its polygons checked compiled, building
a small roadmap, planning a station pair and a joint pair by each curve method, verifying,
proving (a curve and the same curve backwards, as the station table answers the way
back), stopping a move and naming contacts. ``wafer-kernels`` runs it once after an install (the
README's set-up does) and builds the signatures numba then holds ahead of time (``kernels_ahead``);
the node and the tools then only load the kernels (``kernels_lookup.load_ahead``, milliseconds, or
``kernels.load_cached``, about a second), and ``node.startup.kernels_ready`` is what the
node does at start-up: load them, and compile the missing ones only if some are missing
(after an upgrade of the package, or on another machine).
"""

from dataclasses import replace
import time
from typing import Callable, Optional

import numpy as np

from wafer_planner_ros import kernels
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.geometry import polygons
from wafer_planner_ros.geometry.contacts import body_contacts
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service import table  # noqa: F401 - its kernels count too
from wafer_planner_ros.trajectory.methods import KnotTiming, WholeCurve
from wafer_planner_ros.trajectory.verify import verify

WARM_NODES = 150
"""Roadmap nodes of the workload: enough to plan on, quick to build."""
JOINT_PAIR = ((-1.2, 2.4, 1.3), (1.0, -2.0, -1.0))
"""A joint request of the workload (free in the default cell)."""


def compile_kernels(progress: Optional[Callable[[str], None]] = None) -> dict:
    """
    Compile (or load) every kernel on the workload; return what it took.

    ``progress(step)`` is called before each step. Returns ``kernels`` (registered),
    ``signatures`` (compiled or loaded), ``compiled`` (not found in the cache), ``seconds``
    and ``cache`` (where numba keeps them).
    """
    say = progress or (lambda step: None)
    begun, before = time.monotonic(), kernels.compiled_count()
    say('loading what is cached')
    kernels.load_cached()
    say('the cell: polygon checks')
    cell = Cell.from_yaml(default_cell_path())
    compiled = (lambda k: k)
    inner = 0.1 * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    for polygon in (cell.boundary, *cell.obstacles):
        polygons.simple_polygon(polygon, form=compiled)
        polygons.touches_or_overlaps(cell.boundary, polygon, form=compiled)
        # One inside the other, no edge meeting: the point-in-polygon test runs too.
        polygons.touches_or_overlaps(polygon, inner + polygon.mean(axis=0), form=compiled)
    say('a roadmap: sampling, clearance, certified edges')
    roadmap = load_or_build(cell, RoadmapSettings(nodes=WARM_NODES), cache_dir=None).roadmap
    stations = sorted(cell.stations)
    for method, budget in ((KnotTiming, None), (WholeCurve, None)):
        say(f'planning by {method.name}')
        planner = Planner(cell, roadmap, replace(PlannerSettings(), method=method))
        for start, goal in ((stations[0], stations[-1]), JOINT_PAIR):
            try:
                result = planner.plan(start, goal, budget=budget)
            except PlanningError:
                continue  # a workload plan that fails has still run its kernels
            body_contacts(cell.clearance_model, result.positions[len(result.positions) // 2])
            # The way back, as the station table answers it.
            verify(result.trajectory.backwards(), cell, result.goal_q, result.start_q)
            # A controlled stop of it, as the node answers a stop request.
            try:
                planner.stop(result.trajectory, 0.3 * result.cycle_time)
            except PlanningError:
                pass  # a workload stop that fails has still run its kernels
    say('contacts')
    body_contacts(cell.clearance_model, np.asarray(JOINT_PAIR[0]))
    return {'kernels': len(kernels.registered()),
            'signatures': sum(len(k.signatures()) for k in kernels.registered()),
            'compiled': kernels.compiled_count() - before,
            'seconds': time.monotonic() - begun, 'cache': str(kernels.cache_root())}
