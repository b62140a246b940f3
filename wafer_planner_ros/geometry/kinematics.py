"""
Kinematics of the planar three-joint wafer-transfer arm.

q1 is the shoulder angle from +x; q2 and q3 are relative (elbow, wrist); the blade heading
is q1 + q2 + q3. Every function takes configurations of shape (..., 3) and vectorises over
the leading axes.
"""

from dataclasses import dataclass

import numpy as np

from wafer_planner_ros.kernels import kernel


ELBOW_WORDS = {1: 'elbow right', -1: 'elbow left'}
"""
Plain words for the elbow branches, by the sign of q2.

Seen from above (z up), with q2 > 0 the elbow lies to the right of the line from the
shoulder to the wrist, as a right arm bends; with q2 < 0, to the left.
"""


def elbow_words(elbow) -> str:
    """Return 'elbow right' (+1), 'elbow left' (-1) or '' (None: joint angles, no branch)."""
    return '' if elbow is None else ELBOW_WORDS[1 if elbow >= 0 else -1]


@dataclass(frozen=True)
class IkSolution:
    """One inverse-kinematics branch of a wafer pose."""

    elbow: int
    """Sign of q2: +1 or -1."""
    q: np.ndarray
    """Joint angles (rad), shape (3,)."""


@dataclass(frozen=True, eq=False)
class PlanarArm:
    """A planar serial arm: shoulder at ``base``, links of ``link_lengths`` (m)."""

    base: np.ndarray
    """Shoulder axis position (m), shape (2,)."""
    link_lengths: np.ndarray
    """Shoulder->elbow, elbow->wrist, wrist->wafer centre (m), shape (3,)."""

    def absolute_angles(self, q: np.ndarray) -> np.ndarray:
        """Return the absolute angle of each link from +x (rad), shape (..., 3)."""
        return np.cumsum(q, axis=-1)

    def joint_points(self, q: np.ndarray) -> np.ndarray:
        """Return base, elbow, wrist and wafer centre (m), shape (..., 4, 2)."""
        theta = self.absolute_angles(np.asarray(q, dtype=float))
        steps = self.link_lengths[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        points = np.empty(theta.shape[:-1] + (4, 2))
        points[..., 0, :] = self.base
        points[..., 1:, :] = self.base + np.cumsum(steps, axis=-2)
        return points

    def wafer_center(self, q: np.ndarray) -> np.ndarray:
        """Return the wafer-centre position (m), shape (..., 2)."""
        return self.joint_points(q)[..., 3, :]

    def heading(self, q: np.ndarray) -> np.ndarray:
        """Return the blade heading q1 + q2 + q3 (rad)."""
        return np.sum(q, axis=-1)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Return d(wafer centre)/dq, shape (..., 2, 3)."""
        theta = self.absolute_angles(np.asarray(q, dtype=float))
        # Column i sums the contributions of links i..2, all rotated by joint i.
        tail_x = np.cumsum((self.link_lengths * np.cos(theta))[..., ::-1], axis=-1)[..., ::-1]
        tail_y = np.cumsum((self.link_lengths * np.sin(theta))[..., ::-1], axis=-1)[..., ::-1]
        return np.stack([-tail_y, tail_x], axis=-2)

    def wafer_velocity(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Return the wafer-centre velocity (m/s), shape (..., 2)."""
        return np.einsum('...ij,...j->...i', self.jacobian(q), qd)

    def wafer_acceleration(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Return the wafer-centre acceleration (m/s^2) for (q, qd, qdd), shape (..., 2)."""
        return np.stack(self.wafer_acceleration_xy(q, qd, qdd), axis=-1)

    def wafer_acceleration_xy(self, q, qd, qdd) -> tuple:
        """Return the wafer-centre acceleration's x and y components (m/s^2), each (...,)."""
        q, qd, qdd = (np.asarray(x, dtype=float) for x in (q, qd, qdd))
        shape = np.broadcast_shapes(q.shape, qd.shape, qdd.shape)
        q, qd, qdd = (np.ascontiguousarray(np.broadcast_to(x, shape).reshape(-1, 3))
                      for x in (q, qd, qdd))
        ax, ay = _wafer_acceleration_many(np.asarray(self.link_lengths, float), q, qd, qdd)
        return ax.reshape(shape[:-1]), ay.reshape(shape[:-1])

    def wafer_jerk(self, q, qd, qdd, qddd) -> np.ndarray:
        """
        Return the wafer-centre jerk (m/s^3) for (q, qd, qdd, qddd), shape (..., 2).

        With th_j, w_j, a_j, z_j the cumulative joint angles, velocities, accelerations and
        jerks: p''' = sum_j l_j ((z_j - w_j^3) (-sin th_j, cos th_j)
        - 3 w_j a_j (cos th_j, sin th_j)).
        """
        states = [np.asarray(x, dtype=float) for x in (q, qd, qdd, qddd)]
        shape = np.broadcast_shapes(*(x.shape for x in states))
        states = [np.ascontiguousarray(np.broadcast_to(x, shape).reshape(-1, 3))
                  for x in states]
        jerk = _wafer_jerk_many(np.asarray(self.link_lengths, float), *states)
        return jerk.reshape(shape[:-1] + (2,))

    def inverse(self, wafer_center, heading: float, position_limits: np.ndarray) -> list:
        """
        Return the IK branches placing the wafer centre at ``wafer_center`` with ``heading``.

        Angles are wrapped by multiples of 2*pi into ``position_limits`` (shape (3, 2));
        a branch that cannot be wrapped into the limits is left out. An unreachable pose
        gives an empty list.
        """
        l1, l2, l3 = self.link_lengths
        wrist = np.asarray(wafer_center, float) - l3 * np.array([np.cos(heading), np.sin(heading)])
        dx, dy = wrist - self.base
        with np.errstate(over='ignore', divide='ignore', invalid='ignore'):
            # A pose far beyond reach (or an absurdly short link) overflows: unreachable.
            cos_q2 = (dx * dx + dy * dy - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        if not abs(cos_q2) <= 1.0 + 1e-12:
            return []
        solutions = []
        for elbow in (1, -1):
            q2 = elbow * np.arccos(np.clip(cos_q2, -1.0, 1.0))
            q1 = np.arctan2(dy, dx) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
            q = wrap_into_limits(np.array([q1, q2, heading - q1 - q2]), position_limits)
            if q is not None and not any(np.allclose(q, s.q) for s in solutions):
                solutions.append(IkSolution(elbow=elbow, q=q))
        return solutions


def wrap_into_limits(q: np.ndarray, position_limits: np.ndarray):
    """Return q with each angle shifted by a multiple of 2*pi into its limits, or None."""
    lower, upper = position_limits[:, 0], position_limits[:, 1]
    # Smallest shift that brings the angle at or above the lower limit.
    shifted = q + 2.0 * np.pi * np.ceil((lower - q) / (2.0 * np.pi) - 1e-12)
    inside = (shifted >= lower - 1e-12) & (shifted <= upper + 1e-12)
    return np.clip(shifted, lower, upper) if bool(np.all(inside)) else None


@kernel(nogil=True)
def wafer_acceleration_point(link_lengths, q, qd, qdd):
    """
    Return the wafer-centre acceleration (ax, ay) of one state (float or complex).

    p = base + sum_j l_j (cos th_j, sin th_j) with th_j = q_1 + ... + q_j, so
    p'' = sum_j l_j (a_j (-sin th_j, cos th_j) - w_j^2 (cos th_j, sin th_j)), w and a
    being the cumulative joint velocities and accelerations.
    """
    theta, omega, alpha = 0.0 * q[0], 0.0 * q[0], 0.0 * q[0]
    ax, ay = 0.0 * q[0], 0.0 * q[0]
    for j in range(3):
        theta, omega, alpha = theta + q[j], omega + qd[j], alpha + qdd[j]
        c, s, spin = np.cos(theta), np.sin(theta), omega * omega
        ax = ax - link_lengths[j] * (alpha * s + spin * c)
        ay = ay + link_lengths[j] * (alpha * c - spin * s)
    return ax, ay


@kernel(nogil=True)
def _wafer_acceleration_many(link_lengths, q, qd, qdd):
    ax, ay = np.empty(len(q)), np.empty(len(q))
    for k in range(len(q)):
        ax[k], ay[k] = wafer_acceleration_point(link_lengths, q[k], qd[k], qdd[k])
    return ax, ay


@kernel(nogil=True)
def _wafer_jerk_many(link_lengths, q, qd, qdd, qddd):
    jerk = np.zeros((len(q), 2))
    for k in range(len(q)):
        theta, omega, alpha, zeta = 0.0, 0.0, 0.0, 0.0
        for j in range(3):
            theta, omega = theta + q[k, j], omega + qd[k, j]
            alpha, zeta = alpha + qdd[k, j], zeta + qddd[k, j]
            c, s = np.cos(theta), np.sin(theta)
            turn = link_lengths[j] * (zeta - omega ** 3)
            pull = 3.0 * link_lengths[j] * omega * alpha
            jerk[k, 0] += -turn * s - pull * c
            jerk[k, 1] += turn * c - pull * s
    return jerk
