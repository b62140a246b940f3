"""
Ports: the straight channel from a station's retracted pose to its pick/place pose.

A port lies along the station's heading: the pick/place pose is ``depth`` beyond the
retracted pose (the wafer centre moved by ``depth`` along the heading, the heading kept).
With ``s`` the wafer centre's distance past the retracted pose along the port's axis and
``y`` its offset from the axis, the wafer is **inside** the port where ``s > |y|``: a
wafer on its way in is inside once it has passed the retracted pose, one that sweeps past
the port's mouth (|y| larger than how far it is past the retracted pose) is not, nor one
that turns at the retracted pose itself. While it is inside, its centre must stay within
``lateral_tolerance`` of the axis and the blade within ``heading_tolerance`` of the
heading: so it enters and leaves the port straight and aligned.

That rule is four margins per port (``PortModel.margins``), all positive exactly where the
rule holds, in metres, so that the proof and the optimiser treat them as they treat a
body's clearance. With ``dh`` the blade's angle from the heading (wrapped into (-pi, pi]):

- outside = (|y| - s) / sqrt(2): positive where the wafer is not inside;
- left, right = max(outside, lateral_tolerance -+ y): the offset on each side;
- turned left, turned right = max(outside, R (heading_tolerance -+ dh)), R =
  lateral_tolerance / heading_tolerance (metres per radian, so that every margin tops out
  at the lateral tolerance).

One margin per side, not one of |y|: each is smooth where the wafer is inside, which the
optimiser's linearised rows need (a wafer on the axis sits on the kink of |y|). All are
1-Lipschitz in the wafer centre's position and the heading ones R-Lipschitz in the
heading, so turning joint i by dq changes them by at most ``PortModel.lipschitz[.., i]
|dq|`` (the distance from joint i's axis to the wafer centre, or R if larger: the heading
moves by dq itself).

**A keep-out round a mouth, for the optimiser.** A wafer that sweeps past a port's mouth
turned is held outside the wedge s > |y|, whose tip is a corner: an optimum that grazes it
sits on a constraint with a kink, and an optimiser whose rows are taken at samples cuts
the corner between them, round after round. ``PortModel.keeping_out`` gives a port a disc
of a radius round the tip besides: its outside term becomes min(outside, sqrt(s^2 + y^2)
- radius), smooth in front of the mouth. That only ever lowers a margin, so a curve that
keeps these margins keeps the rule's; the proof and the verification keep the rule
itself.
"""

from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

DEFAULT_LATERAL_TOLERANCE = 0.001
"""m: how far off the port's axis the wafer centre may be while inside, by default."""
DEFAULT_HEADING_TOLERANCE = 0.0087
"""rad: how far the blade may turn from the port's heading while inside, by default (0.5 deg)."""
MARGINS = ('left', 'right', 'turned left', 'turned right')
"""The four margins of a port, in their order (see the module)."""
CHANNEL_STEP = 0.02
"""m: the spacing of the configurations along a port's channel first checked (halved where
the clearance there does not cover the motion between them)."""


@dataclass(frozen=True, eq=False)
class Port:
    """The port of one station (see the module)."""

    station: str
    retracted: np.ndarray
    """(2,) the wafer centre at the retracted pose (m)."""
    heading: float
    """rad: the blade heading in and out of the port, along its axis."""
    depth: float
    """m: how far beyond the retracted pose the pick/place pose lies."""
    lateral_tolerance: float = DEFAULT_LATERAL_TOLERANCE
    heading_tolerance: float = DEFAULT_HEADING_TOLERANCE

    @property
    def axis(self) -> np.ndarray:
        """Return the unit vector along the heading, into the port."""
        return np.array([np.cos(self.heading), np.sin(self.heading)])

    @property
    def normal(self) -> np.ndarray:
        """Return the unit vector to the left of the axis."""
        return np.array([-np.sin(self.heading), np.cos(self.heading)])

    @property
    def inside_center(self) -> np.ndarray:
        """Return the wafer centre at the pick/place pose (m)."""
        return self.retracted + self.depth * self.axis

    @property
    def heading_scale(self) -> float:
        """Return R (m/rad): the heading margin's metres per radian."""
        return self.lateral_tolerance / self.heading_tolerance

    def offsets(self, centers: np.ndarray) -> tuple:
        """Return (s, y): the distance past the retracted pose and the offset from the axis."""
        d = np.asarray(centers, float) - self.retracted
        (ux, uy), (nx, ny) = self.axis, self.normal
        # Elementwise, not a matrix product: the same rounding however many at once.
        return d[..., 0] * ux + d[..., 1] * uy, d[..., 0] * nx + d[..., 1] * ny

    def channel(self, arm, start_q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """
        Return the configurations (K, 3) placing the wafer ``s`` (K,) m into the port.

        ``start_q`` is the retracted pose on one elbow branch and ``s`` ascends from 0: each
        configuration places the wafer centre on the axis with the port's heading, on the
        same branch, every angle continued from ``start_q`` (no wrap by 2 pi); at s = 0
        exactly ``start_q``. NaN where the arm cannot reach.
        """
        start_q = np.asarray(start_q, float)
        q = self.configurations(arm, s, start_q[1])
        q = np.unwrap(q, axis=0)
        q += 2.0 * np.pi * np.round((start_q - q[0]) / (2.0 * np.pi))
        q[np.asarray(s) == 0.0] = start_q  # the station's configuration, not its rounding
        return q

    def configurations(self, arm, s: np.ndarray, elbow: float, near=None) -> np.ndarray:
        """
        Return the configurations placing the wafer ``s`` m into the port on a branch.

        ``elbow``: the sign of q2 of the branch. ``near`` (K, 3): each angle is shifted by
        a multiple of 2 pi to the nearest to it. NaN where the arm cannot reach.
        """
        centers = self.retracted + np.asarray(s, float)[:, None] * self.axis
        q = inverse_on_branch(arm, centers, self.heading, 1 if elbow >= 0.0 else -1)
        if near is not None:
            q += 2.0 * np.pi * np.round((np.asarray(near, float) - q) / (2.0 * np.pi))
        return q


def inverse_on_branch(arm, centers: np.ndarray, heading: float, elbow: int) -> np.ndarray:
    """Return the (K, 3) configurations placing the wafer at ``centers`` (NaN: out of reach)."""
    l1, l2, l3 = arm.link_lengths
    wrist = np.asarray(centers, float) - l3 * np.array([np.cos(heading), np.sin(heading)])
    d = wrist - arm.base
    cos_q2 = (np.sum(d * d, axis=1) - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    with np.errstate(invalid='ignore'):
        q2 = elbow * np.arccos(np.where(np.abs(cos_q2) <= 1.0, cos_q2, np.nan))
    q1 = np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
    return np.stack([q1, q2, heading - q1 - q2], axis=1)


class PortModel:
    """The port margins of every port of a cell (see the module): four per port."""

    def __init__(self, arm, ports: Sequence[Port], keep_out: Optional[Sequence[float]] = None):
        """
        Keep the arm and the ports; a cell without ports has no margins at all.

        ``keep_out``: per port, the radius (m) of the disc round its mouth kept out of as
        well (0: none; see the module); None: none at all.
        """
        self.arm = arm
        self.ports: Tuple[Port, ...] = tuple(ports)
        self.keep_out = np.zeros(len(self.ports)) if keep_out is None else \
            np.asarray(keep_out, float)
        if self.keep_out.shape != (len(self.ports),) or not np.all(self.keep_out >= 0.0):
            raise ValueError(f'keep_out must be one radius >= 0 per port, not {keep_out!r}')
        reach = np.cumsum(np.asarray(arm.link_lengths, float)[::-1])[::-1]   # (3,)
        rows = []
        for port in self.ports:
            turning = np.maximum(reach, port.heading_scale)
            rows += [reach, reach, turning, turning]
        self.lipschitz = np.array(rows).reshape(-1, 3)
        """(4P, 3) m/rad: the bound on each margin's change per radian of each joint."""
        self.names = tuple(f'{p.station} port {kind}' for p in self.ports
                           for kind in MARGINS)
        self.tolerances = np.repeat([p.lateral_tolerance for p in self.ports], len(MARGINS))
        """(4P,) m: the largest value of each margin (the port's lateral tolerance)."""

    def keeping_out(self, radius: float, ends: np.ndarray) -> 'PortModel':
        """
        Return these margins with a disc of ``radius`` round every other port's mouth.

        ``ends`` (N, 3): configurations a curve starts or ends at; a port whose mouth (the
        wafer centre at its retracted pose) one of them puts the wafer at gets no disc,
        as the curve leaves or enters it there.
        """
        centers = self.arm.wafer_center(np.atleast_2d(np.asarray(ends, float)))
        return PortModel(self.arm, self.ports, [
            0.0 if np.min(np.hypot(*(centers - port.retracted).T)) < 1e-9 else radius
            for port in self.ports])

    def breaks_keep_out(self, path: np.ndarray) -> bool:
        """
        Return whether configurations along a curve come within a keep-out, turned.

        Turned: the wafer off that port's axis or heading by more than its tolerance
        (where the rule holds it to the outside term, which the disc lowers).
        """
        path = np.atleast_2d(np.asarray(path, float))
        centers, heading = self.arm.wafer_center(path), self.arm.heading(path)
        for port, radius in zip(self.ports, self.keep_out):
            if radius <= 0.0:
                continue
            s, y = port.offsets(centers)
            loose = (np.abs(y) > port.lateral_tolerance) | \
                (np.abs(_wrapped(heading - port.heading)) > port.heading_tolerance)
            if np.any(np.hypot(s, y)[loose] < radius):
                return True
        return False

    def __len__(self) -> int:
        """Return the number of margins (four per port)."""
        return len(MARGINS) * len(self.ports)

    def margins(self, q: np.ndarray) -> np.ndarray:
        """Return each configuration's margins, (N, 4P) for (N, 3): <= 0 breaks the rule (m)."""
        return self._margins(q, False)[0]

    def margins_gradient(self, q: np.ndarray) -> tuple:
        """
        Return the margins (N, 4P) and their gradient d margin / d q (N, 4P, 3).

        The gradient of the larger term of each max (the outside term where they tie; of
        |y| in it the one on the positive side at zero).
        """
        return self._margins(q, True)

    def inside(self, q: np.ndarray) -> np.ndarray:
        """Return the index of the port the wafer is inside for each configuration, or -1."""
        q = np.atleast_2d(np.asarray(q, float))
        where = np.full(len(q), -1)
        centers = self.arm.wafer_center(q)
        for k, port in enumerate(self.ports):
            s, y = port.offsets(centers)
            where[(where < 0) & (s > np.abs(y))] = k
        return where

    def deviation(self, q: np.ndarray) -> tuple:
        """Return (port index or -1, |offset| (m), |heading error| (rad)) of each config."""
        q = np.atleast_2d(np.asarray(q, float))
        where = self.inside(q)
        centers, heading = self.arm.wafer_center(q), self.arm.heading(q)
        offset, turn = np.zeros(len(q)), np.zeros(len(q))
        for k, port in enumerate(self.ports):
            at = where == k
            offset[at] = np.abs(port.offsets(centers[at])[1])
            turn[at] = np.abs(_wrapped(heading[at] - port.heading))
        return where, offset, turn

    def _margins(self, q, gradients: bool) -> tuple:
        q = np.atleast_2d(np.asarray(q, float)).reshape(-1, 3)
        n = len(q)
        values = np.empty((n, len(self)))
        grad = np.zeros((n, len(self), 3)) if gradients else None
        if not self.ports:
            return values, grad
        centers, heading = self.arm.wafer_center(q), self.arm.heading(q)
        jac = self.arm.jacobian(q) if gradients else None                 # (N, 2, 3)
        for k, port in enumerate(self.ports):
            s, y = port.offsets(centers)
            side = np.where(y >= 0.0, 1.0, -1.0)
            dh = _wrapped(heading - port.heading)
            outside = (np.abs(y) - s) / np.sqrt(2.0)
            radius = self.keep_out[k]
            if radius > 0.0:
                tip = np.hypot(s, y)
                in_disc = tip - radius < outside
                outside = np.minimum(outside, tip - radius)
            tol, scale = port.lateral_tolerance, port.heading_scale
            terms = (tol - y, tol + y, scale * (port.heading_tolerance - dh),
                     scale * (port.heading_tolerance + dh))
            first = len(MARGINS) * k
            for m, term in enumerate(terms):
                values[:, first + m] = np.maximum(outside, term)
            if not gradients:
                continue
            along = np.einsum('i,nij->nj', port.axis, jac)                  # ds/dq
            across = np.einsum('i,nij->nj', port.normal, jac)               # dy/dq
            d_outside = (side[:, None] * across - along) / np.sqrt(2.0)
            if radius > 0.0:
                d_tip = (s[:, None] * along + y[:, None] * across) / \
                    np.maximum(tip, 1e-12)[:, None]
                d_outside = np.where(in_disc[:, None], d_tip, d_outside)
            turning = np.full_like(across, scale)                            # d(R dh)/dq
            for m, (term, d_term) in enumerate(zip(terms, (-across, across, -turning,
                                                           turning))):
                grad[:, first + m] = np.where((outside >= term)[:, None], d_outside, d_term)
        # A configuration that is not finite is nowhere: as in the clearance model.
        finite = np.isfinite(q).all(axis=1)
        values[~finite] = -np.inf
        if gradients:
            grad[~finite] = 0.0
        return values, grad


class PortedModel:
    """
    A cell's clearance model with its port margins as further bodies: what a motion keeps > 0.

    ``body_clearance`` is the clearance model's (links, wafer) then the port margins
    (``PortModel``), with ``lipschitz`` the rows of both: the proof, and the whole-curve
    optimiser's clearance rows, hold a curve to the port rules as they hold it clear of the
    walls; so do the roadmap's nodes and edges and the corridor's boxes and segments (a
    box near a port is sized by how far the wafer is from entering it).
    """

    def __init__(self, clearance_model, port_model: PortModel, body_lipschitz: np.ndarray):
        """Join a clearance model (bodies' Lipschitz rows ``body_lipschitz``) and a port model."""
        self.clearance_model, self.port_model = clearance_model, port_model
        self._body_lipschitz = body_lipschitz
        self.lipschitz = np.vstack([body_lipschitz, port_model.lipschitz])
        self.body_names = tuple(clearance_model.body_names) + port_model.names
        self.bodies = clearance_model.body_count
        """The first this many columns are the robot's bodies; the rest port margins."""
        self.body_count = self.bodies + len(port_model)
        self.tolerances = port_model.tolerances
        """(4P,) m: the largest value of each port margin."""

    def keeping_out(self, radius: float, ends: np.ndarray) -> 'PortedModel':
        """Return this model with ``PortModel.keeping_out``'s margins (itself if no disc)."""
        kept = self.port_model.keeping_out(radius, ends)
        if not np.any(kept.keep_out > 0.0):
            return self  # no port but the curve's own: the rule alone
        return PortedModel(self.clearance_model, kept, self._body_lipschitz)

    def body_clearance(self, q: np.ndarray) -> np.ndarray:
        """Return every body's clearance then every port margin (N, 4 + 4P), in m."""
        q = np.atleast_2d(np.asarray(q, float))
        bodies = self.clearance_model.body_clearance(q)
        if not len(self.port_model):
            return bodies
        return np.concatenate([bodies, self.port_model.margins(q)], axis=1)

    def body_clearance_gradient(self, q: np.ndarray) -> tuple:
        """Return ``body_clearance`` and its gradient by q (N, 4 + 4P, 3)."""
        q = np.atleast_2d(np.asarray(q, float))
        bodies, gradient = self.clearance_model.body_clearance_gradient(q)
        if not len(self.port_model):
            return bodies, gradient
        margins, by_q = self.port_model.margins_gradient(q)
        return (np.concatenate([bodies, margins], axis=1),
                np.concatenate([gradient, by_q], axis=1))

    def clearance(self, q: np.ndarray) -> np.ndarray:
        """Return the smallest of ``body_clearance`` per configuration (N,)."""
        return self.body_clearance(q).min(axis=-1)


def _wrapped(angle) -> np.ndarray:
    """Return angles wrapped into (-pi, pi]."""
    return -((np.pi - np.asarray(angle, float)) % (2.0 * np.pi) - np.pi)


def describe_deviation(model: PortModel, q: np.ndarray) -> Optional[str]:
    """Return how a configuration breaks a port's tolerances, or None if it does not."""
    where, offset, turn = model.deviation(q)
    k = int(where[0])
    if k < 0:
        return None
    port = model.ports[k]
    problems = []
    if not offset[0] <= port.lateral_tolerance:
        problems.append(f'{offset[0] * 1000:.2f} mm off its axis (tolerance '
                        f'{port.lateral_tolerance * 1000:.2f} mm)')
    if not turn[0] <= port.heading_tolerance:
        problems.append(f'turned {np.degrees(turn[0]):.2f} deg from its heading (tolerance '
                        f'{np.degrees(port.heading_tolerance):.2f} deg)')
    if not problems:
        return None
    return f'the wafer is inside the port of {port.station} ' + ' and '.join(problems)
