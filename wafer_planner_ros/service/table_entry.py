"""
A station table's entry: one pair's plan as plain data, and how an untrusted one is read.

An entry keeps what an answer needs of a plan (``plan_entry``): the branches, the curve's
description, the λ-scaled start's cycle time, the paths behind the curve, the warnings and
planning counts; never a figure of its verification. A pair whose reverse is planned gets
that entry backwards in time (``reversed_entry``), verified again.

A table file is not trusted: its digest guards against damage, not against a deliberate
edit. So every entry read from one is verified in full as if just planned
(``verified_entry``: well formed and at rest exactly on its two stations on the branches it
names, every limit, the proof and the dense collision check over all of [0, T]; a curve over
``MAX_DURATION`` is rejected before, since checking costs time and memory in proportion to
its length). What an answer reports (``entry_result``) is that verification and what it
measures on the curve (its method, lengths, counts of points), never a figure of the
file's; the rest it takes from the entry is checked for what it can be (``_described``).
"""

import time
from typing import Tuple

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import answer, Planner, PlanResult
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.verify import Verification, verify

MAX_DURATION = 60.0
"""s: a stored curve longer than this is rejected before it is checked (the planner's
station moves take seconds; checking a curve costs time and memory in proportion to it)."""
MAX_ITEMS = 10000
"""Most vertices of a stored path, or warnings or counts of an entry."""
MAX_TEXT = 1000
"""Most characters of a stored warning or count's name."""
MEASURED = ('method', 'roadmap_path_vertices', 'path_vertices', 'control_points', 'branches',
            'joint_path_length', 'wafer_path_length')
"""Metrics an answer from the table measures on what it answers with, never read."""


def plan_entry(result: PlanResult) -> dict:
    """Return what the table keeps of a plan (plain data; an answer's ``source`` is not)."""
    metrics = {name: value for name, value in result.metrics.items() if name != 'source'}
    return _stored(result.branches, result.trajectory, result.initial_cycle_time,
                   result.roadmap_path, result.path, metrics, result.warnings,
                   result.timings_ms['total'])


def reversed_entry(planner: Planner, pair, entry: dict) -> Tuple[dict, Verification]:
    """Return the entry of ``pair`` from that of its reverse (backwards) and its verification."""
    begun = time.perf_counter()
    trajectory = entry_curve(entry).backwards()
    branches = entry['branches'][::-1]
    checked = verify(trajectory, planner.cell, *_ends(planner, pair, branches))
    if not checked.ok:  # cannot happen for a verified curve; never trusted all the same
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the reversed trajectory {"->".join(pair)} failed verification: '
                            + '; '.join(checked.problems))
    return _stored(branches, trajectory, entry['initial_cycle_time'],
                   np.asarray(entry['roadmap_path'])[::-1], np.asarray(entry['path'])[::-1],
                   dict(entry['metrics'], reversed=True, branches=branches), entry['warnings'],
                   (time.perf_counter() - begun) * 1000.0), checked


def _stored(branches, trajectory, initial_cycle_time, roadmap_path, path, metrics, warnings,
            planning_ms: float) -> dict:
    """Return a table entry (plain data): the plan, no figure of its verification."""
    return {
        'branches': list(branches), 'trajectory': trajectory.describe(),
        'initial_cycle_time': initial_cycle_time,
        'roadmap_path': np.asarray(roadmap_path).tolist(), 'path': np.asarray(path).tolist(),
        'metrics': dict(metrics), 'warnings': list(warnings), 'planning_ms': planning_ms,
    }


def verified_entry(planner: Planner, pair, entry: dict) -> Verification:
    """
    Return the full verification of a stored entry's curve, from its stations (``verify``).

    Raise ValueError if the entry cannot be read, its curve is longer than ``MAX_DURATION``,
    or a field an answer takes from it is unfit (``_described``).
    """
    curve = entry_curve(entry)
    if not curve.duration <= MAX_DURATION:
        raise ValueError(f'its curve lasts {curve.duration:.6g} s, over {MAX_DURATION:g} s')
    checked = verify(curve, planner.cell, *_ends(planner, pair, entry['branches']))
    if checked.ok:
        _described(curve, entry, _ends(planner, pair, entry['branches'], retracted=True))
    return checked


def _described(curve: Trajectory, entry: dict, retracted: list) -> dict:
    """
    Return what an answer takes from a stored entry besides its verified curve, checked.

    Raise ValueError unless: the initial (λ-scaled start's) cycle time is finite and no
    shorter than the curve; the path is a finite (n, 3) array from the curve's start to its
    end, and so is the roadmap path from the ``retracted`` ends (an end inside a port: its
    retracted pose, where the roadmap begins); the warnings are texts; the planning counts
    are numbers or flags. ``MEASURED`` metrics are not read: the caller measures them.
    """
    initial = float(entry['initial_cycle_time'])
    if not curve.duration <= initial < np.inf:
        raise ValueError(f'its initial cycle time {initial!r} is not a finite time at least '
                         f"the curve's {curve.duration:.6g} s")
    paths = {}
    for name, ends, what in (
            ('roadmap_path', np.asarray(retracted), "from its stations' retracted poses"),
            ('path', curve.evaluate([0.0, curve.duration]), "from the curve's start")):
        path = np.asarray(entry[name], float)
        if path.ndim != 2 or path.shape[1] != 3 or not 2 <= len(path) <= MAX_ITEMS \
                or not np.all(np.isfinite(path)) \
                or not np.allclose(path[[0, -1]], ends, rtol=0.0, atol=1e-9):
            raise ValueError(f'its {name} is not a path {what} to its end')
        paths[name] = path
    warnings = entry['warnings']
    if not isinstance(warnings, list) or len(warnings) > MAX_ITEMS or not all(
            isinstance(text, str) and len(text) <= MAX_TEXT for text in warnings):
        raise ValueError('its warnings are not a list of texts')
    counts = {name: value for name, value in entry['metrics'].items() if name not in MEASURED}
    if len(counts) > MAX_ITEMS or not all(
            isinstance(name, str) and len(name) <= MAX_TEXT and (
                isinstance(value, bool) or isinstance(value, int)
                or isinstance(value, float) and np.isfinite(value))
            for name, value in counts.items()):
        raise ValueError('its planning counts are not all finite numbers or flags')
    return {'initial_cycle_time': initial, 'warnings': tuple(warnings), 'counts': counts,
            **paths}


def _ends(planner: Planner, pair, branches, retracted: bool = False) -> list:
    """
    Return the configurations of a pair's ends (stations, or inside ports) on the branches.

    ``retracted``: an end inside a port as its port's mouth (the end of its way out).
    """
    ends = []
    for name, branch, role in zip(pair, branches, ('start', 'goal')):
        end = planner.endpoint(name, role)
        k = next(k for k, (elbow, _) in enumerate(end.configs)
                 if elbow is None or elbow == branch)
        channel = end.channel(k) if retracted else None
        ends.append(end.configs[k][1] if channel is None else channel.mouth)
    return ends


def entry_curve(entry: dict) -> Trajectory:
    """Return an entry's curve, of the kind its description names."""
    return Trajectory.from_description(entry['trajectory'])


def entry_result(planner: Planner, pair, entry: dict, verification: Verification,
                 method: str, lengths: dict) -> PlanResult:
    """Return the answer of a stored entry, sampled at the planner's period (``answer``)."""
    trajectory = entry_curve(entry)
    described = _described(trajectory, entry,
                           _ends(planner, pair, entry['branches'], retracted=True))
    start, goal = (planner.endpoint(name, role) for name, role in zip(pair, ('start', 'goal')))
    # A station given by joint angles has no elbow branch (None).
    branches = [None if branch is None else int(branch) for branch in entry['branches']]
    # Measured on the curve: its description's control points, or its transfer's (a kind
    # without any has 0).
    description = trajectory.describe()
    points = description.get('control_points') or (
        description.get('transfer') or {}).get('control_points', ())
    start_q, goal_q = trajectory.evaluate([0.0, trajectory.duration])
    return answer(planner, start, goal, start_q, goal_q, branches, trajectory,
                  described['initial_cycle_time'], verification, described['roadmap_path'],
                  described['path'], described['counts'], len(points), described['warnings'],
                  method=method, extra={'source': 'table'}, lengths=lengths)
