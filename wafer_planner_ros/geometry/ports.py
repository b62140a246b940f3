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

from wafer_planner_ros.kernels import kernel

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
        self._frames = np.array([[*p.retracted, *p.axis, *p.normal, p.heading,
                                  p.lateral_tolerance, p.heading_tolerance, p.heading_scale]
                                 for p in self.ports], float).reshape(-1, 10)
        """(P, 10): each port as ``_port_margins`` takes it."""

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
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, float)).reshape(-1, 3))
        values = np.empty((len(q), len(self)))
        grad = np.zeros((len(q), len(self), 3) if gradients else (0, 0, 3))
        if self.ports:
            _port_margins(q, np.asarray(self.arm.base, float),
                          np.asarray(self.arm.link_lengths, float), self._frames,
                          self.keep_out, gradients, values, grad)
        return values, (grad if gradients else None)


@kernel(nogil=True)
def _port_margins(q, base, lengths, frames, keep_out, gradients, values, grad):
    """
    Write each configuration's port margins (``PortModel.margins``) and their gradient.

    ``frames`` (P, 10): per port its retracted wafer centre (2), axis (2), normal (2),
    heading, lateral and heading tolerances and R; ``keep_out`` (P,): the disc radii.
    Writes ``values`` (N, 4P) and, with ``gradients``, ``grad`` (N, 4P, 3), zero on entry:
    of each max the larger term's gradient (the outside term where they tie; of |y| in it
    the one on the positive side at zero). A configuration that is not finite is nowhere,
    as in the clearance model: -inf, no gradient.
    """
    root2 = np.sqrt(2.0)
    l1, l2, l3 = lengths[0], lengths[1], lengths[2]
    across = np.empty(3)
    along = np.empty(3)
    d_outside = np.empty(3)
    for n in range(len(q)):
        t1 = q[n, 0]
        t2 = t1 + q[n, 1]
        t3 = t2 + q[n, 2]
        if not (np.isfinite(q[n, 0]) and np.isfinite(q[n, 1]) and np.isfinite(q[n, 2])):
            values[n, :] = -np.inf
            continue
        x1, x2, x3 = l1 * np.cos(t1), l2 * np.cos(t2), l3 * np.cos(t3)
        y1, y2, y3 = l1 * np.sin(t1), l2 * np.sin(t2), l3 * np.sin(t3)
        cx = base[0] + ((x1 + x2) + x3)
        cy = base[1] + ((y1 + y2) + y3)
        # d(centre)/dq: column i sums the links i..2, all turned by joint i
        jx = (-(y3 + y2 + y1), -(y3 + y2), -y3)
        jy = (x3 + x2 + x1, x3 + x2, x3)
        for k in range(len(frames)):
            rx, ry, ux, uy, nx, ny = frames[k, 0], frames[k, 1], frames[k, 2], \
                frames[k, 3], frames[k, 4], frames[k, 5]
            heading, tol, turn_tol, scale = frames[k, 6], frames[k, 7], frames[k, 8], \
                frames[k, 9]
            dx, dy = cx - rx, cy - ry
            s = dx * ux + dy * uy
            y = dx * nx + dy * ny
            dh = -((np.pi - (t3 - heading)) % (2.0 * np.pi) - np.pi)
            outside = (abs(y) - s) / root2
            radius = keep_out[k]
            tip = 1.0
            in_disc = False
            if radius > 0.0:
                tip = np.hypot(s, y)
                in_disc = tip - radius < outside
                outside = min(outside, tip - radius)
            first = 4 * k
            terms = (tol - y, tol + y, scale * (turn_tol - dh), scale * (turn_tol + dh))
            for m in range(4):
                values[n, first + m] = max(outside, terms[m])
            if not gradients:
                continue
            side = 1.0 if y >= 0.0 else -1.0
            for i in range(3):
                along[i] = ux * jx[i] + uy * jy[i]      # ds/dq
                across[i] = nx * jx[i] + ny * jy[i]     # dy/dq
                if in_disc:
                    d_outside[i] = (s * along[i] + y * across[i]) / max(tip, 1e-12)
                else:
                    d_outside[i] = (side * across[i] - along[i]) / root2
            for m in range(4):
                for i in range(3):
                    if outside >= terms[m]:
                        grad[n, first + m, i] = d_outside[i]
                    elif m == 0:
                        grad[n, first + m, i] = -across[i]
                    elif m == 1:
                        grad[n, first + m, i] = across[i]
                    elif m == 2:
                        grad[n, first + m, i] = -scale
                    else:
                        grad[n, first + m, i] = scale


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
