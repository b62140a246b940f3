"""
Where a motion comes closest to the walls and obstacles, and how close.

The closest approach is the configuration of least clearance along the motion, with the
body that is nearest then and the pair of nearest points (``geometry.contacts``). On a
curve it is searched at the verification's collision-check times (no joint moves more than
``verify.COLLISION_STEP`` between two), so its distance is the verified minimum clearance.
A recording holds samples instead (every 10 ms, say): between two, the motion is taken as
the quintic matching the positions, velocities and accelerations at both (exact on the
cubic pieces of a B-spline, close across a knot), searched as finely.
"""

from dataclasses import dataclass

import numpy as np

from wafer_planner_ros.geometry.contacts import body_contacts, BodyContact
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.verify import COLLISION_STEP, collision_times, steps

MOST_CONFIGURATIONS = 200_000
"""Most configurations searched between the samples of one motion."""


@dataclass(frozen=True, eq=False)
class Approach:
    """The closest approach of a motion."""

    time: float
    """s from the start of the motion."""
    q: np.ndarray
    """(3,) the configuration then."""
    contact: BodyContact
    """The nearest body, the wall or obstacle, and their nearest points."""

    @property
    def distance(self) -> float:
        """Return how far (m) the nearest body is from the wall or obstacle."""
        return self.contact.clearance + self.contact.margin


def closest_approach(model, times, q) -> Approach:
    """Return the closest approach over configurations q (N, 3) at ``times`` (N,) s."""
    q = np.atleast_2d(np.asarray(q, float))
    i = int(np.argmin(model.clearance(q)))
    contact = min(body_contacts(model, q[i]), key=lambda c: c.clearance)
    return Approach(time=float(np.asarray(times, float)[i]), q=q[i], contact=contact)


def on_curve(model, curve: Trajectory) -> Approach:
    """Return the closest approach of a curve, as the verification measures it."""
    times = collision_times(curve)
    return closest_approach(model, times, curve.evaluate(times))


def on_samples(model, times, q, qd, qdd) -> Approach:
    """Return the closest approach of sampled states (N,), (N, 3) x 3, between the samples."""
    return closest_approach(model, *densified(times, q, qd, qdd))


def densified(times, q, qd, qdd, step: float = COLLISION_STEP) -> tuple:
    """
    Return (times, q) filling in the samples, no joint moving more than about ``step`` rad.

    Each interval is the quintic matching the positions, velocities and accelerations at
    both of its ends; at most ``MOST_CONFIGURATIONS`` in all. Samples without finite
    velocities and accelerations are returned as they are.
    """
    times, q, qd, qdd = (np.asarray(v, float) for v in (times, q, qd, qdd))
    if len(times) < 2 or not (np.isfinite(qd).all() and np.isfinite(qdd).all()):
        return times, q
    h = np.diff(times)[:, None]
    travel = np.max(np.maximum.reduce([np.abs(np.diff(q, axis=0)), np.abs(qd[:-1]) * h,
                                       np.abs(qd[1:]) * h]), axis=1)
    counts = np.maximum(np.ceil(travel / step), 1).astype(int)
    total = int(counts.sum())
    if total > MOST_CONFIGURATIONS:
        counts = np.maximum(counts * MOST_CONFIGURATIONS // total, 1)
    interval = np.repeat(np.arange(len(h)), counts)
    s = (steps(counts) / np.repeat(counts, counts))[:, None]
    s3, s4, s5 = s ** 3, s ** 4, s ** 5
    span = h[interval]
    q0, q1 = q[interval], q[interval + 1]
    v0, v1 = qd[interval] * span, qd[interval + 1] * span
    a0, a1 = qdd[interval] * span ** 2, qdd[interval + 1] * span ** 2
    # The quintic Hermite basis on s in [0, 1].
    dense = ((1 - 10 * s3 + 15 * s4 - 6 * s5) * q0 + (s - 6 * s3 + 8 * s4 - 3 * s5) * v0
             + (0.5 * s * s - 1.5 * s3 + 1.5 * s4 - 0.5 * s5) * a0
             + (0.5 * s3 - s4 + 0.5 * s5) * a1 + (-4 * s3 + 7 * s4 - 3 * s5) * v1
             + (10 * s3 - 15 * s4 + 6 * s5) * q1)
    return (np.append(times[interval] + s[:, 0] * span[:, 0], times[-1]),
            np.vstack([dense, q[-1:]]))
