"""Independent dense re-check of joint-space segments with the python-fcl model."""

import numpy as np

STEP = 1e-3  # rad: no joint moves more than this between two checks
_BATCH = 200_000


def segment_points(qa: np.ndarray, qb: np.ndarray, step: float = STEP):
    """Yield (segment indices, configurations) covering every segment at <= step per joint."""
    counts = np.maximum(np.ceil(np.abs(qb - qa).max(axis=1) / step).astype(int), 1) + 1
    start = 0
    while start < len(qa):
        stop = start + max(1, int(np.searchsorted(np.cumsum(counts[start:]), _BATCH)))
        n = counts[start:stop]
        owner = np.repeat(np.arange(start, stop), n)
        offset = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        s = (offset / (n - 1).repeat(n))[:, None]
        yield owner, qa[owner] + s * (qb[owner] - qa[owner])
        start = stop


def colliding_segments(fcl_model, qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Return the indices of segments that fcl finds in collision anywhere (1 mrad steps)."""
    hits = []
    for owner, q in segment_points(np.atleast_2d(qa), np.atleast_2d(qb)):
        hits.append(np.unique(owner[fcl_model.in_collision_many(q)]))
    return np.unique(np.concatenate(hits)) if hits else np.empty(0, dtype=int)
