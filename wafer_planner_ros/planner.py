"""
The planning pipeline: request -> roadmap path -> corridor -> spline -> timing -> verified.

``Planner.plan(start, goal)`` takes a station name or three joint angles for each end. When
a station allows both elbow branches every combination is planned and the one with the
shortest cycle time is returned (SPEC section 3); a combination whose optimisation shows it
cannot win is given up part-way (``timing.optimise``'s ``give_up_above``). Every returned
trajectory has passed ``verify``; a request that cannot be answered raises
``PlanningError`` with its code.
"""

from dataclasses import dataclass, field, replace
import logging
import time
from typing import Mapping, Optional, Tuple

import numpy as np

from wafer_planner_ros.cell.schema import brief
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.roadmap.search import find_path
from wafer_planner_ros.roadmap.shortcut import shortcut
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.corridor import build_corridor, simplify
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, Timing, TimingProblem
from wafer_planner_ros.trajectory.tuning import TimingSettings
from wafer_planner_ros.trajectory.verify import Verification, verify

logger = logging.getLogger(__name__)

STAGES = ('connect', 'search', 'corridor', 'spline', 'optimise', 'verify')

KNOWN_LISTED = 10
"""The stations an UNKNOWN_STATION message lists (then how many more there are)."""
MAX_QUOTED = 200
"""Most characters of a requested station name quoted in a message."""
SAMPLE_PERIOD_RANGE = (0.001, 1.0)
"""s: the shortest and longest step between returned samples (the verification's is 1 ms)."""


@dataclass(frozen=True)
class PlannerSettings:
    """How trajectories are made. ``PlannerSettings.paper()`` is the paper's pipeline."""

    sample_period: float = 0.01
    """Seconds between the returned samples (the exact final point is added)."""
    shortcut: bool = True
    """Shorten the roadmap path with certified shortcuts (beyond the paper)."""
    per_body_boxes: bool = True
    """Size the safe boxes per body (beyond the paper; False: Eq. 3)."""
    extra_points: int = 1
    """Control points added on every straight stretch (beyond the paper)."""
    timing: TimingSettings = TimingSettings()
    """The time optimiser's tuning."""

    def __post_init__(self):
        """Reject unusable settings."""
        low, high = SAMPLE_PERIOD_RANGE
        if not (isinstance(self.sample_period, (int, float))
                and low <= self.sample_period <= high):
            raise ValueError(f'sample_period must be in [{low}, {high}] s, got '
                             f'{self.sample_period!r}')
        if not isinstance(self.extra_points, int) or self.extra_points < 0:
            raise ValueError(f'extra_points must be an integer >= 0, got {self.extra_points!r}')

    @classmethod
    def paper(cls, sample_period: float = 0.01) -> 'PlannerSettings':
        """Return the settings of the paper's exact pipeline, for comparison."""
        return cls(sample_period=sample_period, shortcut=False, per_body_boxes=False,
                   extra_points=0)


@dataclass(frozen=True, eq=False)
class Endpoint:
    """A resolved start or goal: its label and candidate configurations."""

    label: str
    configs: Tuple[Tuple[Optional[int], np.ndarray], ...]
    """(elbow branch or None for a joint request, q)."""


@dataclass(frozen=True, eq=False)
class PlanResult:
    """A verified trajectory and everything measured while making it."""

    start: Endpoint
    goal: Endpoint
    start_q: np.ndarray
    goal_q: np.ndarray
    branches: Tuple[Optional[int], Optional[int]]
    """The elbow branches used at start and goal (None for joint requests)."""
    spline: CubicBSpline
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    roadmap_path: np.ndarray
    """(P, 3) the A* path from the roadmap."""
    path: np.ndarray
    """(P', 3) the path the corridor was built on (after shortcuts)."""
    timing: Timing
    verification: Optional[Verification]
    """The dense check; None only inside the planner, before it has run."""
    metrics: Mapping = field(default_factory=dict)
    timings_ms: Mapping = field(default_factory=dict)
    warnings: Tuple[str, ...] = ()

    @property
    def cycle_time(self) -> float:
        """Return the trajectory's duration (s)."""
        return self.spline.duration

    @property
    def initial_cycle_time(self) -> float:
        """Return the duration of the λ-scaled start point (the paper's initial point)."""
        return float(self.timing.initial_intervals.sum())


class Planner:
    """Plans on one cell with one roadmap."""

    def __init__(self, cell, roadmap, settings: PlannerSettings = PlannerSettings()):
        """Keep the cell, its roadmap and the settings."""
        self.cell = cell
        self.roadmap = roadmap
        self.settings = settings

    def endpoint(self, value, role: str) -> Endpoint:
        """Resolve a station name or three joint angles; raise PlanningError if unusable."""
        robot = self.cell.robot
        if isinstance(value, str):
            station = self.cell.stations.get(value)
            if station is None:
                names = sorted(self.cell.stations)
                known = ', '.join(names[:KNOWN_LISTED]) + (
                    f' and {len(names) - KNOWN_LISTED} more' if len(names) > KNOWN_LISTED
                    else '')
                raise PlanningError(ErrorCode.UNKNOWN_STATION,
                                    f'{role} {value[:MAX_QUOTED]!r} is not a station of cell '
                                    f'{self.cell.name} ({known[:4 * MAX_QUOTED]})')
            joints = 'joints' in station.spec
            return Endpoint(value, tuple((None if joints else c.elbow, c.q)
                                         for c in station.configs))
        try:
            q = np.asarray(value, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise PlanningError(ErrorCode.INVALID_REQUEST,
                                f'{role} {brief(value)} is neither a station nor joint '
                                'angles') from None
        if q.size != len(robot.joint_names):
            raise PlanningError(ErrorCode.JOINT_MISMATCH,
                                f'{role} has {q.size} joint values; the robot has '
                                f'{len(robot.joint_names)} ({", ".join(robot.joint_names)})')
        if not np.all(np.isfinite(q)):
            raise PlanningError(ErrorCode.NOT_FINITE, f'{role} {q.tolist()} is not finite')
        lower, upper = robot.limits.position.T
        for j in np.nonzero((q < lower) | (q > upper))[0]:
            raise PlanningError(ErrorCode.OUT_OF_LIMITS,
                                f'{role} joint {robot.joint_names[j]} = {q[j]} rad is outside '
                                f'[{lower[j]}, {upper[j]}]')
        model = self.cell.clearance_model
        if model.clearance(q)[0] <= 0.0:
            contact = model.contact(q)
            code = ErrorCode.START_IN_COLLISION if role == 'start' else \
                ErrorCode.GOAL_IN_COLLISION
            raise PlanningError(code, f'{role} {q.tolist()} is in collision '
                                      f'({contact.describe()})')
        return Endpoint(','.join(f'{v:g}' for v in q), ((None, q),))

    def plan(self, start, goal, deadline: Optional[float] = None,
             branches: Optional[Tuple[Optional[int], Optional[int]]] = None) -> PlanResult:
        """
        Return the verified trajectory from start to goal with the shortest cycle time.

        ``deadline``: a ``time.monotonic()`` instant after which the request gives up with
        TIMEOUT. ``branches``: plan only this (start, goal) elbow-branch combination (None
        for joint angles), e.g. to see what each one costs. Raises PlanningError with the
        code of the first reason it cannot answer.
        """
        begun = time.perf_counter()
        a, b = self.endpoint(start, 'start'), self.endpoint(goal, 'goal')
        if branches is not None:
            a, b = (_only_branch(end, elbow, role) for end, elbow, role in
                    ((a, branches[0], 'start'), (b, branches[1], 'goal')))
        stage_ms = dict.fromkeys(STAGES, 0.0)
        prepared, failure = [], None
        for elbow_a, qa in a.configs:
            for elbow_b, qb in b.configs:
                if np.array_equal(qa, qb):
                    raise PlanningError(ErrorCode.INVALID_REQUEST,
                                        f'start and goal are the same configuration '
                                        f'{qa.tolist()}')
                _check_deadline(deadline)
                try:
                    prepared.append(self._prepared(a, b, qa, qb, (elbow_a, elbow_b),
                                                   stage_ms))
                except PlanningError as exc:
                    logger.debug('branches %s -> %s dropped: %s', elbow_a, elbow_b, exc)
                    failure = failure or exc
        # Most promising first (the λ-scaled start's cycle time), so that a combination
        # whose optimisation shows it cannot beat the best so far is given up early.
        candidates, given_up = [], []
        for pair in sorted(prepared, key=lambda p: p.start[0].sum()):
            _check_deadline(deadline)
            best = min((r.cycle_time for r in candidates), default=None)
            result = self._timed(pair, best, stage_ms)
            if result is None:
                logger.debug('branches %s cannot beat %.3f s; given up', pair.branches, best)
                given_up.append(pair)
            else:
                candidates.append(result)
        while candidates:
            # Shortest cycle first; only what is returned needs verifying.
            for result in sorted(candidates, key=lambda r: r.cycle_time):
                _check_deadline(deadline)
                try:
                    result = self._verified(result, stage_ms)
                except PlanningError as exc:
                    logger.warning('%s; trying the next branch combination', exc)
                    failure = failure or exc
                    continue
                total = (time.perf_counter() - begun) * 1000.0
                metrics = dict(result.metrics, candidates=len(prepared),
                               given_up=len(given_up))
                return replace(result, metrics=metrics,
                               timings_ms=dict(stage_ms, total=total))
            # Every faster one failed verification: optimise those given up after all.
            candidates = [self._timed(pair, None, stage_ms) for pair in given_up]
            given_up = []
        raise failure

    def _prepared(self, a, b, qa, qb, branches, stage_ms) -> '_Prepared':
        """Return the path, corridor and λ-scaled start between two configurations."""
        model, lipschitz = self.cell.clearance_model, self.cell.robot.lipschitz
        clock = _Clock(stage_ms)
        found = find_path(self.roadmap, model, lipschitz, qa, qb, clock=clock)
        if found is None:
            raise PlanningError(ErrorCode.NO_PATH,
                                f'no path from {a.label} to {b.label} in the roadmap '
                                f'({self.roadmap.node_count} nodes): connect more nodes or '
                                'check the cell')
        roadmap_path = simplify(found[0])
        path = shortcut(roadmap_path, model, lipschitz) if self.settings.shortcut \
            else roadmap_path
        corridor = build_corridor(path, model.body_clearance(path), lipschitz,
                                  per_body=self.settings.per_body_boxes,
                                  extra=self.settings.extra_points)
        clock.lap('corridor')
        problem = TimingProblem(corridor.control_points, self.cell.robot, self.settings.timing)
        start = scaled_start(problem)
        clock.lap('spline')
        return _Prepared(a, b, qa, qb, branches, roadmap_path, path, corridor.control_points,
                         problem, start)

    def _timed(self, pair: '_Prepared', give_up_above, stage_ms) -> Optional[PlanResult]:
        """Return the optimised trajectory, not yet verified; None if it cannot win."""
        clock = _Clock(stage_ms)
        timing = optimise(pair.problem, pair.start, give_up_above)
        clock.lap('optimise')
        if timing is None:
            return None
        spline = CubicBSpline.from_intervals(pair.control_points, timing.intervals)
        warnings = () if timing.optimised else (
            f'time optimisation failed ({timing.message}); returning the λ-scaled timing',)
        metrics = {
            'cycle_time': spline.duration,
            'initial_cycle_time': float(timing.initial_intervals.sum()),
            'lambda': timing.scale,
            'optimised': timing.optimised,
            'solver_iterations': timing.iterations,
            'constraint_rounds': timing.rounds,
            'wafer_samples': timing.samples,
            'roadmap_path_vertices': len(pair.roadmap_path),
            'path_vertices': len(pair.path),
            'control_points': len(pair.control_points),
            'branches': list(pair.branches),
        }
        empty = np.empty((0, 3))
        return PlanResult(
            start=pair.a, goal=pair.b, start_q=pair.qa, goal_q=pair.qb, branches=pair.branches,
            spline=spline, times=np.empty(0), positions=empty, velocities=empty,
            accelerations=empty, roadmap_path=pair.roadmap_path, path=pair.path,
            timing=timing, verification=None, metrics=metrics, warnings=warnings)

    def _verified(self, result: PlanResult, stage_ms) -> PlanResult:
        """Return the result verified, sampled and measured; raise VERIFICATION_FAILED."""
        clock = _Clock(stage_ms)
        checked = verify(result.spline, self.cell, result.start_q, result.goal_q)
        clock.lap('verify')
        if not checked.ok:
            raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                                f'the trajectory {result.start.label} -> {result.goal.label} '
                                'failed verification: ' + '; '.join(checked.problems))
        spline = result.spline
        dense = spline.evaluate(np.linspace(0.0, spline.duration, 2001))
        wafer = self.cell.robot.arm.wafer_center(dense)
        metrics = dict(
            result.metrics, min_clearance=checked.min_clearance,
            limit_ratios=dict(checked.ratios), peak_jerk=list(checked.peak_jerk),
            limit_checks=checked.limit_samples, collision_checks=checked.collision_samples,
            joint_path_length=float(np.linalg.norm(np.diff(dense, axis=0), axis=1).sum()),
            wafer_path_length=float(np.linalg.norm(np.diff(wafer, axis=0), axis=1).sum()))
        # Samples every sample_period, then the exact final point.
        period = self.settings.sample_period
        times = np.arange(0.0, spline.duration - 1e-9, period)
        times = np.append(times, spline.duration)
        positions, velocities, accelerations = spline.evaluate_orders(times)
        return replace(result, verification=checked, metrics=metrics, times=times,
                       positions=positions, velocities=velocities, accelerations=accelerations)


@dataclass(frozen=True, eq=False)
class _Prepared:
    """One elbow-branch combination up to its time optimisation."""

    a: Endpoint
    b: Endpoint
    qa: np.ndarray
    qb: np.ndarray
    branches: Tuple[Optional[int], Optional[int]]
    roadmap_path: np.ndarray
    path: np.ndarray
    control_points: np.ndarray
    problem: TimingProblem
    start: tuple
    """``scaled_start(problem)``: (intervals, λ)."""


class _Clock:
    """Add the time since the last lap to a named stage."""

    def __init__(self, totals: dict):
        self.totals = totals
        self.last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.totals[stage] += (now - self.last) * 1000.0
        self.last = now


def _only_branch(end: Endpoint, elbow, role: str) -> Endpoint:
    """Return ``end`` with only its configuration on the ``elbow`` branch."""
    configs = tuple(c for c in end.configs if c[0] == elbow)
    if not configs:
        raise PlanningError(ErrorCode.INVALID_REQUEST,
                            f'{role} {end.label} has no elbow branch {elbow!r} (it has '
                            f'{[c[0] for c in end.configs]})')
    return replace(end, configs=configs)


def _check_deadline(deadline: Optional[float]) -> None:
    if deadline is not None and time.monotonic() > deadline:
        raise PlanningError(ErrorCode.TIMEOUT, 'planning did not finish before its deadline')
