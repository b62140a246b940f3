"""
The limits a motion keeps, as objects handed to the optimisers and the verification.

One object per kind of limit, each with everything that limit means: the rows g >= 0 it
gives an optimiser (with their exact Jacobians, compiled in ``rows``), the check the
verification makes of it (the largest |value| / limit over the states checked), and how
that check scales when a curve is slowed (its order in time). What the optimiser keeps and
what the verification checks are one definition, as toppra hands its algorithm a list of
constraint objects.

- ``JointBound``: one derivative's limit per joint (velocity, acceleration, jerk), on the
  control points of that derivative (Eq. 6-8).
- ``WaferBound``: the wafer-centre acceleration on x and y (and |a|) at samples (Eq. 9).
- ``PositionBound``: the joint angles, as the bounds of the points the optimiser moves.
- ``ClearanceBound``: the distance of each body to the walls and the port margins of a
  motion model at samples (the model's Lipschitz constants are what the proof steps by).

``limit_constraints`` makes a limit set's (``cell.limits``) list; the knot-time and the
whole-curve problems take such a list, and ``verify`` checks the same objects. The
clearance is the cell's: the whole-curve problem adds its ``ClearanceBound``.
"""

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from wafer_planner_ros.cell.limits import JointLimits, LimitSet
from wafer_planner_ros.trajectory.rows import control_row_count, control_rows
from wafer_planner_ros.trajectory.rows import position_samples, scatter_rows, wafer_rows

POSITION_MARGIN = 1e-6
"""rad: control points the optimiser moves stay this far inside the position limits, so
that rounding in evaluating the curve never puts it beyond a limit (a point on the limit
did, by 1e-16)."""
CLEARANCE_SCALE = 0.01
"""m: clearance rows are (d - kept) / this, of the order of the other rows."""


@dataclass(frozen=True)
class States:
    """A curve's states at the verification's check times (``verify.limit_states``)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    qddd: np.ndarray
    wafer: np.ndarray
    """(K, 2) the wafer centre's acceleration (m/s^2)."""

    @property
    def derivatives(self) -> tuple:
        """Return (q, q', q'', q''')."""
        return self.q, self.qd, self.qdd, self.qddd


@dataclass(frozen=True, eq=False)
class JointBound:
    """|q^(order)| <= limit for every joint, kept on that derivative's control points."""

    name: str
    """'velocity', 'acceleration' or 'jerk': the verification's name of its ratio."""
    order: int
    """The derivative: 1, 2 or 3; also the ratio's order in time (q(t / λ) divides it by
    λ ** order)."""
    limit: np.ndarray
    """(3,) per joint (rad/s^order)."""
    margin: float = 1.0
    """The share of the limit the optimiser's rows keep."""

    @property
    def kept(self) -> np.ndarray:
        """Return the limit the rows keep: ``margin`` of it."""
        return self.margin * self.limit

    def row_count(self, points: int) -> int:
        """Return the rows of a curve of ``points`` control points."""
        return control_row_count(points, self.order)

    def write_rows(self, points, intervals, columns, values, jacobian, row: int,
                   gradients: bool = True) -> int:
        """
        Write the rows 1 - (D / kept)^2 from ``row`` on, and their Jacobian (``rows``).

        ``columns``: (point column (count, 3), duration column (m,), duration scale (m,)).
        Return the row after the last written.
        """
        return control_rows(points, intervals, self.kept, self.order, *columns, values,
                            jacobian, row, gradients)

    def peak(self, derivative_points: np.ndarray) -> float:
        """Return the largest |D| / kept of this derivative's control points."""
        return float(np.max(np.abs(derivative_points) / self.kept, initial=0.0))

    def ratios(self, states: States) -> Dict[str, float]:
        """Return the largest |q^(order)| / limit over the states (the verification's)."""
        return {self.name: _largest(states.derivatives[self.order], self.limit)}

    def orders(self) -> Dict[str, int]:
        """Return each ratio's order in time."""
        return {self.name: self.order}


@dataclass(frozen=True, eq=False)
class WaferBound:
    """The wafer centre's acceleration on x and y (and |a|), kept at samples."""

    limits: np.ndarray
    """(2,) m/s^2 on x and y, or (3,) with |a| too."""
    margin: float = 1.0
    """The share of each limit the optimiser's rows keep."""
    names = ('wafer_x', 'wafer_y', 'wafer_norm')
    order = 2
    """q(t / λ) divides the wafer acceleration, J(q) q'' + (dJ/dt) q', by λ ** 2."""

    @property
    def parts(self) -> int:
        """Return the rows per sample: x, y (, |a|)."""
        return len(self.limits)

    def write_rows(self, padded, points, span, fraction, link_lengths, columns, values,
                   jacobian, row: int) -> int:
        """Write the rows at the (span, fraction) samples from ``row`` on; return the next."""
        local = self.sample_values(padded, points, span, fraction, link_lengths, True)
        scatter_rows(jacobian, values, row, *local, span, *columns)
        return row + self.parts * len(span)

    def sample_values(self, padded, points, span, fraction, link_lengths,
                      gradients: bool) -> tuple:
        """Return ``rows.wafer_rows`` at the samples with the margin: (c, K) values, ...)."""
        return wafer_rows(padded, points, span, fraction, link_lengths,
                          self.margin * self.limits, gradients)

    def ratio(self, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """Return the worst |value| / limit of x, y (, |a|) at each sample."""
        ratio = np.maximum(np.abs(ax) / self.limits[0], np.abs(ay) / self.limits[1])
        if self.parts == 3:
            ratio = np.maximum(ratio, np.hypot(ax, ay) / self.limits[2])
        return ratio

    def ratios(self, states: States) -> Dict[str, float]:
        """Return the largest |value| / limit on x, y (, |a|) over the states."""
        wafer = states.wafer
        ratios = {'wafer_x': _largest(wafer[:, 0], self.limits[0]),
                  'wafer_y': _largest(wafer[:, 1], self.limits[1])}
        if self.parts == 3:
            ratios['wafer_norm'] = float(np.max(np.hypot(wafer[:, 0], wafer[:, 1]),
                                                initial=0.0) / self.limits[2])
        return ratios

    def orders(self) -> Dict[str, int]:
        """Return each ratio's order in time."""
        return {name: self.order for name in self.names[:self.parts]}


@dataclass(frozen=True, eq=False)
class PositionBound:
    """The joint angles within their limits: the bounds of the points the optimiser moves."""

    joints: JointLimits
    """The limit set's joint limits (their ``position``, (3, 2) rad)."""
    margin: float = POSITION_MARGIN
    """rad kept inside by what the optimiser moves."""

    @property
    def inner(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return (lower, upper): the limits ``margin`` inside, what moved points keep."""
        lower, upper = self.joints.position.T
        return lower + self.margin, upper - self.margin

    def outside(self, q: np.ndarray) -> np.ndarray:
        """Return the joints outside the limits in any configuration of ``q`` (the check)."""
        return self.joints.outside(q)


@dataclass(frozen=True, eq=False)
class ClearanceBound:
    """Each body's distance to the walls, and each port margin, of a motion model."""

    model: object
    """A clearance model (``geometry.clearance``; with ports, ``geometry.ports``): its
    ``lipschitz`` (B, 3) bounds how far each body moves per rad of each joint, what the
    corridor and the proof step by."""

    def write_rows(self, padded, points, span, fraction, body, kept, columns, values,
                   jacobian, row: int) -> int:
        """
        Write (d - kept) / CLEARANCE_SCALE at the (span, fraction, body, kept) samples.

        By the body Jacobian through the basis weights; from ``row`` on; return the next.
        Each sample's configuration, its derivatives and every body's clearance are
        computed once, however many of its bodies have rows (about three): the same
        values, in a third of the time.
        """
        spans, fractions, at = _distinct(span, fraction)
        q, q_h, q_p = position_samples(padded, points, spans, fractions, True)
        distance, gradient = self.model.body_clearance_gradient(np.ascontiguousarray(q.T))
        distance, gradient = distance[at, body], gradient[at, body]    # (K,), (K, 3)
        by_h = np.einsum('ikd,ki->kd', q_h[:, at], gradient)
        by_p = q_p[0, at, :, 0][:, :, None] * gradient[:, None, :]     # (K, 4, 3)
        scatter_rows(jacobian, values, row, ((distance - kept) / CLEARANCE_SCALE)[None],
                     by_h[None] / CLEARANCE_SCALE, by_p[None] / CLEARANCE_SCALE, span,
                     *columns)
        return row + len(span)


def _distinct(span: np.ndarray, fraction: np.ndarray) -> tuple:
    """Return the distinct (span, fraction) samples, and which of them each one is."""
    order = np.lexsort((fraction, span))
    span, fraction = span[order], fraction[order]
    first = np.ones(len(span), dtype=bool)
    first[1:] = (span[1:] != span[:-1]) | (fraction[1:] != fraction[:-1])
    at = np.empty(len(span), dtype=np.int64)
    at[order] = np.cumsum(first) - 1
    return (np.ascontiguousarray(span[first], dtype=np.int64),
            np.ascontiguousarray(fraction[first]), at)


def limit_constraints(limit_set: LimitSet, margin: float = 1.0) -> List:
    """
    Return a limit set's constraints: joint bounds per order, wafer bound, position bound.

    ``margin``: the share of each limit the optimiser's rows keep (the verification
    checks the limits themselves). Velocity first, then acceleration (then jerk), then the
    wafer limit when a wafer is on the blade (the order of the rows), then the positions.
    """
    joints = limit_set.joints
    orders = [('velocity', joints.velocity), ('acceleration', joints.acceleration)] + (
        [('jerk', joints.jerk)] if joints.jerk is not None else [])
    bounds: List = [JointBound(name, k + 1, np.asarray(limit, float), margin)
                    for k, (name, limit) in enumerate(orders)]
    if limit_set.wafer is not None:
        bounds.append(WaferBound(np.asarray(limit_set.wafer.values, float), margin))
    return bounds + [PositionBound(joints)]


def time_limits(constraints) -> List:
    """Return the limits a slower timing relaxes: the joint bounds and the wafer bound."""
    return [c for c in constraints if isinstance(c, (JointBound, WaferBound))]


def state_ratios(constraints, states: States) -> Dict[str, float]:
    """Return the largest |value| / limit of every time limit of a list over the states."""
    ratios: Dict[str, float] = {}
    for constraint in time_limits(constraints):
        ratios.update(constraint.ratios(states))
    return ratios


def position_bound(constraints) -> PositionBound:
    """Return the list's ``PositionBound``."""
    return next(c for c in constraints if isinstance(c, PositionBound))


def joint_bounds(constraints) -> List[JointBound]:
    """Return the ``JointBound`` objects of a list, in its order."""
    return [c for c in constraints if isinstance(c, JointBound)]


def wafer_bound(constraints) -> Optional[WaferBound]:
    """Return the list's ``WaferBound``, None when no wafer is on the blade."""
    return next((c for c in constraints if isinstance(c, WaferBound)), None)


def ratio_orders(constraints) -> Dict[str, int]:
    """Return every time limit's ratio's order in time (``timing_problem.meet_limits``)."""
    orders: Dict[str, int] = {}
    for constraint in time_limits(constraints):
        orders.update(constraint.orders())
    return orders


def _largest(values: np.ndarray, limit) -> float:
    """Return the largest |value| / limit (0 of none)."""
    return float(np.max(np.abs(values) / limit, initial=0.0))
