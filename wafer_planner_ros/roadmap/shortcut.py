"""
Certified shortcuts of a roadmap path (beyond the paper).

A roadmap path zig-zags, and every corner costs time: the spline must turn inside the
corner's small safe box. Every pair of path vertices is tried as a straight segment at once
(certified like roadmap edges), and the path keeps the fewest corners, then the shortest
joint-space length, among the certified segments (a shortest path over the vertices in
order).
"""

import numpy as np

from wafer_planner_ros.geometry.certify import certify_segments


def shortcut(path: np.ndarray, model, lipschitz: np.ndarray) -> np.ndarray:
    """Return the vertices of the shortened path (a subsequence of ``path``, same ends)."""
    n = len(path)
    if n <= 2:
        return path
    i, j = np.triu_indices(n, k=2)
    clearance = model.body_clearance(path)
    ok, _ = certify_segments(model, lipschitz, path[i], path[j], clearance[i], clearance[j])
    reach = np.zeros((n, n), dtype=bool)
    reach[i[ok], j[ok]] = True
    reach[np.arange(n - 1), np.arange(1, n)] = True  # the path's own segments
    # Fewest segments first, then length: dynamic programming over the ordered vertices.
    best = [(0, 0.0, -1)] + [(n + 1, np.inf, -1)] * (n - 1)
    for b in range(1, n):
        for a in np.nonzero(reach[:b, b])[0]:
            hops, length, _ = best[a]
            candidate = (hops + 1, length + float(np.linalg.norm(path[b] - path[a])), int(a))
            if candidate[:2] < best[b][:2]:
                best[b] = candidate
    keep = [n - 1]
    while keep[-1] != 0:
        keep.append(best[keep[-1]][2])
    return path[keep[::-1]]
