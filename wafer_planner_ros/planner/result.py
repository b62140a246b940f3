"""
An answer: a verified trajectory, sampled for the robot, with what was measured making it.

``answer`` is the one place a ``PlanResult`` is made, whatever the curve came from (the
candidate search, a move through a port, a stored table entry): it samples the curve at
the planner's period and adds the figures every answer reports (its method, path sizes and
lengths, branches), so that no source reports them differently.
"""

from dataclasses import dataclass, field
from typing import Mapping, Optional, Tuple

import numpy as np

from wafer_planner_ros.planner.endpoints import Endpoint
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.verify import Verification

LENGTH_SAMPLES = 2001
"""Points along a curve its path lengths are summed over (``path_lengths``)."""


@dataclass(frozen=True, eq=False)
class PlanResult:
    """A verified trajectory and everything measured while making it."""

    start: Endpoint
    goal: Endpoint
    start_q: np.ndarray
    goal_q: np.ndarray
    branches: Tuple[Optional[int], Optional[int]]
    """The elbow branches used at start and goal (None for joint requests)."""
    load: str
    """The limit set planned and verified against (``cell.limits``: loaded or empty)."""
    trajectory: Trajectory
    initial_cycle_time: float
    """s: the cycle time the curve method started from (the paper's λ-scaled timing)."""
    verification: Verification
    """The dense check it passed: limit ratios, clearance, peak jerk."""
    times: np.ndarray
    """(N,) the returned samples every ``sample_period``, then the exact final time."""
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    roadmap_path: np.ndarray
    """(P, 3) the A* path from the roadmap."""
    path: np.ndarray
    """(P', 3) the path the corridor was built on (after shortcuts); an end inside a port
    comes before (after) the retracted pose the roadmap path starts (ends) at."""
    metrics: Mapping = field(default_factory=dict)
    """What is measured nowhere else: path sizes and lengths, the method's figures."""
    timings_ms: Mapping = field(default_factory=dict)
    """ms by stage (``STAGES``), by timed part of a stage (``stopwatch.PARTS``) and in all
    (``total``)."""
    warnings: Tuple[str, ...] = ()

    @property
    def cycle_time(self) -> float:
        """Return the trajectory's duration (s)."""
        return self.trajectory.duration

    @property
    def min_clearance(self) -> float:
        """Return the smallest distance from the robot to a wall or obstacle (m)."""
        return self.verification.min_clearance


def answer(planner, start: Endpoint, goal: Endpoint, start_q, goal_q, branches,
           trajectory: Trajectory, initial_cycle_time: float, verification: Verification,
           roadmap_path, path, metrics: Mapping, control_points: int, warnings=(),
           timings_ms: Optional[Mapping] = None, method: Optional[str] = None,
           extra: Optional[Mapping] = None, lengths: Optional[Mapping] = None) -> PlanResult:
    """
    Return a verified curve as ``planner``'s answer, sampled at its period and measured.

    ``metrics``: the source's own figures, then every answer's (``method``: the planner's
    curve method's name unless given; path sizes, ``control_points``, ``branches``, path
    lengths: ``path_lengths`` unless the caller has them, ``lengths``), then ``extra``.
    """
    times, positions, velocities, accelerations = trajectory.samples(
        planner.settings.sample_period)
    measured = dict(
        metrics, method=planner.method.name if method is None else method,
        roadmap_path_vertices=len(roadmap_path), path_vertices=len(path),
        control_points=control_points, branches=list(branches),
        **(path_lengths(planner.cell, trajectory) if lengths is None else lengths),
        **(extra or {}))
    return PlanResult(
        start=start, goal=goal, start_q=start_q, goal_q=goal_q, branches=tuple(branches),
        load=planner.load, trajectory=trajectory, initial_cycle_time=initial_cycle_time,
        verification=verification, times=times, positions=positions, velocities=velocities,
        accelerations=accelerations, roadmap_path=roadmap_path, path=path, metrics=measured,
        timings_ms=timings_ms or {}, warnings=tuple(warnings))


def path_lengths(cell, trajectory, samples: int = LENGTH_SAMPLES) -> dict:
    """
    Return a trajectory's ``joint_path_length`` (rad) and ``wafer_path_length`` (m).

    Summed over ``samples`` points evenly spaced in time.
    """
    dense = trajectory.evaluate(np.linspace(0.0, trajectory.duration, samples))
    wafer = cell.robot.arm.wafer_center(dense)
    return {'joint_path_length': float(np.linalg.norm(np.diff(dense, axis=0), axis=1).sum()),
            'wafer_path_length': float(np.linalg.norm(np.diff(wafer, axis=0), axis=1).sum())}
