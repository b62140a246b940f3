"""
Lipschitz constants of the arm's bodies with respect to each joint (paper Eq. 1-3).

Turning joint i by dq moves a point at distance rho from that joint's axis by
2 rho sin(|dq|/2) <= rho |dq|. Every point of body k (link capsules, then the wafer disc)
lies within ``sum(link_lengths[i..k]) + radius_k`` of joint i when k is distal to i, and
does not move at all when k is proximal. Moving the joints one at a time and adding up gives
``|a(q) - a(q')| <= sum_i C[k, i] |q_i - q'_i|`` for every point a of body k (Eq. 2), with
``C`` from :func:`body_constants`; the paper's per-joint constant for the whole robot is
``c_i = max_k C[k, i]`` (:func:`joint_constants`).
"""

import numpy as np


def body_constants(link_lengths, body_radii) -> np.ndarray:
    """
    Return C (4, 3): the bound on body k's point displacement per radian of joint i (m/rad).

    Bodies are the three links then the wafer (whose spine ends at the wafer centre, the
    end of link 3), ``body_radii`` in the same order.
    """
    lengths = np.asarray(link_lengths, float)
    radii = np.asarray(body_radii, float)
    constants = np.zeros((4, 3))
    for body in range(4):
        last_link = min(body, 2)
        for joint in range(last_link + 1):
            constants[body, joint] = lengths[joint:last_link + 1].sum() + radii[body]
    return constants


def joint_constants(link_lengths, body_radii) -> np.ndarray:
    """Return the paper's c_i (3,): the largest body constant per joint (m/rad)."""
    return body_constants(link_lengths, body_radii).max(axis=0)


def box_half_widths(clearance: float, constants: np.ndarray) -> np.ndarray:
    """Return the safe box half-widths dq_i = d / (n c_i) around a configuration (Eq. 3)."""
    return clearance / (len(constants) * np.asarray(constants, float))


def body_box_half_widths(body_clearance: np.ndarray, constants: np.ndarray) -> np.ndarray:
    """
    Return safe box half-widths from per-body clearances d_k and constants C (B, 3).

    **Beyond** Eq. 3: dq_i = min over the bodies k that joint i moves of
    d_k / (n_k C[k, i]), n_k being the number of joints that move body k. Every body then
    moves less than its own clearance: sum_i C[k, i] dq_i <= sum_i d_k / n_k = d_k. Since
    d_k >= min_k d_k, n_k <= n and C[k, i] <= c_i, the box contains the paper's.
    """
    constants = np.asarray(constants, float)
    moved = constants > 0.0
    joints_per_body = moved.sum(axis=1, keepdims=True)
    with np.errstate(divide='ignore'):
        widths = np.where(moved, np.asarray(body_clearance, float)[:, None]
                          / (joints_per_body * constants), np.inf)
    return widths.min(axis=0)
