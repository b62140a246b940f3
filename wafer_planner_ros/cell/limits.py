"""
Named limit sets: what a motion may not exceed with a wafer on the blade, or without one.

A cell has two: ``loaded`` (the joint limits and the wafer limit, the acceleration at
which friction stops holding the wafer on the blade) and ``empty`` (joint limits only, the
loaded ones unless the cell file raises them: with no wafer on the blade nothing slides).
A motion is planned and verified against one set. These are the values the cell file
gives; what each limit means to the optimisers and the verification (its rows, its check)
is its constraint object (``trajectory.constraints``), made from a set.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

LOADED = 'loaded'
"""The limit set with a wafer on the blade (the joint limits and the wafer limit)."""
EMPTY = 'empty'
"""The limit set without a wafer (the joint limits only)."""
LOADS = (LOADED, EMPTY)


@dataclass(frozen=True, eq=False)
class JointLimits:
    """Joint limits, one row or entry per joint."""

    position: np.ndarray
    """(3, 2) lower/upper angle (rad)."""
    velocity: np.ndarray
    """(3,) rad/s."""
    acceleration: np.ndarray
    """(3,) rad/s^2."""
    jerk: Optional[np.ndarray] = None
    """(3,) rad/s^3, optional."""

    def outside(self, q) -> np.ndarray:
        """
        Return the joints outside their position limits in any configuration of ``q``.

        ``q``: (3,) or (K, 3); a value that is not a number is outside.
        """
        lower, upper = self.position.T
        q = np.atleast_2d(np.asarray(q, float))
        return np.nonzero(np.any(~((q >= lower) & (q <= upper)), axis=0))[0]

    def shortest_motion(self, displacement) -> np.ndarray:
        """
        Return each joint's shortest rest-to-rest time (s) over ``displacement`` (rad, (3,)).

        The time-optimal profile of one joint alone under its velocity, acceleration and
        jerk limits (jerk bang-bang, ramps of acceleration and a cruise where the distance
        allows them): no motion between two configurations is faster than the largest of
        these, whatever its path.
        """
        distance = np.abs(np.asarray(displacement, float))
        v, a = self.velocity, self.acceleration
        if self.jerk is None:
            cruise = distance >= v * v / a
            with np.errstate(divide='ignore', invalid='ignore'):
                return np.where(cruise, distance / v + v / a, 2.0 * np.sqrt(distance / a))
        j = self.jerk
        ramp = a / j  # s: jerk takes the acceleration from 0 to its limit

        def to_speed(u):  # s: from rest to speed u, fastest
            return np.where(u >= a * ramp, u / a + ramp, 2.0 * np.sqrt(u / j))

        # Without a cruise the motion peaks at the speed u with u * to_speed(u) = distance.
        peak = 0.5 * a * (np.sqrt(ramp * ramp + 4.0 * distance / a) - ramp)
        without_cruise = np.where(distance >= 2.0 * a * ramp * ramp, 2.0 * (peak / a + ramp),
                                  4.0 * np.cbrt(distance / (2.0 * j)))
        with np.errstate(divide='ignore', invalid='ignore'):
            return np.where(distance >= v * to_speed(v), distance / v + to_speed(v),
                            without_cruise)


@dataclass(frozen=True, eq=False)
class WaferLimit:
    """The wafer centre's acceleration limit: on x and y, and optionally on its magnitude."""

    xy: np.ndarray
    """(2,) m/s^2 on x and y."""
    norm: Optional[float] = None
    """m/s^2 on |a|, optional."""

    @property
    def values(self) -> np.ndarray:
        """Return the limits: x, y (, |a|) (m/s^2)."""
        return self.xy if self.norm is None else np.append(self.xy, self.norm)


@dataclass(frozen=True, eq=False)
class LimitSet:
    """The limits one motion keeps: its joints', and the wafer's when one is on the blade."""

    name: str
    """``LOADED`` or ``EMPTY``."""
    joints: JointLimits
    wafer: Optional[WaferLimit]
    """None: no wafer on the blade, no wafer limit."""
