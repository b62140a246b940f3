"""
Named limit sets: what a motion may not exceed with a wafer on the blade, or without one.

A cell has two: ``loaded`` (the joint limits and the wafer limit, the acceleration at
which friction stops holding the wafer on the blade) and ``empty`` (joint limits only, the
loaded ones unless the cell file raises them: with no wafer on the blade nothing slides).
A motion is planned and verified against one set. Each limit gives the optimisers its rows
(``rows``: the bounds the constraint kernels take, with the optimisers' margin) and the
verification its check (``ratios``: the largest |value| / limit over the states checked),
so that what the optimiser keeps and what the verification checks are one definition.
"""

from dataclasses import dataclass
from typing import Dict, Optional

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

    def rows(self, margin: float) -> np.ndarray:
        """Return the bounds of the control-point rows: velocity, acceleration (, jerk)."""
        orders = [self.velocity, self.acceleration] + (
            [self.jerk] if self.jerk is not None else [])
        return margin * np.array(orders, float)

    def ratios(self, qd: np.ndarray, qdd: np.ndarray, qddd: np.ndarray) -> Dict[str, float]:
        """Return the largest |value| / limit of velocity, acceleration (, jerk)."""
        ratios = {'velocity': _ratio(qd, self.velocity),
                  'acceleration': _ratio(qdd, self.acceleration)}
        if self.jerk is not None:
            ratios['jerk'] = _ratio(qddd, self.jerk)
        return ratios

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

    def rows(self, margin: float) -> np.ndarray:
        """Return the bounds the wafer-sample rows take: x, y, |a| (0: no |a| row)."""
        return margin * np.array([self.xy[0], self.xy[1], self.norm or 0.0])

    def ratio(self, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """Return the worst |value| / limit of x, y (, |a|) at each sample."""
        ratio = np.maximum(np.abs(ax) / self.xy[0], np.abs(ay) / self.xy[1])
        if self.norm is not None:
            ratio = np.maximum(ratio, np.hypot(ax, ay) / self.norm)
        return ratio

    def ratios(self, wafer: np.ndarray) -> Dict[str, float]:
        """Return the largest |value| / limit on x, y (, |a|) of accelerations (K, 2)."""
        ratios = {'wafer_x': _ratio(wafer[:, 0], self.xy[0]),
                  'wafer_y': _ratio(wafer[:, 1], self.xy[1])}
        if self.norm is not None:
            ratios['wafer_norm'] = float(np.max(np.hypot(wafer[:, 0], wafer[:, 1]),
                                                initial=0.0) / self.norm)
        return ratios


@dataclass(frozen=True, eq=False)
class LimitSet:
    """The limits one motion keeps: its joints', and the wafer's when one is on the blade."""

    name: str
    """``LOADED`` or ``EMPTY``."""
    joints: JointLimits
    wafer: Optional[WaferLimit]
    """None: no wafer on the blade, no wafer limit."""

    def ratios(self, qd, qdd, qddd, wafer: np.ndarray) -> Dict[str, float]:
        """Return the largest |value| / limit of each limit over states (``verify``)."""
        ratios = self.joints.ratios(qd, qdd, qddd)
        if self.wafer is not None:
            ratios.update(self.wafer.ratios(wafer))
        return ratios

    def wafer_ratio(self, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """Return the worst wafer ratio at each sample (zeros without a wafer limit)."""
        return np.zeros(np.shape(ax)) if self.wafer is None else self.wafer.ratio(ax, ay)


def _ratio(values: np.ndarray, limit) -> float:
    return float(np.max(np.abs(values) / limit, initial=0.0))
