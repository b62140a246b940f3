"""
Certified straight-line motions in joint space, with no discretisation step.

Along a segment a -> b every point of body k moves at most ``L_k = C[k] . |b - a|`` from
where it was at a (and at b), C being the per-body Lipschitz constants. Body k is therefore
safe all along the segment when ``d_k(a) + d_k(b) > L_k``: for every fraction s either
``s L_k < d_k(a)`` or ``(1 - s) L_k < d_k(b)``. When some body's test fails the segment is
split at its midpoint and both halves are tested; a midpoint in collision rejects the
segment. A segment that would need to be split more than ``max_depth`` times (it grazes an
obstacle within nanometres) is rejected too, and so is one whose midpoint comes within
``CONTACT`` of an obstacle, or one with more than ``MAX_OPEN`` pieces still open at once: a
segment that touches an obstacle at a single point (a link whose reach equals a wall's
distance: its clearance 0 at one angle, growing with the square of the angle away from it)
is otherwise refuted only when a midpoint lands on that point to the last bit, and the
pieces near it, open all the while, double every other level (one study variant's roadmap
took minutes instead of a second: doc/how-it-works.md, "Certified edges"). The
answer errs only towards "not certified". All segments are processed together, one
vectorised clearance call per bisection level.
"""

import numpy as np

DEFAULT_MAX_DEPTH = 30
CONTACT = 1e-6
"""m: a midpoint this near an obstacle rejects its segment (as a collision does)."""
MAX_OPEN = 4096
"""Pieces of one segment open at one level beyond which the segment is rejected (above
what any edge of the packaged and test cells' roadmaps needs)."""


def certify_segments(model, lipschitz: np.ndarray, qa: np.ndarray, qb: np.ndarray,
                     da: np.ndarray, db: np.ndarray, max_depth: int = DEFAULT_MAX_DEPTH):
    """
    Return which segments qa[m] -> qb[m] are certified collision-free, and the evaluations.

    ``lipschitz``: per-body constants (B, 3); ``da``/``db``: per-body clearances (M, B) at the
    end points (from ``model.body_clearance``), which must be free. Returns ``(ok, count)``:
    a bool array (M,) and the number of clearance evaluations spent.
    """
    ok = np.ones(len(qa), dtype=bool)
    seg = np.arange(len(qa))
    evaluations = 0
    for depth in range(max_depth + 1):
        reach = np.abs(qb - qa) @ lipschitz.T                    # (m, B)
        open_ = ~np.all(da + db > reach, axis=1)
        seg, qa, qb, da, db = seg[open_], qa[open_], qb[open_], da[open_], db[open_]
        if depth == max_depth:
            ok[seg] = False
        if not len(seg) or depth == max_depth:
            break
        crowded = np.bincount(seg, minlength=len(ok)) > MAX_OPEN
        ok[crowded] = False
        alive = ok[seg]  # drop pieces of segments already rejected
        seg, qa, qb, da, db = seg[alive], qa[alive], qb[alive], da[alive], db[alive]
        qm = 0.5 * (qa + qb)
        dm = model.body_clearance(qm)
        evaluations += len(qm)
        hit = np.any(dm <= CONTACT, axis=1)
        ok[seg[hit]] = False
        free = ~hit
        seg, qa, qb, qm, da, db, dm = (
            seg[free], qa[free], qb[free], qm[free], da[free], db[free], dm[free])
        seg = np.concatenate([seg, seg])
        qa, qb = np.concatenate([qa, qm]), np.concatenate([qm, qb])
        da, db = np.concatenate([da, dm]), np.concatenate([dm, db])
    return ok, evaluations
