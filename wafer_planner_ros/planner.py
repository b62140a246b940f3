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
from wafer_planner_ros.moves.channel import Channel, channel_bounds
from wafer_planner_ros.moves.through import compose, free_end, PortMove
from wafer_planner_ros.moves.timing import profile
from wafer_planner_ros.roadmap.search import find_path
from wafer_planner_ros.roadmap.shortcut import shortcut
from wafer_planner_ros.trajectory.corridor import build_corridor, simplify
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.methods import CurveMethod, Draft, KnotTiming, METHODS
from wafer_planner_ros.trajectory.methods import Shaped
from wafer_planner_ros.trajectory.shape_problem import FreeEnd
from wafer_planner_ros.trajectory.stopwatch import collecting, PARTS
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings
from wafer_planner_ros.trajectory.verify import Verification, verify

logger = logging.getLogger(__name__)

STAGES = ('connect', 'search', 'corridor', 'spline', 'optimise', 'verify', 'stopping')
"""The stages of a plan, timed in its ``timings_ms`` (with ``PARTS`` of them and ``total``).
Of a move through a port: ``corridor`` its ways through the ports (their bounds and free
ends), ``stopping`` its transfer planned at rest between the port mouths (``Planner._leg``),
``optimise`` the transfer blended into the ways (``CurveMethod.blend``), ``verify`` the
moves checked whole."""

KNOWN_LISTED = 10
"""The stations an UNKNOWN_STATION message lists (then how many more there are)."""
MAX_QUOTED = 200
"""Most characters of a requested station name quoted in a message."""
LEGS_KEPT = 64
"""The stop-and-go legs a planner keeps (``Planner._leg``): every retract and extend of 16
stations with ports on both elbow branches, with 32 transfers between them."""
LEGS_SHARE = 0.75
"""Of the time to a budgeted request's deadline, the share a move through a port may spend
on its transfer (``_through``): the rest verifies and answers."""
AT_MOUTH = 1e-9
"""m: joint angles whose wafer centre is at most this far past a port's mouth are at the
mouth, not inside the port (rounding puts a retracted pose a hair inside)."""
MAX_WAY_TIME = 30.0
"""s: a way through a port that takes longer from rest to rest is refused (NO_PATH)."""
CHANNEL_CHECKS = 65
"""Configurations along the way out of a port from joint angles inside it checked against
the position limits (the proof and the verification check the move itself)."""
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
    channels: Tuple[Optional[Channel], ...] = ()
    """Per configuration inside a port (a ``<station>:inside`` request, or joint angles
    inside a port): its straight way out to the port's mouth (``moves.channel``), else
    None; empty when no configuration is inside a port."""

    def channel(self, k: int) -> Optional[Channel]:
        """Return the way out of a port of configuration ``k`` (None: not inside one)."""
        return self.channels[k] if self.channels else None


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
        self._by_method = {settings.method: self}
        self._legs: dict = {}
        """The transfers between port mouths planned so far (``_leg``), at most
        ``LEGS_KEPT``."""
        self._drafts: dict = {}
        """The other elbow-branch combinations those answers finished, not yet verified
        (``_leg``), at most ``LEGS_KEPT``."""
        self._ends: dict = {}
        """The ways through ports as free ends (``_free_end``), at most ``LEGS_KEPT``."""
        self._bounds: dict = {}
        """The bounds along each channel, or why it has none (``_channel``)."""
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

    def with_method(self, method: Type[CurveMethod]) -> 'Planner':
        """
        Return the planner of this cell, roadmap and limit set with another curve method.

        One per method, shared: what one plans between port mouths (``_leg``) serves the
        moves through the ports the other plans.
        """
        if method not in self._by_method:
            planner = Planner(self.cell, self.roadmap, replace(self.settings, method=method))
            planner._by_method = self._by_method
            self._by_method[method] = planner
        return self._by_method[method]

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
            port = station.port
            return Endpoint(value, tuple((None if joints else c.elbow, c.q)
                                         for c in station.inside),
                            tuple(Channel.out_of(robot.arm, c.q, port.axis, port.depth,
                                                 mouth=retracted[c.elbow])
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
        channel = self._channel_of(q, role)
        return Endpoint(label, ((None, q),), () if channel is None else (channel,))

    def _channel_of(self, q: np.ndarray, role: str) -> Optional[Channel]:
        """
        Return the way out of the port joint angles ``q`` are inside, None if in none.

        The wafer centre moves parallel to the port's axis, the blade keeping its heading,
        out to the port's mouth: refused when ``q`` breaks the port's tolerances, or when
        the way leaves the position limits.
        """
        ports = self.cell.port_model
        k = int(ports.inside(q)[0])
        if k < 0:
            return None
        how = describe_deviation(ports, q)
        if how is not None:
            raise PlanningError(ErrorCode.OUT_OF_LIMITS, f'{role} {q.tolist()}: {how}')
        port, robot = ports.ports[k], self.cell.robot
        length = float(port.offsets(robot.arm.wafer_center(q[None]))[0][0])
        if length <= AT_MOUTH:
            # At the mouth itself, a rounding inside (a station's own retracted pose):
            # there is no way out to take, and one of that length would end at the
            # mouth's inverse kinematics, not exactly at q.
            return None
        channel = Channel.out_of(robot.arm, q, port.axis, length)
        lower, upper = robot.limits.position.T
        along = channel.configurations(np.linspace(0.0, length, CHANNEL_CHECKS))
        if not np.all((along >= lower) & (along <= upper)):
            raise PlanningError(ErrorCode.OUT_OF_LIMITS,
                                f'{role} {q.tolist()} is inside the port of {port.station}, '
                                f'whose way out on its elbow branch (to '
                                f'{channel.mouth.round(4).tolist()}) leaves '
                                'robot.joint_limits.position')
        return channel

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
        return self._planned(*self._ends_of(start, goal, branches), deadline, until, begun)

    def _ends_of(self, start, goal, branches) -> Tuple[Endpoint, Endpoint]:
        """Return the resolved ends of a request, each on its branch of ``branches`` if given."""
        a, b = self.endpoint(start, 'start'), self.endpoint(goal, 'goal')
        if branches is None:
            return a, b
        return tuple(_only_branch(end, elbow, role) for end, elbow, role in
                     ((a, branches[0], 'start'), (b, branches[1], 'goal')))

    def _planned(self, a: Endpoint, b: Endpoint, deadline: Optional[float],
                 until: Optional[float], begun: float) -> PlanResult:
        """Return the fastest verified answer between two resolved ends (``plan``)."""
        if a.channels or b.channels:
            return self._through(a, b, deadline, until, begun, blend=True)
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
                    prepared.append(self._prepared(a, b, qa, qb, (elbow_a, elbow_b),
                                                   stage_ms))
                except PlanningError as exc:
                    logger.debug('branches %s -> %s dropped: %s', elbow_a, elbow_b, exc)
                    failure = failure or exc
        bound = None
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
            ordered = sorted(candidates, key=lambda c: c.shaped.trajectory.duration)
            for k, candidate in enumerate(ordered):
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
                counts = {'candidates': len(prepared), 'given_up': len(given_up)}
                result = self._result(candidate, checked, counts, dict(
                    stage_ms, total=(time.perf_counter() - begun) * 1000.0))
                if until is None:  # a transfer between port mouths, should one ask for it
                    self.keep(result)
                    for other in ordered[k + 1:]:  # the slower ones, not verified (``_leg``)
                        self._keep(self._drafts, _leg_key(
                            other.pair.qa, other.pair.qb, other.pair.branches), (other, counts))
                return result
            # Every faster one failed verification: finish those given up after all.
            candidates = [c for c in (self._finished(pair, bound, stage_ms, until, deadline)
                                      for pair in given_up) if c is not None]
            given_up = []
        raise failure

    def stop_and_go(self, start, goal, deadline: Optional[float] = None,
                    load: Optional[str] = None,
                    branches: Optional[Tuple[Optional[int], Optional[int]]] = None
                    ) -> PlanResult:
        """
        Return the move through a port that stops at each port mouth, verified (``_through``).

        The same move as ``plan`` without blending the ways through the ports into the
        transfer: straight out of the start's port to rest at its mouth, the transfer from
        rest to rest, straight into the goal's port. ``load`` and ``branches`` as for
        ``plan``. Raises PlanningError: INVALID_REQUEST when neither end is inside a port,
        else the first reason none could be planned.
        """
        if load is not None and load != self.load:
            return self.for_load(load).stop_and_go(start, goal, deadline, branches=branches)
        begun = time.perf_counter()
        a, b = self._ends_of(start, goal, branches)
        if not (a.channels or b.channels):
            raise PlanningError(ErrorCode.INVALID_REQUEST,
                                f'{a.label} -> {b.label} does not stop on its way: neither '
                                'end is inside a port')
        return self._through(a, b, deadline, None, begun, blend=False)

    def _through(self, a: Endpoint, b: Endpoint, deadline: Optional[float],
                 until: Optional[float], begun: float, blend: bool) -> PlanResult:
        """
        Return the fastest verified move through a port between two resolved ends.

        Per elbow-branch combination: straight out of the start's port along its axis
        (``moves.channel``), the transfer between the two port mouths, straight into the
        goal's port. The transfer is first planned from rest to rest (``_leg``: a move
        between the mouths, planned once per planner without a budget), which makes the
        move that stops at the mouths (``moves.through.compose``); with ``blend`` the curve
        method then optimises the transfer with each mouth a free end
        (``CurveMethod.blend``: the mouth speeds chosen with the transfer, the ways through
        the ports timed to meet them), and the faster verified move is kept. Combinations
        are taken fastest first by the joints' own shortest motion between the mouths plus
        the ways at their fastest, and given up when that cannot beat the best so far.
        Every answer is verified as a whole (``verify``).
        """
        stage_ms = dict.fromkeys(STAGES + PARTS, 0.0)
        clock = _Clock(stage_ms)
        combinations, failure = [], None
        for i, (elbow_a, qa) in enumerate(a.configs):
            for j, (elbow_b, qb) in enumerate(b.configs):
                if np.array_equal(qa, qb):
                    raise PlanningError(ErrorCode.INVALID_REQUEST,
                                        f'start and goal are the same configuration '
                                        f'{qa.tolist()}')
                try:
                    ways = [self._channel(a, i), self._channel(b, j)]
                except PlanningError as exc:
                    failure = failure or exc
                    continue
                mouths = [q if way is None else way[0].mouth for q, way in zip((qa, qb), ways)]
                fastest = float(self.cell.robot.limits.shortest_motion(
                    mouths[1] - mouths[0]).max()) + sum(
                        self._free_end(way).least_time for way in ways if way is not None)
                combinations.append((fastest, i, j, ways, mouths))
        clock.lap('corridor')
        best, tried = None, 0
        # Within a budget, the transfer (planned, unless kept from an earlier answer, and
        # blended) may take up to LEGS_SHARE of the time to the deadline: the budget alone
        # leaves it slower than the move stopping at the mouths unbudgeted. Once one move is
        # verified and that time is spent, only the combinations whose transfer is kept
        # are tried.
        left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
        legs_until = until if until is None or left is None else \
            max(until, time.monotonic() + LEGS_SHARE * left)
        for fastest, i, j, ways, mouths in sorted(combinations, key=lambda c: c[0]):
            _check_deadline(deadline)
            if best is not None and fastest >= best.cycle_time:
                continue
            (elbow_a, _), (elbow_b, _) = a.configs[i], b.configs[j]
            if best is not None and legs_until is not None and \
                    time.monotonic() >= legs_until and not self._kept(
                        mouths, (elbow_a, elbow_b)):
                continue
            if np.array_equal(*mouths):
                # Only out of a port to its mouth, or only in: the way alone.
                result = self._answer(a, b, i, j, None, compose(None, *ways), {}, ())
                if result is None:
                    failure = failure or PlanningError(
                        ErrorCode.VERIFICATION_FAILED,
                        f'the move {a.label} -> {b.label} failed verification')
                elif best is None or result.cycle_time < best.cycle_time:
                    best, tried = result, tried + 1
                continue
            ends = [Endpoint(end.label if way is None else _mouth_label(end, role),
                             ((elbow, mouth),))
                    for end, role, way, elbow, mouth in zip(
                        (a, b), ('start', 'goal'), ways, (elbow_a, elbow_b), mouths)]
            try:
                transfer = self._leg(*ends, deadline, legs_until)
                stop = compose(transfer.trajectory, *ways)
            except PlanningError as exc:
                logger.debug('branches %s -> %s: no transfer: %s', elbow_a, elbow_b, exc)
                failure = failure or exc
                continue
            tried += 1
            moves = [(stop, transfer.metrics, transfer.warnings)]
            if blend:
                clock.lap('stopping')
                with collecting(stage_ms):
                    shaped = self.method.blend(
                        transfer.trajectory, [None if way is None else self._free_end(way)
                                              for way in ways],
                        None if best is None else best.cycle_time, legs_until, deadline)
                clock.lap('optimise')
                try:
                    if shaped is not None:
                        moves.insert(0, (compose(shaped.trajectory, *ways),
                                         dict(transfer.metrics, **shaped.metrics),
                                         transfer.warnings + shaped.warnings))
                except ValueError as exc:  # a mouth state no way through its port meets
                    logger.warning('the move %s -> %s, blended, is left: %s', a.label,
                                   b.label, exc)
            # Fastest first: stopping can be the faster where a mouth is near a fold.
            for move, metrics, warnings in sorted(moves, key=lambda m: m[0].duration):
                if best is not None and move.duration >= best.cycle_time:
                    continue
                result = self._answer(a, b, i, j, transfer, move, metrics, warnings)
                clock.lap('verify')
                if result is None:
                    failure = failure or PlanningError(
                        ErrorCode.VERIFICATION_FAILED,
                        f'the move {a.label} -> {b.label} failed verification')
                    continue
                best = result
                break
        if best is None:
            raise failure or PlanningError(ErrorCode.NO_PATH,
                                           f'no move from {a.label} to {b.label}')
        return replace(best, metrics=dict(best.metrics, candidates=len(combinations),
                                          given_up=len(combinations) - tried),
                       timings_ms=dict(stage_ms,
                                       total=(time.perf_counter() - begun) * 1000.0))

    def _channel(self, end: Endpoint, k: int) -> Optional[tuple]:
        """
        Return (Channel, Bounds) of configuration ``k``'s way out of its port, or None.

        The bounds are this planner's limit set's along it (``channel_bounds``).
        """
        channel = end.channel(k)
        if channel is None:
            return None
        key = (channel.inside.tobytes(), channel.mouth.tobytes(), channel.length)
        with self._legs_lock:
            found = self._bounds.get(key)
        if found is None:
            try:
                found = channel_bounds(channel, self.cell.robot)
            except ValueError as exc:
                found = str(exc)
            else:
                took = profile(channel.length, 0.0, found.at(0.0, 0.0)).duration
                if took > MAX_WAY_TIME:
                    found = (f'its straight way out of the port takes {took:.1f} s at the '
                             f'{self.load} limits (over {MAX_WAY_TIME:g} s: the arm is nearly '
                             'folded or stretched along it)')
            self._keep(self._bounds, key, found)
        if isinstance(found, str):
            raise PlanningError(ErrorCode.NO_PATH, f'{end.label}: {found}')
        return channel, found

    def _free_end(self, way: tuple) -> FreeEnd:
        """Return a way through a port as the transfer's free end (kept per channel)."""
        channel, bounds = way
        key = (channel.inside.tobytes(), channel.mouth.tobytes(), bounds)
        with self._legs_lock:
            end = self._ends.get(key)
        if end is None:
            end = free_end(channel, bounds)
            self._keep(self._ends, key, end)
        return end

    def _leg(self, start: Endpoint, goal: Endpoint, deadline: Optional[float],
             until: Optional[float] = None) -> PlanResult:
        """
        Return the move from ``start`` to ``goal``, each of one configuration, planned once.

        A transfer between two port mouths serves every move through those ports: the last
        ``LEGS_KEPT`` answers this planner gave without a budget are kept, by their ends'
        configurations and branches (``_planned``; the station table's station pairs are
        such answers), and so are the other elbow-branch combinations such an answer
        finished (optimised as far as they go, but not verified, as only the fastest is):
        one of those is verified when a move first asks for it, and planned again if it
        fails. One planned within a budget (``until``) is not kept.
        """
        key = _leg_key(start.configs[0][1], goal.configs[0][1],
                       (start.configs[0][0], goal.configs[0][0]))
        with self._legs_lock:
            leg = self._legs.get(key)
            draft = None if leg is not None else self._drafts.pop(key, None)
        if draft is not None:
            leg = self._drafted(*draft)
        if leg is None:
            leg = self._planned(start, goal, deadline, until, time.perf_counter())
        return leg

    def _drafted(self, candidate: '_Candidate', counts: dict) -> Optional[PlanResult]:
        """Return a kept combination verified as an answer (and keep it), None if it fails."""
        begun = time.perf_counter()
        stage_ms = dict.fromkeys(STAGES + PARTS, 0.0)
        try:
            checked = self._verified(candidate, stage_ms)
        except PlanningError as exc:
            logger.debug('a kept combination is planned again: %s', exc)
            return None
        result = self._result(candidate, checked, counts, dict(
            stage_ms, total=(time.perf_counter() - begun) * 1000.0))
        self.keep(result)
        return result

    def keep(self, result: PlanResult) -> None:
        """
        Keep a verified answer planned without a budget as a transfer between its ends.

        A move through a port whose mouths are its ends, on its branches, takes it as its
        transfer (``_leg``) instead of planning one.
        """
        self._keep(self._legs, _leg_key(result.start_q, result.goal_q, result.branches),
                   result)

    def _kept(self, mouths, branches) -> bool:
        """Return whether the transfer between two mouths on their branches is kept."""
        with self._legs_lock:
            return _leg_key(*mouths, branches) in self._legs

    def _keep(self, kept: dict, key, value) -> None:
        """Keep ``value`` in one of this planner's caches, the oldest out beyond LEGS_KEPT."""
        with self._legs_lock:
            if key not in kept and len(kept) >= LEGS_KEPT:
                del kept[next(iter(kept))]
            kept[key] = value

    def _answer(self, a: Endpoint, b: Endpoint, i: int, j: int,
                transfer: Optional[PlanResult], move: PortMove, metrics: Mapping,
                warnings) -> Optional[PlanResult]:
        """
        Return a move through a port from ``a`` to ``b`` as a verified answer, else None.

        ``transfer``: the planned transfer the move's was made from (None: a way alone).
        """
        qa, qb = a.configs[i][1], b.configs[j][1]
        checked = verify(move, self.cell, qa, qb)
        if not checked.ok:
            logger.warning('the move %s -> %s failed verification: %s', a.label, b.label,
                           '; '.join(checked.problems))
            return None
        times, positions, velocities, accelerations = move.samples(
            self.settings.sample_period)
        roadmap_path = np.empty((0, 3)) if transfer is None else transfer.roadmap_path
        path = np.stack([qa, qb]) if transfer is None else np.concatenate(
            [qa[None]] * (move.out is not None) + [transfer.path]
            + [qb[None]] * (move.into is not None))
        branches = (a.configs[i][0], b.configs[j][0])
        speeds = [0.0 if way is None else way.profile.end_speed
                  for way in (move.out, move.into)]
        braking = [0.0 if way is None else -way.profile.end_acceleration
                   for way in (move.out, move.into)]
        stops = sum(way is not None and way.profile.end_speed == 0.0
                    for way in (move.out, move.into))
        return PlanResult(
            start=a, goal=b, start_q=qa, goal_q=qb, branches=branches, load=self.load,
            trajectory=move,
            initial_cycle_time=move.in_port_time + (
                0.0 if transfer is None else transfer.initial_cycle_time),
            verification=checked, times=times, positions=positions, velocities=velocities,
            accelerations=accelerations, roadmap_path=roadmap_path, path=path,
            metrics=dict(metrics, method=self.method.name, stops=stops,
                         start_mouth_speed=speeds[0], goal_mouth_speed=speeds[1],
                         start_mouth_braking=braking[0], goal_mouth_braking=braking[1],
                         in_port_time=move.in_port_time,
                         transfer_time=move.duration - move.in_port_time,
                         roadmap_path_vertices=len(roadmap_path),
                         path_vertices=len(path),
                         control_points=0 if move.transfer is None else len(
                             move.transfer.control_points),
                         branches=list(branches), **path_lengths(self.cell, move)),
            warnings=tuple(warnings))

    def _prepared(self, a, b, qa, qb, branches, stage_ms) -> '_Prepared':
        """Return the path, corridor and the method's draft between two configurations."""
        model = self.cell.motion_model  # the port margins too: the corridor keeps them
        lipschitz = model.lipschitz
        route = find_path(self.roadmap, model, lipschitz, qa, qb)
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
                   channels=tuple(end.channels[k] for k in kept) if end.channels else ())


def _leg_key(qa: np.ndarray, qb: np.ndarray, branches) -> tuple:
    """Return the key of a move between two configurations on their branches (``_leg``)."""
    return tuple((branch, q.tobytes()) for branch, q in zip(branches, (qa, qb)))


def _mouth_label(end: Endpoint, role: str) -> str:
    """Return the label of where an end inside a port leaves it: its station's name."""
    return end.label[:-len(INSIDE)] if end.label.endswith(INSIDE) else \
        f'the port mouth of the {role}'


def _check_deadline(deadline: Optional[float]) -> None:
    if deadline is not None and time.monotonic() > deadline:
        raise PlanningError(ErrorCode.TIMEOUT, 'planning did not finish before its deadline')
