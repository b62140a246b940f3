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

from wafer_planner_ros.trajectory.jerk_profile import JerkProfile

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
class Profile(JerkProfile):
    """sigma(t) from rest at 0 to (``length``, speed, acceleration): seven phases."""

    @property
    def length(self) -> float:
        """Return the distance covered (m)."""
        return float(self.states[-1, 0])

    @classmethod
    def described(cls, data) -> 'Profile':
        """Return the profile ``describe`` gave (raise ValueError if it is not one)."""
        made = super().described(data)
        if made.starts.shape != (8,):
            raise ValueError(f'a profile with shapes {made.starts.shape}, '
                             f'{made.jerks.shape}, {made.states.shape}')
        return made

    def ill_formed(self) -> Optional[str]:
        """Return what makes the data no profile from rest that never moves back, or None."""
        problem = self.structure_problem()
        if problem is not None:
            return problem
        if np.any(self.states[0] != 0.0):
            return f'it starts at {self.states[0].tolist()}, not at rest at 0'
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
