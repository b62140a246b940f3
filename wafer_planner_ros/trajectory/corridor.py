"""
Safe corridor and control-point placement (paper sections 4.1-4.2).

Around each connecting point q_j of the path (its interior vertices), with clearance d_j,
the box ``|q'_i - q_j,i| <= SAFETY * d_j / (n c_i)`` (Eq. 3) holds only free configurations:
no point of the robot moves as far as d_j. **Beyond the paper**, the default box is sized
per body (``lipschitz.body_box_half_widths``): each body may move up to its own clearance,
which gives a larger box (rounder, faster corners) with the same guarantee; the paper's box
stays selectable. The adjacent path segments enter and leave the
box at the intersection points I_in, I_out (never past a segment's middle, so neighbouring
boxes never cross over).

Control points: three at the start and three at the goal (complete stops); at each
connecting point the paper's single points at q_j and midway between q_j and the
intersection points, and **beyond the paper** the intersection points themselves:
``I_in, (I_in + q_j)/2, q_j, (q_j + I_out)/2, I_out``. With them every four consecutive
control points lie either in one box or on one straight path segment, so by the strong
convex-hull property every span of the cubic curve lies in a safe box or on a certified
segment: the curve is collision-free for *any* knot times, which the time optimisation then
changes freely. (With the paper's points alone a span's hull can reach from one box across
to the next segment, outside both.)
"""

from dataclasses import dataclass

import numpy as np

from wafer_planner_ros.geometry.lipschitz import body_box_half_widths, box_half_widths

SAFETY = 0.999
"""Boxes are shrunk by this factor so that their corners are strictly inside the clearance."""


@dataclass(frozen=True, eq=False)
class Corridor:
    """Boxes around the connecting points and the control points placed in them."""

    path: np.ndarray
    """(P, 3) path vertices: start, connecting points, goal."""
    half_widths: np.ndarray
    """(P - 2, 3) box half-widths at the connecting points (rad)."""
    entries: np.ndarray
    """(P - 2, 3) where the incoming segment enters each box."""
    exits: np.ndarray
    """(P - 2, 3) where the outgoing segment leaves each box."""
    control_points: np.ndarray
    """(6 + 5 (P - 2), 3)."""


def simplify(path: np.ndarray) -> np.ndarray:
    """Return the path without repeated consecutive vertices."""
    keep = np.ones(len(path), dtype=bool)
    keep[1:] = np.any(path[1:] != path[:-1], axis=1)
    return path[keep]


def build_corridor(path: np.ndarray, body_clearances: np.ndarray, constants: np.ndarray,
                   per_body: bool = True, extra: int = 1) -> Corridor:
    """
    Return the corridor of a path.

    ``body_clearances``: each body's clearance (m) at each path vertex, (P, B) (only
    interior vertices are used); ``constants``: the per-body Lipschitz constants C (B, 3).
    ``per_body=False`` gives the paper's boxes (Eq. 3 with c_i = max_k C[k, i]).
    ``extra`` evenly spaced control points are added on every straight stretch between
    boxes (and from the start and to the goal): they lie on the certified segment, so the
    proof stands, and the timing gets more knots to shape the speed along long stretches.
    """
    path = np.asarray(path, float)
    inner = path[1:-1]
    if per_body:
        half = [body_box_half_widths(SAFETY * d, constants) for d in body_clearances[1:-1]]
    else:
        c = np.asarray(constants).max(axis=0)
        half = [box_half_widths(SAFETY * d.min(), c) for d in body_clearances[1:-1]]
    half = np.array(half).reshape(len(inner), 3)
    entries = _box_exit(inner, path[:-2], half)
    exits = _box_exit(inner, path[2:], half)
    points = [path[:1]] * 3
    stretch_from = path[0]
    fractions = np.arange(1, extra + 1)[:, None] / (extra + 1)
    for q, entry, leave in zip(inner, entries, exits):
        points.append(stretch_from + fractions * (entry - stretch_from))
        points.append(np.stack([entry, 0.5 * (entry + q), q, 0.5 * (q + leave), leave]))
        stretch_from = leave
    points.append(stretch_from + fractions * (path[-1] - stretch_from))
    points += [path[-1:]] * 3
    return Corridor(path=path, half_widths=half, entries=entries, exits=exits,
                    control_points=np.concatenate(points))


def _box_exit(centre: np.ndarray, towards: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Return where the segment from each box centre towards a neighbour leaves the box."""
    direction = towards - centre
    with np.errstate(divide='ignore'):
        reach = np.where(direction != 0.0, half / np.abs(direction), np.inf).min(axis=1)
    return centre + np.minimum(reach, 0.5)[:, None] * direction
