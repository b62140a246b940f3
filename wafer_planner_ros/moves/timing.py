"""
The timing along a channel: a jerk-limited one-dimensional profile from rest.

Along a straight channel the motion is one number, the distance sigma moved, timed under
three bounds: speed V, acceleration A and jerk J (``Bounds``, which a channel's derivatives
turn the joint and wafer limits into: ``channel.channel_bounds``). A ``Profile`` starts at
rest at sigma = 0 and ends at sigma = ``length`` in the mouth state the transfer continues
from: a speed v >= 0 and an acceleration a (v = a = 0: a stop there). It is the
time-optimal such profile under the bounds (Ruckig, Berscheid and Kroeger 2021): seven
phases of constant jerk, a cubic in time each. Only profiles that never move back
(sigma' >= 0 throughout, so 0 <= sigma <= length) are ways through a port: the others leave
it at one end or the other (``monotone``).
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np
import ruckig

BISECTIONS = 32
"""Halvings of the reach search (``Bounds.reach``)."""
BACKWARDS = 1e-12
"""m/s: the most a profile may move back (rounding near a stop)."""
SPEED_MARGIN = 1e-9
"""Relative: how far below the speed bound the reach search stays (Ruckig refuses a target
speed on its bound with an acceleration pushing past it)."""


@dataclass(frozen=True)
class Bounds:
    """The bounds of a one-dimensional motion: speed (m/s), acceleration (m/s^2), jerk."""

    speed: float
    acceleration: float
    jerk: float
    resting: Optional['Bounds'] = None
    """The bounds of a profile that ends at rest, where they differ (``at``)."""

    def at(self, speed: float, acceleration: float) -> 'Bounds':
        """
        Return the bounds of a profile ending in this state: ``resting`` for a stop.

        A profile that stops at the end of a channel moves slowly near it, so where the
        limits tighten there (an arm nearly folded or stretched at a port's mouth) a stop
        may use larger bounds than a profile that leaves at speed (``channel_bounds``).
        """
        if speed == 0.0 and acceleration == 0.0 and self.resting is not None:
            return self.resting
        return self

    def reach(self, length: float, acceleration: float = 0.0) -> float:
        """
        Return the highest speed at which a profile leaves a channel of ``length`` m.

        Leaving with ``acceleration`` (m/s^2, <= 0: still slowing down, or none) along
        the channel; 0 when none does.
        """
        low, high = 0.0, self.speed * (1.0 - SPEED_MARGIN)
        if _solved(length, high, acceleration, self) is not None:
            return high
        if _solved(length, low, acceleration, self) is None:
            return 0.0
        for _ in range(BISECTIONS):
            middle = 0.5 * (low + high)
            if middle in (low, high):
                break
            low, high = (middle, high) if _solved(length, middle, acceleration, self) \
                is not None else (low, middle)
        return low

    def time(self, length: float, speed: float, acceleration: float = 0.0) -> Optional[float]:
        """Return the duration of ``profile``, None when there is none (it would move back)."""
        solved = _solved(length, speed, acceleration, self)
        return None if solved is None else solved.duration


@dataclass(frozen=True, eq=False)
class Profile:
    """sigma(t) from rest at 0 to (``length``, speed, acceleration): seven phases."""

    starts: np.ndarray
    """(8,) the phases' start times, then the end time (s)."""
    jerks: np.ndarray
    """(7,) each phase's jerk (m/s^3)."""
    states: np.ndarray
    """(8, 3) sigma, its speed and acceleration at each start, then at the end."""

    @property
    def duration(self) -> float:
        """Return the profile's time (s)."""
        return float(self.starts[-1])

    @property
    def length(self) -> float:
        """Return the distance covered (m)."""
        return float(self.states[-1, 0])

    @property
    def end_speed(self) -> float:
        """Return the speed at the end (m/s)."""
        return float(self.states[-1, 1])

    @property
    def end_acceleration(self) -> float:
        """Return the acceleration at the end (m/s^2)."""
        return float(self.states[-1, 2])

    def evaluate(self, t) -> np.ndarray:
        """Return (K, 4): sigma and its first three derivatives at times ``t`` (clipped)."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        k = np.clip(np.searchsorted(self.starts, t, side='right') - 1, 0, len(self.jerks) - 1)
        tau = t - self.starts[k]
        (p, v, a), j = self.states[k].T, self.jerks[k]
        out = np.stack([p + tau * (v + tau * (a / 2.0 + tau * j / 6.0)),
                        v + tau * (a + tau * j / 2.0), a + tau * j, j], axis=1)
        at_end = t >= self.duration
        out[at_end, :3] = self.states[-1]
        return out

    def peak_speed(self, a, b) -> np.ndarray:
        """Return the exact largest |sigma'| on each [a_k, b_k] within one phase, (K,)."""
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        k = np.clip(np.searchsorted(self.starts, 0.5 * (a + b), side='right') - 1, 0,
                    len(self.jerks) - 1)
        (_, v, acc), j = self.states[k].T, self.jerks[k]

        def speed(tau):
            return np.abs(v + tau * (acc + tau * j / 2.0))

        low, high = a - self.starts[k], b - self.starts[k]
        peaks = np.maximum(speed(low), speed(high))
        with np.errstate(divide='ignore', invalid='ignore'):
            turn = np.where(j != 0.0, -acc / j, -np.inf)
        inside = (turn > low) & (turn < high)
        return np.where(inside, np.maximum(peaks, speed(np.where(inside, turn, low))), peaks)

    def slowest(self) -> float:
        """Return the least sigma' over the profile (exact: each phase's ends and turn)."""
        tau = np.diff(self.starts)
        (_, v, a), j = self.states[:-1].T, self.jerks
        with np.errstate(divide='ignore', invalid='ignore'):
            turn = np.where(j != 0.0, -a / j, -1.0)
        turn = np.where((turn > 0.0) & (turn < tau), turn, 0.0)
        at_turn = v + turn * (a + turn * j / 2.0)
        return float(min(self.states[:, 1].min(), at_turn.min()))

    def describe(self) -> dict:
        """Return the profile as plain data."""
        return {'starts': self.starts.tolist(), 'jerks': self.jerks.tolist(),
                'states': self.states.tolist()}

    @classmethod
    def described(cls, data) -> 'Profile':
        """Return the profile ``describe`` gave (raise ValueError if it is not one)."""
        try:
            made = cls(*(np.asarray(data[k], float) for k in ('starts', 'jerks', 'states')))
        except (KeyError, TypeError) as exc:
            raise ValueError(f'not a profile: {exc}') from None
        if made.starts.shape != (8,) or made.jerks.shape != (7,) or \
                made.states.shape != (8, 3):
            raise ValueError(f'a profile with shapes {made.starts.shape}, '
                             f'{made.jerks.shape}, {made.states.shape}')
        return made

    def ill_formed(self) -> Optional[str]:
        """Return what makes the data no profile from rest that never moves back, or None."""
        if not (np.isfinite(self.starts).all() and np.isfinite(self.jerks).all()
                and np.isfinite(self.states).all()):
            return 'its data are not finite'
        if self.starts[0] != 0.0 or np.any(np.diff(self.starts) < 0.0):
            return f'its phase times {self.starts.tolist()} do not ascend from 0'
        if np.any(self.states[0] != 0.0):
            return f'it starts at {self.states[0].tolist()}, not at rest at 0'
        # Each phase must end where the next starts (its cubic integrated).
        tau = np.diff(self.starts)
        p, v, a = self.states[:-1].T
        j = self.jerks
        integrated = np.stack([p + tau * (v + tau * (a / 2.0 + tau * j / 6.0)),
                               v + tau * (a + tau * j / 2.0), a + tau * j], axis=1)
        gap = np.abs(integrated - self.states[1:]).max()
        if not gap <= 1e-9:
            return f'its phases do not join (by {gap:.3g})'
        if not self.slowest() >= -BACKWARDS:
            return f'it moves back (at {self.slowest():.3g} m/s)'
        return None


def profile(length: float, speed: float, bounds: Bounds,
            acceleration: float = 0.0) -> Profile:
    """
    Return the fastest profile from rest over ``length`` m ending at (speed, acceleration).

    Raise ValueError when there is none that never moves back (``Bounds.reach``).
    """
    solved = _solved(length, speed, acceleration, bounds)
    if solved is None:
        raise ValueError(f'a channel of {length:.6g} m cannot be left at {speed:.6g} m/s '
                         f'and {acceleration:.6g} m/s^2 (at most '
                         f'{bounds.reach(length, acceleration):.6g} m/s then)')
    return solved


def _solved(length: float, speed: float, acceleration: float,
            bounds: Bounds) -> Optional[Profile]:
    """Return Ruckig's time-optimal profile, None when it has none or it moves back."""
    if not (0.0 <= speed <= bounds.speed and abs(acceleration) <= bounds.acceleration):
        return None
    given = ruckig.InputParameter(1)
    given.current_position, given.current_velocity, given.current_acceleration = \
        [0.0], [0.0], [0.0]
    given.target_position, given.target_velocity, given.target_acceleration = \
        [length], [speed], [acceleration]
    given.max_velocity, given.max_acceleration, given.max_jerk = \
        [bounds.speed], [bounds.acceleration], [bounds.jerk]
    trajectory = ruckig.Trajectory(1)
    try:
        if ruckig.Ruckig(1).calculate(given, trajectory) != ruckig.Result.Working:
            return None
    except (ruckig.RuckigError, RuntimeError):  # a target it cannot reach within the bounds
        return None
    phases = trajectory.profiles[0][0]
    starts = np.concatenate([[0.0], np.cumsum(phases.t)])
    states = np.stack([phases.p, phases.v, phases.a], axis=1)
    # Exact at the end: the channel's mouth state.
    states[-1] = (length, speed, acceleration)
    made = Profile(starts, np.asarray(phases.j, float), states)
    return made if made.slowest() >= -BACKWARDS else None
