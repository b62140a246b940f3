"""
The planning pipeline: request -> roadmap path -> corridor -> spline -> timing -> verified.

``Planner.plan(start, goal)`` takes a station name or three joint angles for each end. When
a station allows both elbow branches every combination is planned and the one with the
shortest cycle time is returned; a combination that cannot win is given up before it is
optimised when even its joints' fastest rest-to-rest motions
(``JointLimits.shortest_motion``) take longer than the best so far, and part-way when its
optimisation shows it (the methods' ``give_up_above``). A move into or out of a port,
planned without a time budget, is never slower than stopping at the port mouths: that
stop-and-go chain is planned first (``Planner.stop_and_go``), and it is the bound every
combination must beat and the answer when none does. Every returned trajectory has passed
``verify``; a request that cannot be answered raises ``PlanningError`` with its code.
"""

from dataclasses import dataclass, field, replace
import logging
import threading
import time
from typing import Mapping, Optional, Tuple, Type

import numpy as np

from wafer_planner_ros.cell.limits import LOADS
from wafer_planner_ros.cell.schema import brief
from wafer_planner_ros.cell.stations import INSIDE
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.geometry.contacts import colliding
from wafer_planner_ros.geometry.ports import describe_deviation
from wafer_planner_ros.roadmap.search import find_path
from wafer_planner_ros.roadmap.shortcut import shortcut
from wafer_planner_ros.trajectory.corridor import build_corridor, simplify, through_ports
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.methods import CurveMethod, Draft, KnotTiming, METHODS
from wafer_planner_ros.trajectory.methods import Shaped
from wafer_planner_ros.trajectory.stops import stopping_curve
from wafer_planner_ros.trajectory.stopwatch import collecting, PARTS
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings
from wafer_planner_ros.trajectory.verify import Verification, verify

logger = logging.getLogger(__name__)

STAGES = ('connect', 'search', 'corridor', 'spline', 'optimise', 'verify', 'stopping')
"""The stages of a plan, timed in its ``timings_ms`` (with ``PARTS`` of them and ``total``);
``stopping``: the stop-and-go chain of a move through a port, its legs planned, joined and
verified (``Planner._stopping``)."""

KNOWN_LISTED = 10
"""The stations an UNKNOWN_STATION message lists (then how many more there are)."""
MAX_QUOTED = 200
"""Most characters of a requested station name quoted in a message."""
LEGS_KEPT = 64
"""The stop-and-go legs a planner keeps (``Planner._leg``): every retract and extend of 16
stations with ports on both elbow branches, with 32 transfers between them."""
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
    method: Type[CurveMethod] = KnotTiming
    """How the curve through the corridor is shaped and timed: a ``CurveMethod`` class
    (``trajectory.methods``), or its name (``METHODS``: where settings come from text)."""
    timing: TimingSettings = TimingSettings()
    """The time optimiser's tuning."""
    shape: ShapeSettings = ShapeSettings()
    """The whole-curve optimiser's tuning."""

    def __post_init__(self):
        """Reject unusable settings."""
        low, high = SAMPLE_PERIOD_RANGE
        if not (isinstance(self.sample_period, (int, float))
                and low <= self.sample_period <= high):
            raise ValueError(f'sample_period must be in [{low}, {high}] s, got '
                             f'{self.sample_period!r}')
        if not isinstance(self.extra_points, int) or self.extra_points < 0:
            raise ValueError(f'extra_points must be an integer >= 0, got {self.extra_points!r}')
        method = METHODS.get(self.method) if isinstance(self.method, str) else self.method
        if not (isinstance(method, type) and issubclass(method, CurveMethod)):
            raise ValueError(f'method must be one of {", ".join(sorted(METHODS))}, got '
                             f'{self.method!r}')
        object.__setattr__(self, 'method', method)  # frozen: the class, whatever was given

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
    ways_out: Tuple[Optional[np.ndarray], ...] = ()
    """Per configuration inside a port (a ``<station>:inside`` request, or joint angles
    inside a port): the configurations out of the port to its retracted pose
    (``Port.way_out``), else None; empty when no configuration is inside a port."""

    def way_out(self, k: int) -> Optional[np.ndarray]:
        """Return the way out of a port of configuration ``k`` (None: not inside one)."""
        return self.ways_out[k] if self.ways_out else None


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


class Planner:
    """Plans on one cell with one roadmap."""

    def __init__(self, cell, roadmap, settings: PlannerSettings = PlannerSettings()):
        """Keep the cell, its roadmap and the settings."""
        self.cell = cell
        self.roadmap = roadmap
        self.settings = settings
        self.method = settings.method(cell, settings.timing, settings.shape)
        self._by_load = {cell.robot.load: self}
        self._legs: dict = {}
        """The stop-and-go legs planned so far (``_leg``), at most ``LEGS_KEPT``."""
        self._legs_lock = threading.Lock()

    @property
    def load(self) -> str:
        """Return the limit set this planner plans against (``cell.limits``)."""
        return self.cell.robot.load

    def for_load(self, load: str) -> 'Planner':
        """Return the planner of this cell and roadmap against the limit set ``load``."""
        if load not in self._by_load:
            if load not in LOADS:
                raise PlanningError(ErrorCode.INVALID_REQUEST,
                                    f'unknown load {brief(load)}: one of {", ".join(LOADS)}')
            planner = Planner(self.cell.with_load(load), self.roadmap, self.settings)
            planner._by_load = self._by_load  # one planner per limit set, shared
            self._by_load[load] = planner
        return self._by_load[load]

    def endpoint(self, value, role: str) -> Endpoint:
        """
        Resolve a station name or three joint angles; raise PlanningError if unusable.

        ``<station>:inside`` names the station's pick/place pose inside its port; joint
        angles that put the wafer inside a port are a pose inside it too, refused when
        they break its tolerances.
        """
        robot = self.cell.robot
        if isinstance(value, str):
            name = value[:-len(INSIDE)] if value.endswith(INSIDE) else value
            station = self.cell.stations.get(name)
            if station is None:
                names = sorted(self.cell.stations)
                known = ', '.join(names[:KNOWN_LISTED]) + (
                    f' and {len(names) - KNOWN_LISTED} more' if len(names) > KNOWN_LISTED
                    else '')
                raise PlanningError(ErrorCode.UNKNOWN_STATION,
                                    f'{role} {value[:MAX_QUOTED]!r} is not a station of cell '
                                    f'{self.cell.name} ({known[:4 * MAX_QUOTED]})')
            joints = 'joints' in station.spec
            if name == value:
                return Endpoint(value, tuple((None if joints else c.elbow, c.q)
                                             for c in station.configs))
            if station.port is None:
                raise PlanningError(ErrorCode.INVALID_REQUEST,
                                    f'{role} {value!r}: station {name} has no port (its '
                                    'port: key in the cell file)')
            retracted = {c.elbow: c.q for c in station.configs}
            return Endpoint(value, tuple((None if joints else c.elbow, c.q)
                                         for c in station.inside),
                            tuple(station.port.way_out(robot.arm, c.q, retracted[c.elbow])
                                  for c in station.inside))
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
            # Every body that collides, and how: a link crossing the wall, a wafer beyond it.
            how = '; '.join(c.describe() for c in colliding(model, q)) or \
                model.contact(q).describe()
            code = ErrorCode.START_IN_COLLISION if role == 'start' else \
                ErrorCode.GOAL_IN_COLLISION
            raise PlanningError(code, f'{role} {q.tolist()} is in collision ({how})')
        label = ','.join(f'{v:g}' for v in q)
        way = self._way_out(q, role)
        return Endpoint(label, ((None, q),), () if way is None else (way,))

    def _way_out(self, q: np.ndarray, role: str) -> Optional[np.ndarray]:
        """Return the way out of the port joint angles ``q`` are inside, None if in none."""
        ports = self.cell.port_model
        k = int(ports.inside(q)[0])
        if k < 0:
            return None
        how = describe_deviation(ports, q)
        if how is not None:
            raise PlanningError(ErrorCode.OUT_OF_LIMITS, f'{role} {q.tolist()}: {how}')
        port, robot = ports.ports[k], self.cell.robot
        retracted = port.configurations(robot.arm, np.zeros(1), q[1], near=q[None])[0]
        lower, upper = robot.limits.position.T
        if not np.all((retracted >= lower) & (retracted <= upper)):
            raise PlanningError(ErrorCode.OUT_OF_LIMITS,
                                f'{role} {q.tolist()} is inside the port of {port.station}, '
                                f'whose retracted pose on its elbow branch '
                                f'({retracted.round(4).tolist()}) is beyond '
                                'robot.joint_limits.position')
        return port.way_out(robot.arm, q, retracted)

    def plan(self, start, goal, deadline: Optional[float] = None,
             branches: Optional[Tuple[Optional[int], Optional[int]]] = None,
             budget: Optional[float] = None, load: Optional[str] = None) -> PlanResult:
        """
        Return the verified trajectory from start to goal with the shortest cycle time.

        ``load``: the limit set, ``LOADED`` (a wafer on the blade: the wafer limit holds)
        or ``EMPTY`` (none: joint limits only); None: this planner's (``load``). An empty
        move made with a wafer on the blade can slide it.

        ``deadline``: a ``time.monotonic()`` instant after which the request gives up with
        TIMEOUT. ``branches``: plan only this (start, goal) elbow-branch combination (None
        for joint angles), e.g. to see what each one costs. ``budget``: seconds from now
        after which a curve method that improves step by step returns the best curve it has
        (verified like any other), and the elbow-branch combinations not yet finished are
        given up when one is. Raises PlanningError with the code of the first reason it
        cannot answer.
        """
        if load is not None and load != self.load:
            return self.for_load(load).plan(start, goal, deadline, branches, budget)
        begun = time.perf_counter()
        until = None if budget is None else time.monotonic() + budget
        a, b = self.endpoint(start, 'start'), self.endpoint(goal, 'goal')
        if branches is not None:
            a, b = (_only_branch(end, elbow, role) for end, elbow, role in
                    ((a, branches[0], 'start'), (b, branches[1], 'goal')))
        return self._planned(a, b, deadline, until, begun)

    def _planned(self, a: Endpoint, b: Endpoint, deadline: Optional[float],
                 until: Optional[float], begun: float, stopping: bool = True) -> PlanResult:
        """
        Return the fastest verified answer between two resolved ends (``plan``).

        ``stopping``: whether a request through a port also plans its stop-and-go chain
        (``_stopping``), the bound every non-stop combination must beat.
        """
        stage_ms = dict.fromkeys(STAGES + PARTS, 0.0)
        prepared, failure = [], None
        for i, (elbow_a, qa) in enumerate(a.configs):
            for j, (elbow_b, qb) in enumerate(b.configs):
                if np.array_equal(qa, qb):
                    raise PlanningError(ErrorCode.INVALID_REQUEST,
                                        f'start and goal are the same configuration '
                                        f'{qa.tolist()}')
                _check_deadline(deadline)
                try:
                    prepared.append(self._prepared(a, b, (qa, a.way_out(i)),
                                                   (qb, b.way_out(j)), (elbow_a, elbow_b),
                                                   stage_ms))
                except PlanningError as exc:
                    logger.debug('branches %s -> %s dropped: %s', elbow_a, elbow_b, exc)
                    failure = failure or exc
        stops = self._stopping(a, b, deadline, until, stage_ms)[0] if stopping else None
        bound = None if stops is None else stops.cycle_time
        # Most promising first (the method's starting point), so that a combination whose
        # optimisation shows it cannot beat the best so far is given up early.
        candidates, given_up = [], []
        for pair in sorted(prepared, key=lambda p: p.draft.estimate):
            _check_deadline(deadline)
            best = min((c.shaped.trajectory.duration for c in candidates), default=bound)
            if best is not None and pair.fastest >= best:
                logger.debug('branches %s take at least %.3f s, the best so far %.3f s; '
                             'given up', pair.branches, pair.fastest, best)
                given_up.append(pair)
                continue
            if best is not None and until is not None and time.monotonic() >= until:
                logger.debug('branches %s not optimised: the time budget is spent',
                             pair.branches)
                given_up.append(pair)
                continue
            candidate = self._finished(pair, best, stage_ms, until, deadline)
            if candidate is None:
                logger.debug('branches %s cannot beat %.3f s; given up', pair.branches, best)
                given_up.append(pair)
            else:
                candidates.append(candidate)
        while candidates:
            # Shortest cycle first; only what is returned needs verifying.
            for candidate in sorted(candidates, key=lambda c: c.shaped.trajectory.duration):
                _check_deadline(deadline)
                try:
                    checked = self._verified(candidate, stage_ms)
                except PlanningError as exc:
                    candidate = candidate.fallback()
                    logger.warning('%s; trying %s', exc, 'the curve it started from'
                                   if candidate else 'the next branch combination')
                    failure = failure or exc
                    try:
                        checked = self._verified(candidate, stage_ms) if candidate else None
                    except PlanningError:
                        checked = None
                    if checked is None:
                        continue
                if stops is None or candidate.shaped.trajectory.duration < stops.cycle_time:
                    counts = {'candidates': len(prepared), 'given_up': len(given_up)}
                    return self._result(candidate, checked, counts, dict(
                        stage_ms, total=(time.perf_counter() - begun) * 1000.0))
                given_up = []  # the fastest verified curve is no faster than stopping
                break
            # Every faster one failed verification: finish those given up after all.
            candidates = [c for c in (self._finished(pair, bound, stage_ms, until, deadline)
                                      for pair in given_up) if c is not None]
            given_up = []
        if stops is not None:
            return replace(stops, metrics=dict(stops.metrics, candidates=len(prepared)),
                           timings_ms=dict(stage_ms,
                                           total=(time.perf_counter() - begun) * 1000.0))
        raise failure

    def stop_and_go(self, start, goal, deadline: Optional[float] = None,
                    load: Optional[str] = None) -> PlanResult:
        """
        Return the move through a port that stops at the port's mouth, verified (``_stopping``).

        What ``plan`` returns when no non-stop curve is faster, without looking for one: its
        legs are short moves into or out of a port and a move between retracted poses, so it
        takes seconds where ``plan`` may take minutes. Raises PlanningError: INVALID_REQUEST
        when neither end is inside a port or the move is a single leg, else the first reason
        no chain could be planned.
        """
        if load is not None and load != self.load:
            return self.for_load(load).stop_and_go(start, goal, deadline)
        begun = time.perf_counter()
        a, b = self.endpoint(start, 'start'), self.endpoint(goal, 'goal')
        stage_ms = dict.fromkeys(STAGES + PARTS, 0.0)
        result, failure = self._stopping(a, b, deadline, None, stage_ms)
        if result is None:
            raise failure or PlanningError(
                ErrorCode.INVALID_REQUEST, f'{a.label} -> {b.label} does not stop on its way: '
                'neither end is inside a port, or it only leaves (enters) one')
        return replace(result, timings_ms=dict(stage_ms,
                                               total=(time.perf_counter() - begun) * 1000.0))

    def _stopping(self, a: Endpoint, b: Endpoint, deadline: Optional[float],
                  until: Optional[float], stage_ms: dict) -> tuple:
        """
        Return (the fastest stop-and-go answer of a request through a port or None, why not).

        Into or out of a port a move can always stop at the port's mouth: retract to the
        retracted pose, transfer, extend, each leg planned from rest to rest on the request's
        elbow branches (``_planned``, without stops of its own), then joined into one curve
        that stops where they meet (``stops.stopping_curve``) and verified like any other.
        The fastest over the elbow-branch combinations is what every non-stop curve must
        beat: so a move through a port is never slower than stopping on its way. None when
        neither end is inside a port, when the request is a single leg (a retract to its
        own retracted pose), within a time budget (``until``: the legs would not fit in
        it), or when no chain could be planned (then with the first PlanningError of a leg,
        or VERIFICATION_FAILED). Its time goes to ``stage_ms['stopping']``.
        """
        if until is not None or not (a.ways_out or b.ways_out):
            return None, None
        clock = _Clock(stage_ms)
        best, failure = None, None
        for i, (elbow_a, qa) in enumerate(a.configs):
            for j, (elbow_b, qb) in enumerate(b.configs):
                ends = _stops(a, i, 'start') + _stops(b, j, 'goal')[::-1]
                ends = [e for k, e in enumerate(ends) if k == 0
                        or not np.array_equal(e.configs[0][1], ends[k - 1].configs[0][1])]
                if len(ends) < 3:
                    continue  # one leg: the request itself
                try:
                    chain = [self._leg(start, goal, deadline)
                             for start, goal in zip(ends, ends[1:])]
                except PlanningError as exc:
                    logger.debug('branches %s -> %s: no stop-and-go chain: %s', elbow_a,
                                 elbow_b, exc)
                    failure = failure or exc
                    continue
                result = self._joined(a, b, i, j, chain)
                if result is None:
                    failure = failure or PlanningError(
                        ErrorCode.VERIFICATION_FAILED, f'the stop-and-go chain {a.label} -> '
                        f'{b.label} failed verification')
                elif best is None or result.cycle_time < best.cycle_time:
                    best = result
        clock.lap('stopping')
        return best, failure

    def _leg(self, start: Endpoint, goal: Endpoint, deadline: Optional[float]) -> PlanResult:
        """
        Return the leg from ``start`` to ``goal``, each of one configuration, planned once.

        A retract or extend serves every move through its port (the station table's six
        loaded pairs of the default cell need 10 of them, not 24): the last ``LEGS_KEPT``
        are kept, by their ends' configurations (and ways out).
        """
        key = tuple((end.configs[0][0], end.configs[0][1].tobytes(),
                     None if end.way_out(0) is None else end.way_out(0).tobytes())
                    for end in (start, goal))
        with self._legs_lock:
            leg = self._legs.get(key)
        if leg is None:
            leg = self._planned(start, goal, deadline, None, time.perf_counter(),
                                stopping=False)
            with self._legs_lock:
                if len(self._legs) >= LEGS_KEPT:
                    del self._legs[next(iter(self._legs))]
                self._legs[key] = leg
        return leg

    def _joined(self, a: Endpoint, b: Endpoint, i: int, j: int,
                chain: list) -> Optional[PlanResult]:
        """Return the legs joined into one verified answer from ``a`` to ``b``, else None."""
        trajectory = stopping_curve([leg.trajectory for leg in chain], self.cell.robot,
                                    self.settings.timing)
        qa, qb = a.configs[i][1], b.configs[j][1]
        checked = verify(trajectory, self.cell, qa, qb)
        if not checked.ok:
            logger.warning('the stop-and-go chain %s -> %s failed verification: %s', a.label,
                           b.label, '; '.join(checked.problems))
            return None
        times, positions, velocities, accelerations = trajectory.samples(
            self.settings.sample_period)
        transfer = chain[1] if a.way_out(i) is not None else chain[0]
        path = np.concatenate([chain[0].path] + [leg.path[1:] for leg in chain[1:]])
        branches = (a.configs[i][0], b.configs[j][0])
        return PlanResult(
            start=a, goal=b, start_q=qa, goal_q=qb, branches=branches, load=self.load,
            trajectory=trajectory,
            initial_cycle_time=max(sum(leg.initial_cycle_time for leg in chain),
                                   trajectory.duration),
            verification=checked, times=times, positions=positions, velocities=velocities,
            accelerations=accelerations, roadmap_path=transfer.roadmap_path, path=path,
            metrics=dict(method=self.method.name, stops=len(chain) - 1,
                         legs_cycle_time=sum(leg.cycle_time for leg in chain),
                         roadmap_path_vertices=len(transfer.roadmap_path),
                         path_vertices=len(path),
                         control_points=len(trajectory.control_points),
                         branches=list(branches), **path_lengths(self.cell, trajectory)),
            warnings=sum((leg.warnings for leg in chain), ()))

    def _prepared(self, a, b, start, goal, branches, stage_ms) -> '_Prepared':
        """
        Return the path, corridor and the method's draft between two configurations.

        ``start``, ``goal``: (q, its way out of a port or None). From inside a port the
        roadmap path starts at its retracted pose, and the corridor's control points are
        joined to the channel's (``corridor.through_ports``).
        """
        (qa, way_a), (qb, way_b) = start, goal
        model = self.cell.motion_model  # the port margins too: the corridor keeps them
        lipschitz = model.lipschitz
        route = find_path(self.roadmap, model, lipschitz,
                          qa if way_a is None else way_a[-1], qb if way_b is None else way_b[-1])
        stage_ms['connect'] += route.connect_ms
        stage_ms['search'] += route.search_ms
        if route.path is None:
            raise PlanningError(ErrorCode.NO_PATH,
                                f'no path from {a.label} to {b.label} in the roadmap '
                                f'({self.roadmap.node_count} nodes): connect more nodes or '
                                'check the cell')
        clock = _Clock(stage_ms)
        roadmap_path = simplify(route.path)
        path = shortcut(roadmap_path, model, lipschitz) if self.settings.shortcut \
            else roadmap_path
        corridor = build_corridor(path, model.body_clearance(path), lipschitz,
                                  per_body=self.settings.per_body_boxes,
                                  extra=self.settings.extra_points)
        corridor = through_ports(corridor, way_a, None if way_b is None else way_b[::-1])
        path = np.concatenate([qa[None] if way_a is not None else path[:0], path,
                               qb[None] if way_b is not None else path[:0]])
        clock.lap('corridor')
        draft = self.method.draft(corridor)
        clock.lap('spline')
        fastest = float(self.cell.robot.limits.shortest_motion(qb - qa).max())
        return _Prepared(a, b, qa, qb, branches, roadmap_path, path,
                         len(corridor.control_points), draft, fastest)

    def _finished(self, pair: '_Prepared', give_up_above, stage_ms, until=None,
                  deadline=None) -> Optional['_Candidate']:
        """Return the finished curve, not yet verified; None if it cannot win."""
        clock = _Clock(stage_ms)
        with collecting(stage_ms):  # the optimisation's parts (``stopwatch.PARTS``)
            shaped = self.method.finish(pair.draft, give_up_above, until, deadline)
        clock.lap('optimise')
        return None if shaped is None else _Candidate(pair, shaped)

    def _verified(self, candidate: '_Candidate', stage_ms) -> Verification:
        """Return the dense check of a candidate; raise VERIFICATION_FAILED if it fails."""
        clock = _Clock(stage_ms)
        pair = candidate.pair
        checked = verify(candidate.shaped.trajectory, self.cell, pair.qa, pair.qb)
        clock.lap('verify')
        if not checked.ok:
            raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                                f'the trajectory {pair.a.label} -> {pair.b.label} '
                                'failed verification: ' + '; '.join(checked.problems))
        return checked

    def adopted(self, other: PlanResult, backwards: bool = False) -> Optional[PlanResult]:
        """
        Return another answer's motion as this planner's answer if it passes its verification.

        ``backwards``: the motion reversed in time, from ``other``'s goal to its start. A
        curve planned against one limit set answers a request of another whenever it passes
        that one's verification in full (every limit, the ports, the proof, the dense
        collision check): a loaded move, say, for an empty request whose own optimised
        curve came out slower (the optimiser is local; the empty set has every freedom the
        loaded one has). Its metrics say ``adopted``. None when it does not pass.
        """
        trajectory = other.trajectory.backwards() if backwards else other.trajectory
        start_q, goal_q = (other.goal_q, other.start_q) if backwards else \
            (other.start_q, other.goal_q)
        checked = verify(trajectory, self.cell, start_q, goal_q)
        if not checked.ok:
            return None
        times, positions, velocities, accelerations = trajectory.samples(
            self.settings.sample_period)
        order = slice(None, None, -1 if backwards else 1)
        return replace(
            other, start=other.goal if backwards else other.start,
            goal=other.start if backwards else other.goal, start_q=start_q, goal_q=goal_q,
            branches=tuple(other.branches[order]), load=self.load, trajectory=trajectory,
            verification=checked, times=times, positions=positions, velocities=velocities,
            accelerations=accelerations, roadmap_path=np.asarray(other.roadmap_path)[order],
            path=np.asarray(other.path)[order],
            metrics=dict(other.metrics, adopted=True, branches=list(other.branches[order]))
            | ({'reversed': not other.metrics.get('reversed', False)} if backwards else {}))

    def faster(self, result: Optional[PlanResult], other: Optional[PlanResult],
               backwards: bool = False) -> Optional[PlanResult]:
        """
        Return ``result``, or ``other`` as this planner's answer (``adopted``) if faster.

        ``other`` is taken when it is shorter than ``result`` (or ``result`` is None) and
        passes this planner's verification; ``backwards``: ``other`` reversed in time.
        """
        if other is None or (result is not None and result.cycle_time <= other.cycle_time):
            return result
        return self.adopted(other, backwards) or result

    def _result(self, candidate: '_Candidate', checked: Verification, counts: dict,
                timings_ms: dict) -> PlanResult:
        """Return the verified candidate sampled and measured."""
        pair, trajectory = candidate.pair, candidate.shaped.trajectory
        metrics = dict(
            candidate.shaped.metrics, method=self.method.name,
            roadmap_path_vertices=len(pair.roadmap_path), path_vertices=len(pair.path),
            control_points=pair.control_points, branches=list(pair.branches), stops=0,
            **path_lengths(self.cell, trajectory), **counts)
        times, positions, velocities, accelerations = trajectory.samples(
            self.settings.sample_period)
        return PlanResult(
            start=pair.a, goal=pair.b, start_q=pair.qa, goal_q=pair.qb, branches=pair.branches,
            load=self.load, trajectory=trajectory,
            initial_cycle_time=candidate.shaped.initial_cycle_time, verification=checked,
            times=times, positions=positions, velocities=velocities,
            accelerations=accelerations, roadmap_path=pair.roadmap_path, path=pair.path,
            metrics=metrics, timings_ms=timings_ms, warnings=candidate.shaped.warnings)


def path_lengths(cell, trajectory) -> dict:
    """Return a trajectory's ``joint_path_length`` (rad) and ``wafer_path_length`` (m)."""
    dense = trajectory.evaluate(np.linspace(0.0, trajectory.duration, 2001))
    wafer = cell.robot.arm.wafer_center(dense)
    return {'joint_path_length': float(np.linalg.norm(np.diff(dense, axis=0), axis=1).sum()),
            'wafer_path_length': float(np.linalg.norm(np.diff(wafer, axis=0), axis=1).sum())}


@dataclass(frozen=True, eq=False)
class _Prepared:
    """One elbow-branch combination up to its curve method's draft."""

    a: Endpoint
    b: Endpoint
    qa: np.ndarray
    qb: np.ndarray
    branches: Tuple[Optional[int], Optional[int]]
    roadmap_path: np.ndarray
    path: np.ndarray
    control_points: int
    """How many control points the corridor placed."""
    draft: Draft
    fastest: float
    """s: no motion between the two configurations is faster (the joint limits alone)."""


@dataclass(frozen=True, eq=False)
class _Candidate:
    """A finished combination, before verification."""

    pair: _Prepared
    shaped: Shaped

    def fallback(self) -> Optional['_Candidate']:
        """Return the combination with the curve its method started from, if it has one."""
        make = self.shaped.fallback
        return None if make is None else _Candidate(self.pair, make())


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
    kept = [k for k, c in enumerate(end.configs) if c[0] == elbow]
    configs = tuple(end.configs[k] for k in kept)
    if not configs:
        raise PlanningError(ErrorCode.INVALID_REQUEST,
                            f'{role} {end.label} has no elbow branch {elbow!r} (it has '
                            f'{[c[0] for c in end.configs]})')
    return replace(end, configs=configs,
                   ways_out=tuple(end.ways_out[k] for k in kept) if end.ways_out else ())


def _stops(end: Endpoint, k: int, role: str) -> list:
    """
    Return configuration ``k`` of an end, then its retracted pose if it is inside a port.

    Each is an ``Endpoint`` of that one configuration (``role``: the end's, start or goal);
    the retracted pose of a ``<station>:inside`` end is labelled with the station's name.
    """
    elbow, q = end.configs[k]
    here = Endpoint(end.label, ((elbow, q),), (end.way_out(k),) if end.ways_out else ())
    way = end.way_out(k)
    if way is None:
        return [here]
    label = end.label[:-len(INSIDE)] if end.label.endswith(INSIDE) else \
        f'the retracted pose of the {role}'
    return [here, Endpoint(label, ((elbow, way[-1]),))]


def _check_deadline(deadline: Optional[float]) -> None:
    if deadline is not None and time.monotonic() > deadline:
        raise PlanningError(ErrorCode.TIMEOUT, 'planning did not finish before its deadline')
