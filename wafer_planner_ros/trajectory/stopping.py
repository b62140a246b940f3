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

The timing is built forwards in steps of ``STEP`` seconds of constant jerk
(``_brake``, compiled): brake as hard as the jerk allows, down to the largest deceleration
the acceleration limits leave at each state, and ease the deceleration off at the moment
that brings sigma' and sigma'' to zero together with the jerk still within its limit
(sigma'' = -sqrt(2 J' sigma'), J' the jerk then available): the time-optimal stop of one
axis (Ruckig's velocity interface) with bounds that follow the path. The limits along the
path between the steps are linear between samples ``GRID`` seconds of path time apart.
Checked then exactly as the verification checks every answer (``verify.limit_ratios``);
a stop that misses a limit between the steps is built again keeping a smaller share of
each limit (``SHARES``). Where none keeps them all, or none is sooner at rest, the rest of
the curve itself is the stop (verified, it ends at rest): on a time-optimal move that is
already braking as hard as its limits allow to its goal, nothing on its path stops sooner.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.kernels import kernel
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.verify import limit_ratios

STEP = 0.002
"""s: the time of one constant-jerk phase of a stop's timing."""
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
HALVINGS = 12
"""Halvings that find how hard a step may brake where the hardest would not ease off."""
TOLERANCE = 1e-9
"""Relative: how far a state may be past a bound and count as on it (``_eases``)."""
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
    Return the fastest stop of ``trajectory`` from ``at`` on its path (the module).

    Under every limit of ``robot``'s limit set, checked as the verification does; raise
    PlanningError as ``moving_state`` does.
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
    rest = trajectory.duration - at
    return Stop(Retimed(trajectory, JerkProfile(np.array([0.0, rest]), np.zeros(1), np.array(
        [[at, 1.0, 0.0], [trajectory.duration, 1.0, 0.0]]))), None, 'rest')


def _braked(trajectory, at, robot, acceleration, jerk, wafer) -> Optional[Stop]:
    """Return the stop braked step by step (``_brake``) that keeps every limit, or None."""
    window = min(WINDOW, trajectory.duration - at)
    while True:
        path = _path(trajectory, robot.arm, at, at + window)
        for share in SHARES:
            phases, ended = _timing(path, acceleration, jerk, wafer, share)
            if not ended:
                break  # past the sampled window: sample more of the path
            stop = Retimed(trajectory, JerkProfile(*phases))
            if _keeps(stop, robot):
                return Stop(stop, share, 'braked')
        else:
            return None
        if at + window >= trajectory.duration:
            return None
        window = min(2.0 * window, trajectory.duration - at)


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

    The hold a controller makes without a planner: each joint braked on its own at its
    acceleration limit to rest, off the path and with no jerk limit (as
    ``joint_trajectory_controller`` stops on a cancel); its wafer acceleration from the
    first instant on, sampled until the last joint rests.
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
    return float(np.abs(robot.arm.wafer_acceleration(q, qd, qdd)).max())


def _path(trajectory: Trajectory, arm, begin: float, end: float) -> tuple:
    """Return the path's samples from ``begin`` to ``end`` (its own time) for ``_brake``."""
    count = max(int(np.ceil((end - begin) / GRID)), 1) + 1
    s = np.linspace(begin, end, count)
    q, g1, g2, g3 = trajectory.evaluate_orders(s, range(4))
    zero = np.zeros_like(g1)
    w2 = arm.wafer_acceleration(q, g1, g2)
    w1 = arm.wafer_acceleration(q, zero, g1)
    return s, g1, g2, g3, w1, w2


def _timing(path: tuple, acceleration, jerk, wafer, share: float) -> tuple:
    """Return ((starts, jerks, states), whether it came to rest within the samples)."""
    s, g1, g2, g3, w1, w2 = path
    starts = np.empty(MAX_STEPS + 1)
    jerks = np.empty(MAX_STEPS)
    states = np.empty((MAX_STEPS + 1, 3))
    count, ended = _brake(s[0], s[1] - s[0], len(s), g1, g2, g3, w1, w2,
                          np.asarray(acceleration, float) * share, jerk * share,
                          wafer * share, STEP, HALVINGS, starts, jerks, states)
    return (starts[:count + 1].copy(), jerks[:count].copy(),
            states[:count + 1].copy()), bool(ended)


@kernel(nogil=True)
def _interval(lo, hi, a, b, limit):
    """Narrow [lo, hi] to the x with |b + a x| <= limit (a constraint that fixes none: kept)."""
    if abs(a) > 1e-12:
        x1, x2 = (-limit - b) / a, (limit - b) / a
        lo = max(lo, min(x1, x2))
        hi = min(hi, max(x1, x2))
    return lo, hi


@kernel(nogil=True)
def _sample(values, k, f, j):
    """Return ``values[k, j]`` and ``values[k + 1, j]`` mixed by f."""
    return values[k, j] * (1.0 - f) + values[k + 1, j] * f


@kernel(nogil=True)
def _place(s0, ds, count, s):
    """Return (sample k, fraction to the next) of path time s; k = -1 past the samples."""
    x = (s - s0) / ds
    k = int(np.floor(x))
    if k < 0:
        k = 0
    if k >= count - 1:
        return -1, 0.0
    return k, x - k


@kernel(nogil=True)
def _bounds(s0, ds, count, g1, g2, g3, w1, w2, acceleration, jerk, wafer, s, v, u, h):
    """
    Return (least sigma'', most sigma'', least sigma''', most sigma''') at (s, v, u).

    The acceleration limits bound sigma'' at (s, v); the jerk limits bound a jerk held
    for ``h`` s from (s, v, u), at both ends of that step (sigma'' moves with it).
    (nan, nan, nan, nan) past the samples.
    """
    k, f = _place(s0, ds, count, s)
    s1 = s + h * (v + h * u / 2.0)
    v1 = v + h * u
    k1, f1 = _place(s0, ds, count, s1)
    if k < 0 or k1 < 0:
        return np.nan, np.nan, np.nan, np.nan
    ulo, uhi, jlo, jhi = -np.inf, np.inf, -np.inf, np.inf
    for j in range(3):
        a1 = _sample(g1, k, f, j)
        a2 = _sample(g2, k, f, j)
        a3 = _sample(g3, k, f, j)
        ulo, uhi = _interval(ulo, uhi, a1, a2 * v * v, acceleration[j])
        jlo, jhi = _interval(jlo, jhi, a1, a3 * v * v * v + 3.0 * a2 * v * u, jerk[j])
        # At the step's end, where sigma'' has become u + h j.
        b1, b2, b3 = _sample(g1, k1, f1, j), _sample(g2, k1, f1, j), _sample(g3, k1, f1, j)
        jlo, jhi = _interval(jlo, jhi, b1 + 3.0 * b2 * v1 * h,
                             b3 * v1 * v1 * v1 + 3.0 * b2 * v1 * u, jerk[j])
    for j in range(2):
        if np.isfinite(wafer[j]):
            ulo, uhi = _interval(ulo, uhi, _sample(w1, k, f, j), _sample(w2, k, f, j) * v * v,
                                 wafer[j])
    if np.isfinite(wafer[2]):
        # |b + a u| <= L with a = w1, b = w2 v^2: a quadratic in u.
        ax, ay = _sample(w1, k, f, 0), _sample(w1, k, f, 1)
        bx, by = _sample(w2, k, f, 0) * v * v, _sample(w2, k, f, 1) * v * v
        aa, ab, bb = ax * ax + ay * ay, ax * bx + ay * by, bx * bx + by * by
        if aa > 1e-24:
            disc = ab * ab - aa * (bb - wafer[2] * wafer[2])
            if disc >= 0.0:
                root = np.sqrt(disc)
                ulo = max(ulo, (-ab - root) / aa)
                uhi = min(uhi, (-ab + root) / aa)
    return ulo, uhi, jlo, jhi


@kernel(nogil=True)
def _advance(s, v, u, j, h):
    """Return (s, v, u) after ``h`` seconds of constant jerk j."""
    return (s + h * (v + h * (u / 2.0 + h * j / 6.0)), v + h * (u + h * j / 2.0), u + h * j)


@kernel(nogil=True)
def _easing(v, u):
    """Return the constant jerk that brings sigma' and sigma'' to zero together."""
    if u >= 0.0:
        return 0.0
    if v <= 0.0:
        return np.inf
    return u * u / (2.0 * v)


@kernel(nogil=True)
def _eases(s0, ds, count, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, s, v, u):
    """
    Return whether easing off from (s, v, u) to rest keeps every limit.

    Easing off holds the jerk ``_easing`` gives; checked at every ``step`` until rest as
    the braking is (``_bounds``): sigma'' within the acceleration limits, the jerk within
    the jerk limits at both ends of each step.
    """
    j = _easing(v, u)
    if not (j > 0.0 and np.isfinite(j)):
        return False
    left = -u / j
    while left > 0.0:
        h = min(step, left)
        ulo, uhi, jlo, jhi = _bounds(s0, ds, count, g1, g2, g3, w1, w2, acceleration, jerk,
                                     wafer, s, v, u, h)
        # Within rounding: a braking step held on a bound ends on it up to 1e-16.
        du, dj = TOLERANCE * (1.0 + abs(u)), TOLERANCE * (1.0 + abs(j))
        if np.isnan(ulo) or not (u <= uhi + du and jlo - dj <= j <= jhi + dj):
            return False
        s, v, u = _advance(s, v, u, j, h)
        left -= h
    return True


@kernel(nogil=True)
def _brake(s0, ds, count, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, halvings,
           starts, jerks, states):
    """
    Fill the stop's phases from (s0, 1, 0); return (phases, whether it came to rest).

    Each step of ``step`` s brakes with the hardest jerk the jerk limits allow, held within
    the deceleration the acceleration limits leave at the step's end, as long as easing off
    from the step's end still keeps every limit (``_eases``); where it would not, the
    hardest braking that does (halving); once none does, easing off begins where it
    still did (braking on while it has not yet: at first, with no
    deceleration, there is nothing to ease off), its jerk constant, its last step as
    long as it takes.
    """
    s, v, u = s0, 1.0, 0.0
    t = 0.0
    starts[0] = 0.0
    states[0, 0], states[0, 1], states[0, 2] = s, v, u
    n = 0
    easing = False
    eases = False  # whether easing off from the current state keeps every limit
    while n < len(jerks):
        h = step
        if not easing:
            ulo, uhi, jlo, jhi = _bounds(s0, ds, count, g1, g2, g3, w1, w2, acceleration,
                                         jerk, wafer, s, v, u, step)
            if np.isnan(ulo):
                return n, False
            # Brake: the hardest jerk, then held within the deceleration left at the end.
            j = jlo
            s1, v1, u1 = _advance(s, v, u, j, h)
            lo1, hi1, _, _ = _bounds(s0, ds, count, g1, g2, g3, w1, w2, acceleration, jerk,
                                     wafer, s1, v1, u, 0.0)
            if not np.isnan(lo1):
                j = min(max((min(max(u1, lo1), hi1, 0.0) - u) / h, jlo), jhi)
            s1, v1, u1 = _advance(s, v, u, j, h)
            later = v1 > 0.0 and _eases(s0, ds, count, g1, g2, g3, w1, w2, acceleration,
                                        jerk, wafer, step, s1, v1, u1)
            if eases and not later and v1 > 0.0:
                # Brake less, as hard as still lets easing off keep every limit.
                low, high = j, min(max(_easing(v, u), j), jhi)
                for _ in range(halvings):
                    middle = 0.5 * (low + high)
                    s1, v1, u1 = _advance(s, v, u, middle, h)
                    if v1 > 0.0 and _eases(s0, ds, count, g1, g2, g3, w1, w2, acceleration,
                                           jerk, wafer, step, s1, v1, u1):
                        high, later = middle, True
                    else:
                        low = middle
                if later:
                    j = high
            easing = (eases and not later) or v1 <= 0.0
            eases = later
        if easing:
            j = _easing(v, u)
            if not (j > 0.0 and np.isfinite(j)):
                # Rounding left it a hair from rest: it is there.
                states[n, 1], states[n, 2] = 0.0, 0.0
                return n, True
            h = min(step, -u / j)
            if _place(s0, ds, count, s)[0] < 0:
                return n, False
        s, v, u = _advance(s, v, u, j, h)
        t += h
        jerks[n] = j
        n += 1
        starts[n] = t
        if easing and h < step:
            v, u = 0.0, 0.0  # exactly at rest: what the last step reaches, up to rounding
        states[n, 0], states[n, 1], states[n, 2] = s, v, u
        if v <= 0.0 and u >= 0.0:
            states[n, 1], states[n, 2] = 0.0, 0.0
            return n, True
    return n, False
