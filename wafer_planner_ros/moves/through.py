"""
A move through a port as one curve: the way out, the transfer, the way in.

``PortMove`` is a ``Trajectory`` of up to three parts played one after the other: the way
out of the start's port (a ``Channel`` timed by a ``Profile``, from rest), the transfer (a
``CubicBSpline`` from the start's port mouth to the goal's) and the way into the goal's
port (its channel and profile played backwards, to rest). Either port part may be absent
(an end that is not inside a port: the transfer starts or ends there, at rest); so may the
transfer, where a move only leaves a port to its mouth or only enters one (one way, from
rest to rest). Where two
parts meet they share the mouth's configuration exactly, and its velocity and acceleration
(``compose`` reads the transfer's speed along the channel at each mouth and times the
channel to arrive with it, unaccelerated: the transfer's acceleration there is the
channel's curvature times the speed squared): the motion is continuous in acceleration by
construction, its jerk within each part. Inside a port the wafer centre is on the line and
the blade on its heading exactly, whatever the timing.
"""

from dataclasses import dataclass
from typing import ClassVar, Mapping, Optional, Sequence

import numpy as np

from wafer_planner_ros.moves.channel import Channel
from wafer_planner_ros.moves.timing import Bounds, Profile, profile
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.retimed import along
from wafer_planner_ros.trajectory.shape_problem import FreeEnd

SPEEDS = 25
"""Shares of the reach at which a channel's time is computed for ``free_end``."""
REACH_SHARE = 0.995
"""The share of a way's reach the transfer's optimiser may ask for (``free_end``)."""
LEAST_REACH = 1e-9
"""m/s: a reach taken as at least this (a way that cannot move on at all)."""
ACCELERATIONS = 13
"""Mouth accelerations at which a channel's time and reach are computed for ``free_end``."""
JOIN_TOLERANCE = 1e-6
"""rad/s, rad/s^2: how far the velocity and acceleration of two parts may differ where
they meet (rounding in reading the mouth speed off the transfer: about 1e-12)."""


@dataclass(frozen=True, eq=False)
class Way:
    """A channel and its timing, from rest inside the port to its mouth."""

    channel: Channel
    profile: Profile

    @property
    def duration(self) -> float:
        """Return the time along the channel (s)."""
        return self.profile.duration

    def states(self, t, orders: Sequence[int]) -> list:
        """Return q and its derivatives of ``orders`` at local times ``t`` (out of the port)."""
        sigma = self.profile.evaluate(t)
        return along(self.channel.derivatives(sigma[:, 0]), sigma, orders)

    def peak_speed(self, a, b) -> np.ndarray:
        """Return a bound of every |q'_j| on each [a_k, b_k] within one phase, (K, 3)."""
        sigma = self.profile.evaluate(np.concatenate([a, b]))[:, 0]
        k = len(a)
        return self.channel.speed_bound(sigma[:k], sigma[k:]) * \
            self.profile.peak_speed(a, b)[:, None]

    def describe(self) -> dict:
        """Return the way as plain data."""
        return {'channel': self.channel.describe(), 'profile': self.profile.describe()}

    @classmethod
    def described(cls, data) -> Optional['Way']:
        """Return the way ``describe`` gave, None for None (raise ValueError if not one)."""
        if data is None:
            return None
        if not isinstance(data, Mapping):
            raise ValueError('a way through a port that is not a mapping')
        return cls(Channel.described(data.get('channel', {})),
                   Profile.described(data.get('profile', {})))


class PortMove(Trajectory):
    """The way out of a port, the transfer, the way into a port: one motion (the module)."""

    kind: ClassVar[str] = 'through-ports'

    def __init__(self, out: Optional[Way], transfer: Optional[CubicBSpline],
                 into: Optional[Way]):
        """
        Keep the parts: ``into`` is the goal's way out, played backwards.

        ``transfer`` None: one way alone (``out`` or ``into``, not both).
        """
        if transfer is None and (out is None) == (into is None):
            raise ValueError('a move through a port without a transfer is one way alone')
        self.out, self.transfer, self.into = out, transfer, into
        self._out = 0.0 if out is None else out.duration
        self._into = 0.0 if into is None else into.duration
        self._transfer = 0.0 if transfer is None else transfer.duration
        self._begin = self._out + self._transfer    # the into part starts here

    @property
    def duration(self) -> float:
        """Return the total time (s)."""
        return self._begin + self._into

    @property
    def in_port_time(self) -> float:
        """Return the time spent along the channels (s)."""
        return self._out + self._into

    def evaluate_orders(self, t, orders=(0, 1, 2)) -> tuple:
        """Return the derivatives of the given orders at times t, each (len(t), 3)."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        out = [np.empty((len(t), 3)) for _ in orders]
        first, middle, last = self._parts(t)
        if first.any():
            for target, values in zip(out, self.out.states(t[first], orders)):
                target[first] = values
        if middle.any():
            for target, values in zip(out, self.transfer.evaluate_orders(
                    t[middle] - self._out, orders)):
                target[middle] = values
        if last.any():
            local = self.duration - t[last]
            for target, order, values in zip(out, orders, self.into.states(local, orders)):
                target[last] = values * (-1.0) ** order
        return tuple(out)

    def _parts(self, t, strict: bool = False) -> tuple:
        """
        Return the masks (way out, transfer, way in) of times ``t`` (K,).

        At a join the way out keeps its end and the way in its start, unless ``strict``
        (then a time exactly there goes to the transfer: a piece's middle never is).
        """
        none = np.zeros(len(t), bool)
        if self.transfer is None:
            return (~none, none, none) if self.out is not None else (none, none, ~none)
        first = none if self.out is None else (t < self._out if strict else t <= self._out)
        last = none if self.into is None else (t > self._begin if strict else t >= self._begin)
        last = last & ~first
        return first, ~(first | last), last

    def breaks(self) -> np.ndarray:
        """Return the times between the polynomial pieces of the parts (and the channels')."""
        parts = [] if self.transfer is None else [self.transfer.breaks() + self._out]
        if self.out is not None:
            parts.append(self.out.profile.starts)
        if self.into is not None:
            parts.append(self.duration - self.into.profile.starts)
        return np.unique(np.concatenate(parts))

    def peak_speed(self, a, b) -> np.ndarray:
        """
        Return the largest |q'_j| on each [a_k, b_k] within one piece (K, 3).

        Exact on the transfer; along a channel an upper bound (``Channel.speed_bound``
        times the profile's exact peak speed), which is what the proof and the
        verification's collision steps need.
        """
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        middle = 0.5 * (a + b)
        peaks = np.empty((len(a), 3))
        first, inner, last = self._parts(middle, strict=True)
        if first.any():
            peaks[first] = self.out.peak_speed(a[first], b[first])
        if inner.any():
            peaks[inner] = self.transfer.peak_speed(a[inner] - self._out, b[inner] - self._out)
        if last.any():
            peaks[last] = self.into.peak_speed(self.duration - b[last],
                                               self.duration - a[last])
        return peaks

    def ill_formed(self, start: np.ndarray, goal: np.ndarray) -> Optional[str]:
        """
        Return what makes the parts no motion at rest from ``start`` to ``goal``, or None.

        Each part well formed (the transfer a clamped cubic, a channel's profile from rest
        covering the channel), the parts meeting exactly at each mouth with the same
        velocity and acceleration (``JOIN_TOLERANCE``), exactly at ``start`` and ``goal``
        and at rest there.
        """
        if self.transfer is None:
            points = np.stack([np.asarray(goal, float), np.asarray(start, float)])
        else:
            problem = self.transfer.structure_problem()
            if problem is not None:
                return f'the transfer: {problem}'
            points = self.transfer.control_points
        for name, way, end in (('out of', self.out, points[0]), ('into', self.into, points[-1])):
            if way is None:
                continue
            problem = way.profile.ill_formed()
            if problem is not None:
                return f'the way {name} the port: {problem}'
            if not abs(way.profile.length - way.channel.length) <= 1e-12 * max(
                    1.0, way.channel.length):
                return (f'the way {name} the port covers {way.profile.length:.9g} m of its '
                        f'channel of {way.channel.length:.9g} m')
            if not np.array_equal(way.channel.mouth, end):
                return (f'the way {name} the port ends at {way.channel.mouth.tolist()}, not '
                        f'where the transfer {"starts" if name == "out of" else "ends"} '
                        f'({end.tolist()})')
            problem = way.channel.problem()
            if problem is not None:
                return f'the way {name} the port: {problem}'
        joins = []
        if self.transfer is None:
            pass
        elif self.out is not None:
            joins.append(('start', self.out.states([self.out.duration], (1, 2)),
                          self.transfer.evaluate_orders([0.0], (1, 2))))
        if self.into is not None and self.transfer is not None:
            velocity, acceleration = self.into.states([self.into.duration], (1, 2))
            joins.append(('goal', (-velocity, acceleration), self.transfer.evaluate_orders(
                [self.transfer.duration], (1, 2))))
        for name, way, transfer in joins:
            for order, have, want in zip((1, 2), way, transfer):
                gap = float(np.abs(have[0] - want[0]).max())
                if not gap <= JOIN_TOLERANCE:
                    return (f"the transfer and the {name}'s port meet with derivative "
                            f'{order} differing by {gap:.3g}')
        problem = self.ends_problem(start, goal)
        if problem is not None:
            return problem
        if self.transfer is None:
            way = self.out or self.into
            if way.profile.end_speed != 0.0:
                return 'a way alone does not stop at its mouth'
            return None
        if self.out is None and not np.array_equal(points[1], points[0]):
            return 'the transfer does not start at rest'
        if self.into is None and not np.array_equal(points[-2], points[-1]):
            return 'the transfer does not end at rest'
        return None

    def describe(self) -> dict:
        """Return the parts as plain data."""
        return {'kind': self.kind, 'out': None if self.out is None else self.out.describe(),
                'transfer': None if self.transfer is None else self.transfer.describe(),
                'into': None if self.into is None else self.into.describe()}

    @classmethod
    def described(cls, data: Mapping) -> 'PortMove':
        """Return the move ``describe`` gave (raise ValueError if it is not one)."""
        transfer = data.get('transfer')
        if transfer is not None:
            transfer = Trajectory.from_description(transfer)
            if not isinstance(transfer, CubicBSpline):
                raise ValueError('the transfer of a move through ports is not a cubic '
                                 'B-spline')
        return cls(Way.described(data.get('out')), transfer, Way.described(data.get('into')))

    def backwards(self) -> 'PortMove':
        """Return the same motion backwards in time: the ways swap, the transfer reversed."""
        return PortMove(self.into, None if self.transfer is None else
                        self.transfer.backwards(), self.out)


def mouth_state(transfer: CubicBSpline, channel: Channel, at_goal: bool) -> tuple:
    """
    Return the transfer's speed and acceleration along a channel at its mouth (v, a).

    The transfer leaves the start's mouth with q' = g1 v and q'' = g2 v^2 + g1 a (g1, g2:
    the channel's derivatives by the distance there, out of the port); it reaches the
    goal's mouth the same way seen backwards in time. (0, 0) exactly where it is at rest
    (its first or last three control points equal).
    """
    points = transfer.control_points
    if np.array_equal(*(points[[-1, -2]] if at_goal else points[[0, 1]])) and \
            np.array_equal(*(points[[-1, -3]] if at_goal else points[[0, 2]])):
        return 0.0, 0.0
    t = [transfer.duration if at_goal else 0.0]
    velocity, acceleration = (x[0] for x in transfer.evaluate_orders(t, (1, 2)))
    _, g1, g2, _ = (d[0] for d in channel.derivatives([channel.length]))
    norm = float(g1 @ g1)
    v = float(velocity @ g1 / norm) * (-1.0 if at_goal else 1.0)
    return v, float((acceleration - g2 * v * v) @ g1 / norm)


def compose(transfer: Optional[CubicBSpline], out: Optional[tuple],
            into: Optional[tuple]) -> PortMove:
    """
    Return the move of a transfer with the ways out and in timed to meet it (the module).

    ``out``, ``into``: (Channel, Bounds) of the start's and the goal's port, or None. Each
    channel is timed from rest to the transfer's state at its mouth (``mouth_state``: a
    speed up to what the channel reaches, an acceleration up to none). ``transfer`` None:
    the one way alone, from rest to rest. Raise ValueError when a state cannot be met.
    """
    ways = []
    for end, at_goal in ((out, False), (into, True)):
        if end is None:
            ways.append(None)
            continue
        channel, bounds = end
        v, a = (0.0, 0.0) if transfer is None else mouth_state(transfer, channel, at_goal)
        a = min(max(a, -bounds.acceleration), 0.0)
        v = min(max(v, 0.0), bounds.reach(channel.length, a))
        ways.append(Way(channel, profile(channel.length, v, bounds.at(v, a), a)))
    return PortMove(ways[0], transfer, ways[1])


def free_end(channel: Channel, bounds: Bounds) -> FreeEnd:
    """
    Return the port mouth of a channel as a free end of the transfer (``FreeEnd``).

    The transfer leaves (reaches) the mouth along the channel's line continued: its
    velocity there g1 v and acceleration g2 v^2 + g1 a (the channel's derivatives by the
    distance at the mouth), a up to the channel's acceleration bound in braking, v up to
    ``REACH_SHARE`` of what the channel reaches with it (``Bounds.reach``). ``time(v, a)``
    is how long the channel's own profile takes to arrive so (``timing.profile``):
    interpolated, as are
    the reaches, over a grid of ``ACCELERATIONS`` accelerations and ``SPEEDS`` shares of
    the reach (smooth: the optimiser's model; each move is timed exactly, ``compose``).
    """
    # Imported here: scipy.interpolate brings scipy.optimize, which a node need not load
    # before its first move through a port.
    from scipy.interpolate import PchipInterpolator, RectBivariateSpline
    _, g1, g2, _ = (d[0] for d in channel.derivatives([channel.length]))
    length, braking = channel.length, bounds.acceleration
    accelerations = np.linspace(-braking, 0.0, ACCELERATIONS)
    # The optimiser's reach a little short of the true one, so that interpolation never
    # lets it ask for a mouth state the way cannot meet (``compose``).
    reaches = REACH_SHARE * np.array([bounds.reach(length, a) for a in accelerations])
    shares = np.linspace(0.0, 1.0, SPEEDS)
    times = np.array([[bounds.time(length, share * reach, a) for share in shares]
                      for a, reach in zip(accelerations, reaches)], dtype=float)
    if not np.isfinite(times).all():
        times = _filled(times)
    reach = PchipInterpolator(accelerations, reaches)
    reach_slope = reach.derivative()
    table = RectBivariateSpline(accelerations, shares, times, kx=3, ky=3)

    def time(v, a):
        return float(table(a, v / max(float(reach(a)), LEAST_REACH))[0, 0])

    def time_slopes(v, a):
        r = max(float(reach(a)), LEAST_REACH)
        by_a = float(table(a, v / r, dx=1)[0, 0])
        by_share = float(table(a, v / r, dy=1)[0, 0])
        return by_share / r, by_a - by_share * v * float(reach_slope(a)) / (r * r)

    # No way is faster than the table's fastest, or than the stop (``Bounds.at``).
    least = min(float(times.min()), bounds.at(0.0, 0.0).time(length, 0.0))
    return FreeEnd(g1, g2, braking, time, time_slopes, lambda a: float(reach(a)),
                   lambda a: float(reach_slope(a)), least)


def _filled(times: np.ndarray) -> np.ndarray:
    """Return a time table with any missing entry (no profile) its row's next one's."""
    times = times.copy()
    for row in times:
        for k in range(len(row) - 2, -1, -1):
            if not np.isfinite(row[k]):
                row[k] = row[k + 1]
    return times
