"""
A controlled stop: from any moment of a curve to rest on its own path, as fast as the limits allow.

The stop keeps the path the robot is on (the wafer stays where the curve was proven to
take it) and changes only how fast it is followed: sigma, the curve's own time, from the
moment ``at`` (sigma' = 1, sigma'' = 0: exactly the curve's state) down to sigma' = 0
(``retimed.Retimed``). Along a path every limit is a bound on the timing: with g', g'', g'''
the path's derivatives by sigma,

- acceleration: |g'' sigma'^2 + g' sigma''| <= A per joint, and the wafer's acceleration,
  sigma'^2 w2 + sigma'' w1 (w2 the curve's own, w1 that of g' as an acceleration), within
  its limits on x, y (and |a|);
- jerk: |g''' sigma'^3 + 3 g'' sigma' sigma'' + g' sigma'''| <= J per joint;
- velocity: |g' sigma'| <= V holds already, sigma' never exceeding 1.

The timing is built forwards in steps of ``STEP`` seconds of constant jerk by a compiled
kernel (``braking.brake``) on the path's derivatives sampled every ``GRID`` seconds of its
own time and on both sides of each of its breaks: brake as hard as the limits allow, and
ease the deceleration off in time to come to rest within the jerk limits. Each stop is
then checked ten times as densely as the verification checks an answer (``_keeps``); one
that misses a limit is built again keeping a smaller share of each limit (``SHARES``), and
where none keeps them all, after following the move a little first (``COASTS``). Where
none is sooner at rest, the rest of the curve itself is the stop (verified, it ends at
rest): on a time-optimal move that is already braking to its goal as hard as its limits
allow, nothing on its path stops much sooner.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.trajectory.braking import brake, GAVE_UP, PAST
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.verify import limit_ratios

STEP = 0.002
"""s: the time of one constant-jerk phase of a stop's timing."""
BREAK_SIDE = 1e-9
"""s: how far before each of the curve's breaks its piece there is sampled (``_path``)."""
GRID = 0.0005
"""s of the curve's own time between the samples of the limits along the path."""
DENSE = 1e-4
"""s between the checks of a stop's limits (``_keeps``)."""
WINDOW = 0.5
"""s of the curve's own time sampled first; doubled while a stop runs past it."""
MAX_STEPS = 20_000
"""Phases of one stop at most (40 s): a stop never lasts so long on a planned curve."""
SHARES = (1.0, 0.995, 0.98)
"""The shares of each limit the stop's timing keeps, tried in turn (the module)."""
COASTS = (0.0, 0.02, 0.08)
"""s the move is followed before braking, tried in turn where braking at once keeps no
share of the limits (``_braked``)."""
HALVINGS = 12
"""Halvings that find how hard a step may brake where the hardest would not ease off."""
AT_REST = 1e-9
"""rad/s, rad/s^2: a curve whose velocity and acceleration are no larger is at rest."""


@dataclass(frozen=True)
class Stop:
    """A controlled stop and how it was found."""

    trajectory: Trajectory
    """The stop: a ``Retimed`` of the curve, or the curve's rest where no timing keeps the
    limits (``Retimed`` with sigma = t)."""
    share: Optional[float]
    """The share of the limits the braked timing kept (``SHARES``); None for the others."""
    timing: str
    """'braked' (step by step under the limits along the path) or 'rest' (the rest of the
    curve: no braked timing kept every limit sooner)."""


def moving_state(trajectory: Trajectory, at: float) -> tuple:
    """
    Return (q, q', q'') of ``trajectory`` at ``at``; raise PlanningError where no stop is.

    OUTSIDE_TRAJECTORY when ``at`` is not a number within [0, duration]; AT_REST when the
    curve is at rest there (velocity and acceleration within ``AT_REST``).
    """
    duration = trajectory.duration
    if not (isinstance(at, (int, float)) and 0.0 <= at <= duration):
        raise PlanningError(ErrorCode.OUTSIDE_TRAJECTORY,
                            f'a stop at {at!r} s of a trajectory of {duration:.6g} s: it '
                            'must be within it')
    q, qd, qdd = (x[0] for x in trajectory.evaluate_orders([float(at)], (0, 1, 2)))
    if max(np.abs(qd).max(), np.abs(qdd).max()) <= AT_REST:
        raise PlanningError(ErrorCode.AT_REST,
                            f'the trajectory is at rest at {at:.6g} s: there is nothing to '
                            'stop')
    return q, qd, qdd


def controlled_stop(trajectory: Trajectory, at: float, robot) -> Stop:
    """
    Return the stop of ``trajectory`` from ``at`` on its path, the soonest found (the module).

    Under every limit of ``robot``'s limit set, checked more densely than the verification
    does; the braking kernel's timing, or the rest of the curve where none keeps every
    limit sooner (so not always the time-optimal stop). Raise PlanningError as
    ``moving_state`` does.
    """
    moving_state(trajectory, at)
    at = float(at)
    limit_set = robot.limit_set
    limits = limit_set.joints
    jerk = np.full(3, np.inf) if limits.jerk is None else np.asarray(limits.jerk, float)
    wafer = np.full(3, np.inf)
    if limit_set.wafer is not None:
        given = np.asarray(limit_set.wafer.values, float)
        wafer[:len(given)] = given
    braked = _braked(trajectory, at, robot, limits.acceleration, jerk, wafer)
    if braked is not None and braked.trajectory.duration < trajectory.duration - at:
        return braked
    return rest_of(trajectory, at)


def followed(ahead: Stop, trajectory: Trajectory, at: float) -> Stop:
    """
    Return the stop of ``trajectory`` from ``at`` that follows it to ``ahead``'s moment first.

    ``ahead``: a stop of ``trajectory`` (``controlled_stop``) from a moment no earlier than
    ``at``. The move until that moment (sigma = t), then ``ahead``'s timing: the same limits
    hold on each part, and at the join sigma' = 1, sigma'' = 0 on both sides (the move's
    own state). The rest of the move instead where that is no later at rest (where
    ``ahead`` is the rest of the move, the same motion, joined at its moment).
    Raise PlanningError as ``moving_state`` does; ValueError for a stop from before ``at``.
    """
    moving_state(trajectory, at)
    at = float(at)
    timing = ahead.trajectory.timing
    moment = float(timing.states[0, 0])
    if not (ahead.trajectory.base is trajectory and moment >= at):
        raise ValueError(f'a stop from {moment:.9g} s of another curve, or before {at:.9g} s')
    rest = trajectory.duration - at
    if moment == at:
        return ahead
    coast = moment - at
    if ahead.timing != 'rest' and coast + timing.duration >= rest:
        return rest_of(trajectory, at)  # braking there is no sooner at rest
    # (Where ``ahead`` is the rest of the move, so is this: the move, joined at the moment.)
    phases = _coasted((timing.starts, timing.jerks, timing.states), at, coast)
    # Its breaks: where the move's own are crossed while it is followed (sigma = t), the
    # join (sigma'' = 0 there), then the stop's, later by ``coast``.
    breaks = np.unique(np.concatenate([[0.0, coast], _crossed(trajectory, at, moment),
                                       ahead.trajectory.breaks() + coast]))
    return Stop(Retimed(trajectory, JerkProfile(*phases), breaks), ahead.share, ahead.timing)


def rest_of(trajectory: Trajectory, at: float) -> Stop:
    """Return the rest of ``trajectory`` from ``at`` as a stop (sigma = t): it ends at rest."""
    rest = trajectory.duration - at
    breaks = np.unique(np.concatenate([[0.0, rest],
                                       _crossed(trajectory, at, trajectory.duration)]))
    return Stop(Retimed(trajectory, JerkProfile(np.array([0.0, rest]), np.zeros(1), np.array(
        [[at, 1.0, 0.0], [trajectory.duration, 1.0, 0.0]])), breaks), None, 'rest')


def _crossed(trajectory: Trajectory, at: float, until: float) -> np.ndarray:
    """Return when a curve followed as it is (sigma = t) from ``at`` is at its breaks < until."""
    base = trajectory.breaks()
    return base[(base > at) & (base < until)] - at


def _braked(trajectory, at, robot, acceleration, jerk, wafer) -> Optional[Stop]:
    """
    Return the soonest braked stop (``braking.brake``) that keeps every limit, or None.

    Braking at once first; where no share of the limits keeps them all, the move is
    followed a while before braking (``COASTS``): limits that a curve already at them
    leaves no room in for braking give room a little further on.
    """
    left = trajectory.duration - at
    window = min(WINDOW, left)
    for coast in COASTS:
        if coast >= left:
            return None
        while True:
            path = _path(trajectory, robot.arm, at, min(at + coast + window, at + left))
            stop, ended = _shares(trajectory, path, at, coast, robot, acceleration,
                                  jerk, wafer)
            if stop is not None:
                return stop
            if ended or coast + window >= left:
                break
            window = min(2.0 * window, left - coast)
    return None


def _shares(trajectory, path, at, coast, robot, acceleration, jerk, wafer) -> tuple:
    """
    Return (stop or None, whether every try ended): braking ``coast`` s after ``at``.

    Each share of the limits in turn (``SHARES``); a try no sooner at rest than the rest
    of the move is not checked (``_keeps``): it would not be the stop.

    A try that runs past the samples ends none: the caller samples more of the path.
    """
    begin = at + coast
    left = trajectory.duration - at
    q, qd, qdd = (x[0] for x in trajectory.evaluate_orders([begin], (0, 1, 2)))
    state = np.abs(qdd), np.abs(robot.arm.wafer_acceleration(q, qd, qdd))
    for share in SHARES:
        phases, status = _timing(path, begin, left - coast,
                                 *_kept(acceleration, wafer, share, *state), jerk * share)
        if status == PAST:
            return None, False
        if status == GAVE_UP:
            continue
        if coast + phases[0][-1] >= left:
            continue  # no sooner at rest than the rest of the move (rounding)
        if coast > 0.0:
            # From ``at`` itself: (at + coast) - coast need not be ``at`` again.
            phases = _coasted(phases, at, coast)
        stop = Retimed(trajectory, JerkProfile(*phases))
        if _keeps(stop, robot):
            return Stop(stop, share, 'braked'), True
    return None, True


def _kept(acceleration, wafer, share: float, moving, wafer_moving) -> tuple:
    """
    Return the (acceleration, wafer) bounds a timing keeping ``share`` of them starts from.

    ``share`` of each, or what the curve already demands where the braking begins
    (``moving``; ``wafer_moving``, on x and y) if that is more: a time-optimal move is at
    its limits most of the way, and a bound below where it is would make the timing jerk
    at once, far over the jerk limit, to get under it. The jerk keeps its share.
    """
    accelerations = np.maximum(np.asarray(acceleration, float) * share, moving)
    wafers = np.asarray(wafer, float) * share   # x, y and |a|
    moving_wafer = np.append(wafer_moving, np.hypot(*wafer_moving))
    return accelerations, np.maximum(wafers, moving_wafer)


def _coasted(phases: tuple, at: float, coast: float) -> tuple:
    """Return a stop's phases after ``coast`` s following the move from ``at`` (sigma = t)."""
    starts, jerks, states = phases
    return (np.concatenate([[0.0], starts + coast]), np.concatenate([[0.0], jerks]),
            np.concatenate([[[at, 1.0, 0.0]], states]))


def _keeps(stop: Trajectory, robot) -> bool:
    """
    Return whether a stop keeps every limit, checked every ``DENSE`` s.

    The verification checks every millisecond; within a step of the stop's timing its
    jerk and accelerations move (the path's derivatives under a changing sigma), so the
    stop is checked ten times as densely.
    """
    return all(r <= 1.0 for r in limit_ratios(stop, robot, step=DENSE).values())


def hold_demand(trajectory: Trajectory, at: float, robot, samples: int = 2001) -> float:
    """
    Return the peak wafer acceleration (m/s^2) of an abrupt hold of ``trajectory`` at ``at``.

    The hold a controller makes without a planner (``hold_motion``): its wafer acceleration
    on x and y from the first instant on, sampled until the last joint rests.
    """
    _, q, qd, qdd = hold_motion(trajectory, at, robot, samples)
    return float(np.abs(robot.arm.wafer_acceleration(q, qd, qdd)).max())


def hold_motion(trajectory: Trajectory, at: float, robot, samples: int = 2001) -> tuple:
    """
    Return (t (N,), q, qd, qdd (N, J)): an abrupt hold of ``trajectory`` from ``at``.

    Each joint braked on its own at its acceleration limit to rest, off the path and with
    no jerk limit (as ``joint_trajectory_controller`` stops on a cancel); ``samples``
    instants from ``at`` (t = 0) until the last joint rests (t = the hold's duration).
    """
    q0, v0, _ = (x[0] for x in trajectory.evaluate_orders([float(at)], (0, 1, 2)))
    braking = np.asarray(robot.limit_set.joints.acceleration, float)
    rests = np.abs(v0) / braking
    t = np.linspace(0.0, max(float(rests.max()), 1e-9), samples)[:, None]
    moving = t < rests
    sign = np.sign(v0)
    qdd = np.where(moving, -sign * braking, 0.0)
    tau = np.minimum(t, rests)
    qd = v0 - sign * braking * tau
    q = q0 + v0 * tau - 0.5 * sign * braking * tau ** 2
    return t[:, 0], q, qd, qdd


def _path(trajectory: Trajectory, arm, begin: float, end: float) -> tuple:
    """
    Return the path's samples from ``begin`` to ``end`` (its own time) for ``braking.brake``.

    Every ``GRID`` seconds, and on both sides of each of the curve's breaks (where its
    higher derivatives jump: a jump is then never smeared over a sample's width).
    """
    count = max(int(np.ceil((end - begin) / GRID)), 1) + 1
    breaks = trajectory.breaks()
    breaks = breaks[(breaks > begin) & (breaks < end)]
    s = np.unique(np.concatenate([np.linspace(begin, end, count), breaks,
                                  breaks - BREAK_SIDE]))
    q, g1, g2, g3 = trajectory.evaluate_orders(s, range(4))
    zero = np.zeros_like(g1)
    w2 = arm.wafer_acceleration(q, g1, g2)
    w1 = arm.wafer_acceleration(q, zero, g1)
    return s, breaks, g1, g2, g3, w1, w2


def _timing(path: tuple, begin: float, horizon: float, acceleration, wafer, jerk) -> tuple:
    """
    Return ((starts, jerks, states), status: ``RESTED``, ``PAST`` or ``GAVE_UP``).

    ``horizon``: s of the stop's own time it must be at rest before (``braking.brake``).
    """
    s, breaks, g1, g2, g3, w1, w2 = path
    starts = np.empty(MAX_STEPS + 1)
    jerks = np.empty(MAX_STEPS)
    states = np.empty((MAX_STEPS + 1, 3))
    count, status = brake(s, breaks, g1, g2, g3, w1, w2,
                          np.asarray(acceleration, float), np.asarray(jerk, float),
                          np.asarray(wafer, float), STEP, HALVINGS, begin, float(horizon),
                          starts, jerks, states)
    return (starts[:count + 1].copy(), jerks[:count].copy(),
            states[:count + 1].copy()), int(status)
