"""
The exact straight way out of a port: the joints along the inverse kinematics of a line.

From a configuration inside a port the wafer centre moves straight out along the port's
axis, the blade keeping its heading, to the port's mouth (the retracted pose for a
station's pick/place pose): with ``sigma`` the distance moved (0 inside, ``length`` at the
mouth), the configuration is ``q(sigma)`` = the inverse kinematics of that point and
heading on the end's elbow branch. ``Channel.derivatives`` gives q and its first three
derivatives by sigma from the arm's Jacobian: the wafer centre moves on a straight line at
unit speed without turning, so J q' = d, J q'' = -(dJ/dsigma) q' and so on (``PlanarArm``'s
wafer acceleration and jerk with the higher term zero). ``Channel.speed_bound`` bounds
|dq_i/dsigma| on an interval of sigma rigorously, from the elbow angle's range there: the
collision proof of a motion along the channel rests on it.
"""

from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from wafer_planner_ros.geometry.kinematics import PlanarArm
from wafer_planner_ros.geometry.ports import inverse_on_branch
from wafer_planner_ros.moves.timing import Bounds, profile

GRID = 257
"""Points along a channel at which its derivatives are taken: where its mouth is found
(``Channel.out_of``) and the limits are kept (``channel_bounds``)."""
CONSISTENT = 1e-9
"""rad: how near a channel's end configurations must be to the line's inverse kinematics."""
ROUNDING = 1e-9
"""Relative slack on the elbow's sine in ``Channel.speed_bound``: rounding cannot make the
bound too small."""


@dataclass(frozen=True, eq=False)
class Channel:
    """The straight way from a configuration inside a port out to its mouth (the module)."""

    arm: PlanarArm
    inside: np.ndarray
    """(3,) the configuration inside the port (sigma = 0)."""
    mouth: np.ndarray
    """(3,) the configuration at the mouth (sigma = ``length``)."""
    direction: np.ndarray
    """(2,) the unit vector the wafer centre moves along: out of the port."""
    length: float
    """m: how far the wafer centre moves from ``inside`` to ``mouth``."""

    @classmethod
    def out_of(cls, arm, inside: np.ndarray, axis: np.ndarray, length: float,
               mouth=None) -> 'Channel':
        """
        Return the way from ``inside`` along ``-axis`` for ``length`` m, its end exact.

        ``mouth``: the configuration at its end when it is known exactly (a station's
        retracted pose), else the inverse kinematics there, each angle continued from
        ``inside`` (no wrap by 2 pi).
        """
        inside = np.asarray(inside, float)
        direction = -np.asarray(axis, float) / np.linalg.norm(axis)
        arm = PlanarArm(np.asarray(arm.base, float), np.asarray(arm.link_lengths, float))
        made = cls(arm, inside, inside, direction, float(length))
        if mouth is None:
            sigma = np.linspace(0.0, length, GRID)
            mouth = np.unwrap(np.vstack([inside, made._raw(sigma[1:])]), axis=0)[-1]
        return cls(arm, inside, np.asarray(mouth, float), direction, float(length))

    @property
    def heading(self) -> float:
        """Return the blade's heading all along the channel (rad)."""
        return float(np.sum(self.inside))

    @property
    def elbow(self) -> int:
        """Return the elbow branch: the sign of q2."""
        return 1 if self.inside[1] >= 0.0 else -1

    def _raw(self, sigma) -> np.ndarray:
        """Return the inverse kinematics at ``sigma`` (K,): angles in atan2's range."""
        centres = self.arm.wafer_center(self.inside) + \
            np.asarray(sigma, float)[:, None] * self.direction
        return inverse_on_branch(self.arm, centres, self.heading, self.elbow)

    def configurations(self, sigma) -> np.ndarray:
        """Return q (K, 3) at distances ``sigma`` (K,) out, ``inside`` and ``mouth`` exact."""
        sigma = np.atleast_1d(np.asarray(sigma, float))
        q = self._raw(sigma)
        near = self.inside + (sigma / self.length)[:, None] * (self.mouth - self.inside) \
            if self.length > 0.0 else np.broadcast_to(self.inside, q.shape)
        q += 2.0 * np.pi * np.round((near - q) / (2.0 * np.pi))
        q[sigma <= 0.0] = self.inside
        q[sigma >= self.length] = self.mouth
        return q

    def derivatives(self, sigma) -> tuple:
        """Return (q, dq/dsigma, d2q/dsigma2, d3q/dsigma3) at ``sigma``, each (K, 3)."""
        q = self.configurations(sigma)
        arm = self.arm
        full = np.concatenate([arm.jacobian(q), np.ones((len(q), 1, 3))], axis=1)  # (K,3,3)
        zero = np.zeros_like(q)

        def solve(wafer):
            right = np.concatenate([wafer, np.zeros((len(q), 1))], axis=1)
            return np.linalg.solve(full, right[..., None])[..., 0]

        g1 = solve(np.broadcast_to(self.direction, (len(q), 2)))
        g2 = solve(-arm.wafer_acceleration(q, g1, zero))
        g3 = solve(-arm.wafer_jerk(q, g1, g2, zero))
        return q, g1, g2, g3

    def speed_bound(self, a, b) -> np.ndarray:
        """
        Return an upper bound of every |dq_i/dsigma| on each [a_k, b_k] of sigma, (K, 3).

        The wrist moves on a straight line at unit speed, the heading fixed: with r the
        wrist's distance from the shoulder and q2 the elbow angle, |q1'| <= 1 / (l1 |sin
        q2|), |q2'| <= r / (l1 l2 |sin q2|) and |q3'| = |q1' + q2'| <= 1 / (l2 |sin q2|);
        r^2 is a quadratic in sigma, so its range on the interval, and with it the
        smallest |sin q2| there, are exact.
        """
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        l1, l2, l3 = self.arm.link_lengths
        heading = self.heading
        wrist = self.arm.wafer_center(self.inside) - \
            l3 * np.array([np.cos(heading), np.sin(heading)])
        offset = wrist - self.arm.base
        # r^2(sigma) = |offset|^2 + 2 sigma offset.d + sigma^2
        along = float(offset @ self.direction)

        def r2(s):
            return float(offset @ offset) + 2.0 * s * along + s * s

        foot = np.clip(-along, a, b)
        low = np.minimum(np.minimum(r2(a), r2(b)), r2(foot))
        high = np.maximum(r2(a), r2(b))
        cosines = (np.stack([low, high]) - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        worst = np.abs(cosines).max(axis=0)
        sine = np.sqrt(np.maximum(1.0 - worst * worst, 0.0)) * (1.0 - ROUNDING)
        with np.errstate(divide='ignore'):
            inverse = np.where(sine > 0.0, 1.0 / np.where(sine > 0.0, sine, 1.0), np.inf)
        r = np.sqrt(high) * (1.0 + ROUNDING)
        return np.stack([inverse / l1, r * inverse / (l1 * l2), inverse / l2], axis=1)

    def problem(self) -> Optional[str]:
        """
        Return what makes the data no straight way out of a port, or None.

        Finite; a unit direction and a positive length; ``inside`` and ``mouth`` where the
        inverse kinematics of the line's ends put the arm on ``inside``'s elbow branch
        (within ``CONSISTENT`` rad, up to whole turns): so the way is continuous.
        """
        values = np.concatenate([self.inside, self.mouth, self.direction, [self.length],
                                 self.arm.base, self.arm.link_lengths])
        if not np.isfinite(values).all():
            return 'its data are not finite'
        if not (abs(float(np.hypot(*self.direction)) - 1.0) <= 1e-12 and self.length > 0.0):
            return (f'its direction {self.direction.tolist()} is no unit vector or its '
                    f'length {self.length!r} is not positive')
        ends = self._raw(np.array([0.0, self.length]))
        for name, q, found in (('inside', self.inside, ends[0]), ('mouth', self.mouth, ends[1])):
            gap = np.abs((q - found + np.pi) % (2.0 * np.pi) - np.pi)
            if not np.all(gap <= CONSISTENT):
                return (f'its {name} configuration {q.tolist()} is not where the straight '
                        f'line puts the arm ({found.tolist()})')
        return None

    def describe(self) -> dict:
        """Return the channel as plain data."""
        return {'base': self.arm.base.tolist(), 'link_lengths': self.arm.link_lengths.tolist(),
                'inside': self.inside.tolist(), 'mouth': self.mouth.tolist(),
                'direction': self.direction.tolist(), 'length': self.length}

    @classmethod
    def described(cls, data) -> 'Channel':
        """Return the channel ``describe`` gave (raise ValueError if it is not one)."""
        try:
            base, links, inside, mouth, direction = (np.asarray(data[k], float) for k in (
                'base', 'link_lengths', 'inside', 'mouth', 'direction'))
            made = cls(PlanarArm(base, links), inside, mouth, direction, float(data['length']))
        except (KeyError, TypeError) as exc:
            raise ValueError(f'not a channel: {exc}') from None
        shapes = [(base.shape, (2,)), (links.shape, (3,)),
                  (made.inside.shape, (3,)), (made.mouth.shape, (3,)),
                  (made.direction.shape, (2,))]
        if any(have != want for have, want in shapes):
            raise ValueError(f'a channel with shapes {[s for s, _ in shapes]}')
        return made


SPEED_TRIES = 12
"""Speed bounds tried along a channel (``channel_bounds``), each ``SPEED_STEP`` times the
one before, from the joints' velocity limits down."""
SPEED_STEP = 0.7
ACCELERATION_TRIES = 8
"""Acceleration bounds tried per speed bound, each ``ACCELERATION_STEP`` times the one
before, from the largest the limits allow down."""
ACCELERATION_STEP = 0.5
BISECTIONS = 40
"""Halvings of the acceleration bound's search."""
MARGIN = 0.999
"""The share of each limit the profile along a channel may use: the rest is left to what
the channel's largest derivatives, taken on a grid, miss between its points."""


def channel_bounds(channel: Channel, robot) -> Bounds:
    """
    Return the speed, acceleration and jerk bounds along ``channel`` under ``robot``'s limits.

    Along the channel q' = g1 s', q'' = g2 s'^2 + g1 s'' and q''' = g3 s'^3 + 3 g2 s' s'' +
    g1 s''' (g_k: the k-th derivative by the distance s), and the wafer's acceleration is
    s'' along the channel's direction. A profile from rest inside the port (``timing``)
    with |s''| <= A has s'^2 <= 2 A s at distance s, whatever else it does; one that also
    ends at rest at the mouth (length L) has s'^2 <= 2 A (L - s) as well. So the bounds
    (V, A, J) keep every limit at every s of a grid (each cell of the grid taken at its
    larger |g_k| and at the fastest s' these allow in it): |g1| s' within the velocity
    limit, |g2| s'^2 + |g1| A within the acceleration limit and A within the wafer's limit
    along the direction, |g3| s'^3 + 3 |g2| s' A + |g1| J within the jerk limit. Near a
    folded or stretched arm the g_k grow and a lower V leaves more of the acceleration
    limit to A, and a lower A more of the jerk limit to J: of ``SPEED_TRIES`` speeds from
    the velocity limit's down, each with ``ACCELERATION_TRIES`` accelerations from the
    largest that leaves a positive J down, the bounds whose rest-to-rest profile over the
    channel is fastest are returned. Those of a profile that stops at the mouth are found the
    same way with both caps on s', and returned as the bounds' ``resting`` where they are
    faster: with the arm nearly folded at the mouth, a stop there takes seconds where
    leaving at speed would take minutes. Every limit is taken at ``MARGIN`` of itself.
    Raise ValueError when none allows a motion.
    """
    sigma = np.linspace(0.0, channel.length, GRID)
    _, *orders = channel.derivatives(sigma)
    # Each grid cell at its larger derivatives.
    g1, g2, g3 = (np.maximum(np.abs(g[:-1]), np.abs(g[1:])) for g in orders)
    limits = robot.limits
    velocity, acceleration = MARGIN * limits.velocity, MARGIN * limits.acceleration
    jerk = MARGIN * limits.jerk if limits.jerk is not None else None
    along = np.inf
    wafer = robot.wafer_limit
    if wafer is not None:
        dx, dy = np.abs(channel.direction)
        with np.errstate(divide='ignore'):
            along = min(wafer.xy[0] / dx, wafer.xy[1] / dy)
        if wafer.norm is not None:
            along = min(along, wafer.norm)
        along *= MARGIN
    cells = _Cells(g1, g2, g3, velocity, acceleration, jerk, along, channel.length)
    # Each cell's farthest distance from the inside, and from the mouth for a stop there.
    far, left = sigma[1:, None], channel.length - sigma[:-1, None]
    moving = _fastest(cells, far, np.full_like(left, np.inf))
    if moving is None:
        raise ValueError(f'no motion along the channel from {channel.inside.round(4).tolist()} '
                         'keeps the limits (the arm is stretched or folded there)')
    resting = _fastest(cells, far, left)
    if resting is None or resting[1] >= moving[1]:
        return moving[0]
    return replace(moving[0], resting=resting[0])


@dataclass(frozen=True, eq=False)
class _Cells:
    """A channel's grid cells at their largest derivatives, and the limits (``_fastest``)."""

    g1: np.ndarray
    g2: np.ndarray
    g3: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: Optional[np.ndarray]
    along: float
    length: float


def _fastest(cells: _Cells, far: np.ndarray, left: np.ndarray) -> Optional[tuple]:
    """
    Return (bounds, rest-to-rest time) of the fastest bounds that keep every cell's limits.

    In a cell s' is at most V, sqrt(2 A ``far``) and sqrt(2 A ``left``) (inf: the profile
    need not stop at the mouth); ``channel_bounds``. None when no bounds allow a motion.
    """
    g1, g2, g3, jerk = cells.g1, cells.g2, cells.g3, cells.jerk
    best, best_time = None, np.inf
    highest = min(cells.along, float(np.min(cells.acceleration / g1)))
    stops = bool(np.isfinite(left).any())
    # Moving on at the mouth: V keeps every cell's velocity limit. Stopping there: from
    # the fastest V any cell allows, the caps on s' keeping each cell's (checked in fits).
    by_cell = np.min(cells.velocity / g1, axis=1)
    top = float(np.max(by_cell) if stops else np.min(by_cell))
    for speed in top * SPEED_STEP ** np.arange(SPEED_TRIES):

        def speeds(a, speed=speed):  # (cells, 1): the fastest s' in each cell
            return np.sqrt(np.minimum(np.minimum(speed ** 2, 2.0 * a * far), 2.0 * a * left))

        def rate(a):  # the largest jerk bound with acceleration bound a (<= 0: none)
            if jerk is None:
                return 1e3 * a  # no jerk limit: a steep finite one, the profile a cubic
            v = speeds(a)
            return float(np.min((jerk - g3 * v ** 3 - 3.0 * g2 * v * a) / g1))

        def fits(a):  # each limit a monotone function of a: bisected
            v = speeds(a)
            return bool(not stops or np.all(g1 * v <= cells.velocity)) \
                and bool(np.all(g2 * v ** 2 + g1 * a <= cells.acceleration)) and rate(a) > 0.0

        low, high = 0.0, highest
        if fits(high):
            low = high
        else:
            for _ in range(BISECTIONS):
                middle = 0.5 * (low + high)
                low, high = (middle, high) if fits(middle) else (low, middle)
        if not low > 0.0:
            continue
        # The largest A may leave J tiny (where s' peaks near large g3): lower ones too.
        for a in low * ACCELERATION_STEP ** np.arange(ACCELERATION_TRIES):
            bounds = Bounds(speed, a, rate(a))
            took = profile(cells.length, 0.0, bounds).duration
            if took < best_time:
                best, best_time = bounds, took
    return None if best is None else (best, best_time)
