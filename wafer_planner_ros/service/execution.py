"""
Executing joint trajectories as ros2_controllers' ``joint_trajectory_controller`` does.

``TrajectoryFollower`` is the simulated arm's controller (``node.sim``): it holds what is
being executed and returns the state (q, q', q'') at any time, as the controller would
command it. What it models, from the controller's documentation ("Trajectory
Representation" and "Trajectory Replacement", joint_trajectory_controller/doc/
trajectory.rst) and its ``Trajectory::sample`` (src/trajectory.cpp):

- **Interpolation** (``interpolation_method: splines``): between two points, a quintic
  polynomial when both give positions, velocities and accelerations (exact at the points,
  continuous to the acceleration), a cubic when they give positions and velocities, a line
  when they give positions alone. The controller decides per segment; here a trajectory
  whose points mix these is interpolated at the lowest order any of its points allows.
- **Start time**: the points' ``time_from_start`` count from ``header.stamp``; a zero stamp
  means "now" (the controller's first sample of it).
- **Replacement**: a new trajectory replaces the rest of the current one from its start
  time: until then the current one goes on (a start in the future waits, as the
  ``allow_trajectory_replacement`` handoff and ROS 1's splice do; a later trajectory
  replaces one still waiting), from then on the new one is followed. Before its first
  point's time the controller interpolates from the state it is in at the handoff to the
  first point; a trajectory whose first point is at t = 0 has no such lead-in (ours start
  at t = 0 at the state they were planned from, so that they join without a jump; one that
  starts elsewhere makes the state jump, as it makes the controller lurch). A start in the
  past is followed from now, where it has got to by now (points already past are skipped).
  Jazzy's controller without the deferred handoff replaces at once and leads in from the
  state at receipt: for a start at or before receipt, which is what the planner sends, the
  two agree.
- **After the end** the last point's position is held at rest (the controller keeps
  commanding the last point).
- **Refused** as the controller's ``validate_trajectory_msg`` refuses them: no points,
  joint names that are not the arm's (each once, in any order: the columns are put in the
  arm's order), a point whose positions (or, when given, velocities and accelerations)
  do not have one value per joint, times that do not strictly ascend (or a negative one),
  values that are not finite, a last point not at rest, and a trajectory with a start
  time whose end is already past (``TrajectoryRefused``; nothing changes).

Before anything was sent the arm holds its initial configuration. Times are seconds on
the caller's clock (the node's, from an epoch of its own). ``wafer`` gives the wafer
centre's acceleration at a time against the loaded limit set's wafer limit, as the
verification measures it (``trajectory.constraints.WaferBound``).
"""

from dataclasses import dataclass
import math
from typing import List, NamedTuple, Optional, Sequence

import numpy as np

from wafer_planner_ros.cell.limits import LOADED
from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.trajectory.constraints import limit_constraints, wafer_bound

REST_VELOCITY = float(np.finfo(np.float32).eps)
"""rad/s: the largest |velocity| of a last point the controller takes for rest."""
HISTORY = 8
"""Replaced trajectories kept, so that ``state`` answers for a while before the latest."""


class TrajectoryRefused(WaferPlannerError, ValueError):
    """A trajectory the controller would refuse; the message says why."""


class State(NamedTuple):
    """Joint positions (rad), velocities (rad/s) and accelerations (rad/s^2)."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


class Wafer(NamedTuple):
    """The wafer centre's acceleration at one time, against the loaded wafer limit."""

    acceleration: np.ndarray
    """(2,) x, y (m/s^2)."""
    norm: float
    """|a| (m/s^2)."""
    ratio: float
    """The largest of |x|, |y| (and |a|) over its limit (1: at the limit; 0 with no limit)."""


@dataclass(frozen=True, eq=False)
class Samples:
    """A trajectory's points, columns in the arm's joint order (``samples_of`` checks them)."""

    times: np.ndarray
    """(N,) s from the trajectory's start, strictly ascending."""
    positions: np.ndarray
    """(N, J) rad."""
    velocities: Optional[np.ndarray] = None
    """(N, J) rad/s; None: not given (linear interpolation)."""
    accelerations: Optional[np.ndarray] = None
    """(N, J) rad/s^2; None: not given (cubic with velocities, else linear)."""

    @property
    def duration(self) -> float:
        """Return the last point's time from the start (s)."""
        return float(self.times[-1])


def samples_of(arm_joints: Sequence[str], joint_names: Sequence[str], times: Sequence[float],
               positions: Sequence, velocities: Optional[Sequence] = None,
               accelerations: Optional[Sequence] = None) -> Samples:
    """
    Return a JointTrajectory's points as ``Samples``; raise ``TrajectoryRefused`` if refused.

    ``positions``, ``velocities`` and ``accelerations`` hold one row per point (a point's
    velocities or accelerations may be empty: not given), in the order of ``joint_names``.
    """
    names, arm = list(joint_names), list(arm_joints)
    if not names:
        raise TrajectoryRefused('no joint names')
    if sorted(names) != sorted(arm) or len(set(names)) != len(names):
        raise TrajectoryRefused(f"joint names {names} are not the arm's {arm} (each once)")
    order = [names.index(name) for name in arm]
    if len(times) == 0:
        raise TrajectoryRefused('no points')
    times = np.asarray(times, float)
    if len(positions) != len(times):
        raise TrajectoryRefused(f'{len(times)} times but {len(positions)} points')
    if not np.all(np.isfinite(times)) or times[0] < 0.0:
        raise TrajectoryRefused(f'a time from start is negative or not finite: {times[0]}')
    steps = np.nonzero(np.diff(times) <= 0.0)[0]
    if len(steps):
        i = int(steps[0])
        raise TrajectoryRefused(f'times do not ascend strictly: point {i} at {times[i]} s, '
                                f'point {i + 1} at {times[i + 1]} s')
    columns = {'positions': _rows(positions, len(names), 'positions', False)}
    for field, rows in (('velocities', velocities), ('accelerations', accelerations)):
        columns[field] = None if rows is None else _rows(rows, len(names), field, True)
    if columns['velocities'] is None:  # accelerations alone: the controller interpolates
        columns['accelerations'] = None  # linearly, as with positions alone
    columns = {k: None if v is None else v[:, order] for k, v in columns.items()}
    last = columns['velocities']
    if last is not None and np.any(np.abs(last[-1]) > REST_VELOCITY):
        raise TrajectoryRefused(f'the last point is not at rest: velocities '
                                f'{last[-1].tolist()}')
    return Samples(times, **columns)


def _rows(rows: Sequence, joints: int, field: str, optional: bool) -> Optional[np.ndarray]:
    """Return (N, J) values, or None for an optional field not given at some point."""
    for i, row in enumerate(rows):
        if len(row) != joints and not (optional and len(row) == 0):
            raise TrajectoryRefused(f'point {i} has {len(row)} {field} for {joints} joints')
    if optional and any(len(row) == 0 for row in rows):
        return None
    values = np.array([np.asarray(row, float) for row in rows])
    if not np.all(np.isfinite(values)):
        raise TrajectoryRefused(f'{field} that are not finite')
    return values


@dataclass(frozen=True, eq=False)
class _Piece:
    """One trajectory from the time it took over (``switch``), led in from ``before``."""

    switch: float
    before: State
    start: float = math.nan
    samples: Optional[Samples] = None
    """None: hold ``before``."""

    def state(self, t: np.ndarray) -> State:
        """Return the states at times ``t`` (K,), each (K, J)."""
        k, joints = len(t), len(self.before.q)
        if self.samples is None:
            return State(*(np.broadcast_to(x, (k, joints)).copy() for x in self.before))
        s = self.samples
        order = 0 if s.velocities is None else 1 if s.accelerations is None else 2
        points = [s.positions, _or_zeros(s.velocities, s.positions),
                  _or_zeros(s.accelerations, s.positions)]
        times = np.concatenate([[self.switch], self.start + s.times])
        lead = times[0] < times[1]  # a lead-in from ``before`` to the first point
        if lead:
            points = [np.vstack([b[None], p]) for b, p in zip(self.before, points)]
        else:
            times = times[1:]
        i = np.clip(np.searchsorted(times, t, side='right') - 1, 0, len(times) - 2) \
            if len(times) > 1 else np.zeros(k, int)
        if len(times) == 1:
            out = [np.repeat(p[:1], k, 0) for p in points]
        else:
            span = (times[i + 1] - times[i])[:, None]
            tau = np.clip(t - times[i], 0.0, None)[:, None]
            out = _interpolate(order, span, np.minimum(tau, span),
                               [p[i] for p in points], [p[i + 1] for p in points])
        ended = t >= times[-1]
        out[0][ended] = points[0][-1]
        out[1][ended] = 0.0
        out[2][ended] = 0.0
        return State(*out)


def _or_zeros(values: Optional[np.ndarray], like: np.ndarray) -> np.ndarray:
    return np.zeros_like(like) if values is None else values


def _interpolate(order: int, span: np.ndarray, tau: np.ndarray, a: List, b: List) -> List:
    """
    Return [q, q', q''] at ``tau`` into segments of length ``span`` from state a to b.

    The controller's polynomials (``Trajectory::interpolate_between_points``): order 2 the
    quintic through both ends' position, velocity and acceleration, order 1 the cubic
    through their positions and velocities, order 0 the line through their positions.
    """
    (p0, v0, a0), (p1, v1, a1) = a, b
    T = span
    if order == 0:
        slope = (p1 - p0) / T
        return [p0 + slope * tau, slope + 0.0 * tau, np.zeros_like(p0)]
    if order == 1:
        c = [p0, v0, (3.0 * (p1 - p0) - (2.0 * v0 + v1) * T) / T ** 2,
             (2.0 * (p0 - p1) + (v0 + v1) * T) / T ** 3]
    else:
        c = [p0, v0, 0.5 * a0,
             (20.0 * (p1 - p0) - (8.0 * v1 + 12.0 * v0) * T - (3.0 * a0 - a1) * T ** 2)
             / (2.0 * T ** 3),
             (30.0 * (p0 - p1) + (14.0 * v1 + 16.0 * v0) * T + (3.0 * a0 - 2.0 * a1) * T ** 2)
             / (2.0 * T ** 4),
             (12.0 * (p1 - p0) - 6.0 * (v1 + v0) * T - (a0 - a1) * T ** 2) / (2.0 * T ** 5)]
    q = sum(ck * tau ** k for k, ck in enumerate(c))
    qd = sum(k * ck * tau ** (k - 1) for k, ck in enumerate(c) if k >= 1)
    qdd = sum(k * (k - 1) * ck * tau ** (k - 2) for k, ck in enumerate(c) if k >= 2)
    return [q, qd, qdd]


class TrajectoryFollower:
    """
    The trajectory being executed, and the state it commands at any time.

    See the module's description. Not thread-safe: the node calls it from one executor.
    """

    def __init__(self, robot, initial_q):
        """Hold ``initial_q`` (rad, in ``robot.joint_names``' order) until a trajectory comes."""
        q = np.asarray(initial_q, float)
        if q.shape != (len(robot.joint_names),) or not np.all(np.isfinite(q)):
            raise ValueError(f'the initial configuration must be {len(robot.joint_names)} '
                             f'finite joint angles, got {q.tolist()}')
        self.robot = robot
        self.joint_names = tuple(robot.joint_names)
        self._pieces = [_Piece(-math.inf, State(q, np.zeros_like(q), np.zeros_like(q)))]
        self._wafer = wafer_bound(limit_constraints(robot.limit_sets[LOADED]))

    def replace(self, start_time: Optional[float], samples: Samples, now: float) -> float:
        """
        Follow ``samples`` from ``start_time`` (None: a zero stamp, "now"); return the jump.

        The current trajectory goes on until the later of ``start_time`` and ``now``. The
        jump is the largest |position change| (rad) at that handoff: 0 when the new
        trajectory starts where the arm is (or leads in to its first point).
        Raise ``TrajectoryRefused`` for a start time whose trajectory ends before ``now``.
        """
        start = now if start_time is None else float(start_time)
        if start + samples.duration < now:
            raise TrajectoryRefused(f'the trajectory starts at {start:.3f} s and ends at '
                                    f'{start + samples.duration:.3f} s, before now '
                                    f'({now:.3f} s)')
        switch = max(start, now)
        before = self.state(switch)
        piece = _Piece(switch, before, start, samples)
        # One waiting to start later than this one never will.
        kept = [p for p in self._pieces if p.switch < switch]
        self._pieces = (kept + [piece])[-HISTORY:]
        after = piece.state(np.array([switch]))
        return float(np.max(np.abs(after.q[0] - before.q)))

    def state(self, t) -> State:
        """Return (q, q', q'') at ``t`` (s): (J,) each for a number, (K, J) for (K,) times."""
        times = np.atleast_1d(np.asarray(t, float))
        switches = np.array([p.switch for p in self._pieces])
        which = np.searchsorted(switches, times, side='right') - 1
        which = np.maximum(which, 0)  # before the oldest kept: the oldest's lead-in
        out = [np.empty((len(times), len(self.joint_names))) for _ in range(3)]
        for k in np.unique(which):
            mask = which == k
            for o, values in zip(out, self._pieces[k].state(times[mask])):
                o[mask] = values
        if np.ndim(t) == 0:
            return State(*(o[0] for o in out))
        return State(*out)

    def end_time(self) -> float:
        """Return when the latest trajectory ends (s); -inf if none was sent."""
        last = self._pieces[-1]
        return -math.inf if last.samples is None else last.start + last.samples.duration

    def wafer(self, t: float) -> Wafer:
        """Return the wafer centre's acceleration at ``t`` against the loaded wafer limit."""
        q, qd, qdd = self.state(t)
        acceleration = self.robot.arm.wafer_acceleration(q, qd, qdd)
        ax, ay = (np.array([v]) for v in acceleration)
        ratio = 0.0 if self._wafer is None else float(self._wafer.ratio(ax, ay)[0])
        return Wafer(acceleration, float(np.hypot(*acceleration)), ratio)
