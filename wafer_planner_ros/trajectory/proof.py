"""
Proof that a timed curve is collision-free, with no sampling step.

On a piece [a, b] of the curve joint i moves no faster than V_i, its exact peak speed there
(``Trajectory.peak_speed``), so no point of body k moves farther than
``L_k = sum_i C[k, i] V_i (b - a)`` from where it was at a, or from where it is at b (C: the
per-body Lipschitz constants the roadmap uses). Body k is therefore clear all along the
piece when ``d_k(a) + d_k(b) > L_k``, d_k its clearance: at every instant it is closer in
time, scaled by L_k, to one end than that end's clearance. A piece whose test fails for
some body is split at its middle time and both halves are tested; a middle in collision
refutes the curve. A piece still open after ``max_depth`` splits (the curve grazes an
obstacle within nanometres) is left unproven: the answer errs only towards "not proven".
The model's bodies are grown by the cell's clearance margin, so a proof keeps the margin;
the cell's ``motion_model`` adds its port margins as bodies, so a proof in it also shows
that the wafer keeps every port's tolerances (``geometry.ports``).
The pieces cover all of [0, T] (``Trajectory.covering_breaks``), whatever the curve's own
breaks: whatever is evaluated there is proven. All pieces are tested together: one
vectorised clearance call per bisection level.
"""

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from wafer_planner_ros.trajectory.curve import Trajectory

DEFAULT_MAX_DEPTH = 30


@dataclass(frozen=True, eq=False)
class CurveProof:
    """The outcome of ``prove``."""

    certified: bool
    """Every piece of the curve is proven free."""
    pieces: int
    """Pieces proven free (the leaves of the bisection)."""
    depth: int
    """The most splits any proven piece needed."""
    evaluations: int
    """Configurations whose clearance was computed."""
    collision: Optional[float] = None
    """s: a time at which the curve is in collision (it refutes the curve), if one was met."""
    body: Optional[int] = None
    """The model's body (its column) found in collision then."""
    unproven: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    """(K, 2) start and end times of the pieces left unproven or refuted."""


def prove(trajectory: Trajectory, model, lipschitz: np.ndarray,
          max_depth: int = DEFAULT_MAX_DEPTH) -> CurveProof:
    """Prove ``trajectory`` free in ``model`` piece by piece (see the module's description)."""
    breaks = trajectory.covering_breaks()
    clearance = model.body_clearance(trajectory.evaluate(breaks))
    evaluations = len(breaks)
    a, b, da, db = breaks[:-1], breaks[1:], clearance[:-1], clearance[1:]
    hit = np.nonzero(np.any(clearance <= 0.0, axis=1))[0]
    if len(hit):
        return CurveProof(False, 0, 0, evaluations, float(breaks[hit[0]]),
                          _first(clearance[hit[0]]), np.stack([a, b], axis=1))
    pieces, depth = 0, 0
    for level in range(max_depth + 1):
        reach = (trajectory.peak_speed(a, b) * (b - a)[:, None]) @ lipschitz.T   # (K, B)
        # Written so that NaN stays open: every comparison with NaN is false.
        proven = np.all(da + db > reach, axis=1)
        if proven.any():
            pieces, depth = pieces + int(proven.sum()), level
        a, b, da, db = a[~proven], b[~proven], da[~proven], db[~proven]
        if not len(a) or level == max_depth:
            break
        middle = 0.5 * (a + b)
        dm = model.body_clearance(trajectory.evaluate(middle))
        evaluations += len(middle)
        hit = np.nonzero(np.any(dm <= 0.0, axis=1))[0]
        if len(hit):
            return CurveProof(False, pieces, depth, evaluations, float(middle[hit[0]]),
                              _first(dm[hit[0]]), np.stack([a[hit], b[hit]], axis=1))
        a, b = np.concatenate([a, middle]), np.concatenate([middle, b])
        da, db = np.concatenate([da, dm]), np.concatenate([dm, db])
    return CurveProof(not len(a), pieces, depth, evaluations, None, None,
                      np.stack([a, b], axis=1))


def _first(clearance: np.ndarray) -> int:
    """Return the first body whose clearance is not positive (NaN counts)."""
    return int(np.argmax(~(clearance > 0.0)))
