"""The gradient of each body's clearance with respect to the joint angles."""

import numpy as np

from wafer_planner_ros.geometry.clearance import ClearanceModel
from wafer_planner_ros.geometry.planar import point_segment_distance

STEP = 1e-7
"""Central finite-difference step (rad)."""
TIE = 1e-6
"""Two edges nearer than this (m) to a body are a tie: its gradient is one-sided there."""


def _random_q(cell, count, seed):
    limits = cell.robot.limits.position
    return np.random.default_rng(seed).uniform(limits[:, 0], limits[:, 1], (count, 3))


def _free(model, q):
    return q[(model.body_clearance(q) > 0.0).all(axis=1)]


def _model(cell, margin):
    robot = cell.robot
    return ClearanceModel(robot.arm, robot.body_radii, robot.body_names, cell.boundary,
                          cell.obstacles, margin=margin)


def _edge_vertices(model):
    """Return the vertex indices (into model.vertices) of each edge's two ends, (E, 2)."""
    ends, offset = [], 0
    for polygon in model.polygons:
        n = len(polygon)
        ends.append(offset + np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1))
        offset += n
    return np.concatenate(ends)


def _nearest_edges(model, q):
    """
    Return the edges that hold each body's nearest point, (N, 4, E), and where it is unique.

    The nearest point is unique (the gradient defined) where one edge is nearest by more
    than TIE, or where every edge within TIE of the nearest shares one polygon vertex, the
    nearest point itself: the distance to a corner is smooth though two edges tie at it.
    """
    distances = model.edge_distances(q)
    nearest = distances.min(axis=-1, keepdims=True)
    close = distances <= nearest + TIE
    points = model.arm.joint_points(q)
    a, b = points[:, [0, 1, 2, 3]], points[:, [1, 2, 3, 3]]  # the spines; the wafer's a point
    ab = b - a
    to_vertex = point_segment_distance(model.vertices[None, None], a[:, :, None],
                                       ab[:, :, None], np.sum(ab * ab, axis=-1)[:, :, None])
    corner = to_vertex <= nearest + 1e-12  # (N, 4, V): the vertices at the nearest distance
    ends = _edge_vertices(model)
    at_corner = corner[..., ends[:, 0]] | corner[..., ends[:, 1]]  # (N, 4, E)
    one_corner = (corner.sum(axis=-1) == 1) & ~(close & ~at_corner).any(axis=-1)
    return close, (close.sum(axis=-1) == 1) | one_corner


def test_clearance_equals_body_clearance_exactly(cell):
    model = cell.clearance_model
    q = _random_q(cell, 4000, seed=21)
    q[:3] = [[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.0, 0.0, -np.inf]]
    clearance, gradient = model.body_clearance_gradient(q)
    expected = model.body_clearance(q)
    assert clearance.tobytes() == expected.tobytes()
    assert clearance.shape == (len(q), 4) and gradient.shape == (len(q), 4, 3)
    # Collisions and free configurations both occur in numbers.
    assert 0.1 < (expected.min(axis=1) <= 0.0).mean() < 0.9
    # Not finite: nowhere, no gradient.
    assert np.all(clearance[:3] == -np.inf) and np.all(gradient[:3] == 0.0)
    single, single_gradient = model.body_clearance_gradient(q[5])
    assert single.tobytes() == model.body_clearance(q[5]).tobytes()
    assert np.array_equal(single_gradient, gradient[5:6])


def test_joints_beyond_a_body_do_not_move_it(cell):
    _, gradient = cell.clearance_model.body_clearance_gradient(_random_q(cell, 2000, seed=22))
    assert np.all(gradient[:, 0, 1:] == 0.0)  # the shoulder link: only q1
    assert np.all(gradient[:, 1, 2] == 0.0)  # the elbow link: q1 and q2
    assert np.all(np.abs(gradient[:, 1:, 0]).max(axis=0) > 0.1)  # q1 moves every body


def test_gradient_matches_central_differences(cell):
    model = cell.clearance_model
    q = _free(model, _random_q(cell, 3000, seed=23))
    clearance, gradient = model.body_clearance_gradient(q)
    nearest, unique = _nearest_edges(model, q)
    finite_difference = np.empty_like(gradient)
    for i in range(3):
        step = np.zeros(3)
        step[i] = STEP
        for sign in (1.0, -1.0):
            # Skip a body whose nearest edge a step changes: the difference spans a kink.
            moved = model.edge_distances(q + sign * step).argmin(axis=-1)
            unique &= np.take_along_axis(nearest, moved[..., None], axis=-1)[..., 0]
        finite_difference[..., i] = (model.body_clearance(q + step)
                                     - model.body_clearance(q - step)) / (2.0 * STEP)
    checked = unique[..., None] & np.ones(3, bool)
    error = np.abs(finite_difference - gradient)
    allowed = 1e-5 * np.abs(gradient) + 1e-8
    bad = checked & (error > allowed)
    assert not bad.any(), (
        f'{bad.sum()} entries off, worst at q={q[np.nonzero(bad)[0][0]]}: '
        f'{error[bad].max():.3g} (gradient {gradient[bad][np.argmax(error[bad])]:.6g})')
    # Every body is checked at many configurations, and nearly all are.
    assert unique.sum(axis=0).min() >= 0.8 * len(q) and len(q) > 500


def test_gradient_at_a_corner(cell):
    # A body whose nearest point is an obstacle's corner or a reflex corner of the boundary:
    # the branch of an edge's vertex to a link. Such a corner exists in every cell but the
    # (convex, empty) default one, and there it is checked on its own.
    model = cell.clearance_model
    q = _free(model, _random_q(cell, 3000, seed=24))
    nearest, unique = _nearest_edges(model, q)
    at_corner = unique & (nearest.sum(axis=-1) == 2)
    edge = np.roll(cell.boundary, -1, axis=0) - cell.boundary
    following = np.roll(edge, -1, axis=0)
    turns = edge[:, 0] * following[:, 1] - edge[:, 1] * following[:, 0]
    if not cell.obstacles and np.all(turns > 0.0):
        assert not at_corner.any()
        return
    assert at_corner.any(axis=0).all() and at_corner.sum() >= 100
    rows, bodies = np.nonzero(at_corner)
    _, gradient = model.body_clearance_gradient(q[rows])
    for i in range(3):
        step = np.zeros(3)
        step[i] = STEP
        difference = (model.body_clearance(q[rows] + step)
                      - model.body_clearance(q[rows] - step)) / (2.0 * STEP)
        expected = gradient[np.arange(len(rows)), bodies, i]
        got = difference[np.arange(len(rows)), bodies]
        assert np.all(np.abs(got - expected) <= 1e-5 * np.abs(expected) + 1e-8)


def test_a_step_against_the_gradient_reduces_clearance_as_predicted(cell):
    model = cell.clearance_model
    q = _free(model, _random_q(cell, 2000, seed=25))
    distances = np.sort(model.edge_distances(q), axis=-1)
    clearance, gradient = model.body_clearance_gradient(q)
    size = 1e-4
    checked = 0
    for k in range(4):
        # Clear of ties by far more than the step moves any point, and a real slope.
        norm = np.linalg.norm(gradient[:, k], axis=-1)
        keep = (distances[:, k, 1] - distances[:, k, 0] > 1e-2) & (norm > 1e-2)
        direction = gradient[keep, k] / norm[keep, None]
        after = model.body_clearance(q[keep] - size * direction)[:, k]
        change, predicted = after - clearance[keep, k], -size * norm[keep]
        assert np.all(change < 0.0)
        assert np.all(np.abs(change - predicted) <= 0.01 * np.abs(predicted))
        # And joint by joint: a wrong sign or column shows here.
        for i in range(3):
            step = np.zeros(3)
            step[i] = size
            change = model.body_clearance(q[keep] + step)[:, k] - clearance[keep, k]
            assert np.all(np.abs(change - size * gradient[keep, k, i]) <= 0.01 * size * norm[keep])
        checked += keep.sum()
    assert checked > 1000


def test_gradient_of_known_poses(default_cell):
    model, arm = default_cell.clearance_model, default_cell.robot.arm
    # The shoulder link's far end nearest the wall at y = -0.45, swung 0.3 rad off -y (elbow
    # folded back): clearance 0.45 - 0.36 cos(0.3) - 0.06, rising with q1.
    q = np.array([-np.pi / 2 + 0.3, np.pi, 0.0])
    clearance, gradient = model.body_clearance_gradient(q)
    assert np.isclose(clearance[0, 0], 0.45 - 0.36 * np.cos(0.3) - 0.06)
    assert np.allclose(gradient[0, 0], [0.36 * np.sin(0.3), 0.0, 0.0], rtol=0, atol=1e-15)
    # The wafer 0.25 m below the top wall, nearer to it than to any other: the gradient is
    # minus the y row of the wafer-centre Jacobian.
    q = arm.inverse([0.3, 0.2], np.pi / 2 - 0.5, default_cell.robot.limits.position)[0].q
    clearance, gradient = model.body_clearance_gradient(q)
    assert np.isclose(clearance[0, 3], 0.45 - 0.2 - 0.15)
    assert np.allclose(gradient[0, 3], -arm.jacobian(q)[1], rtol=0, atol=1e-15)
    assert np.all(np.abs(gradient[0, 3]) > 0.05)


def test_crossing_an_edge_has_no_gradient(default_cell):
    # Arm straight down: the elbow link crosses the wall at y = -0.45 (distance zero).
    clearance, gradient = default_cell.clearance_model.body_clearance_gradient(
        [-np.pi / 2, 0.0, 0.0])
    assert clearance[0, 1] == -default_cell.clearance_model.radii[1]
    assert np.all(gradient[0, 1] == 0.0)


def test_margin_lowers_clearance_and_keeps_the_gradient(cell):
    q = _random_q(cell, 2000, seed=26)
    plain, grown = _model(cell, 0.0), _model(cell, 0.005)
    clearance, gradient = plain.body_clearance_gradient(q)
    grown_clearance, grown_gradient = grown.body_clearance_gradient(q)
    assert np.allclose(grown_clearance, clearance - 0.005, rtol=0.0, atol=1e-15)
    assert np.array_equal(grown_gradient, gradient)
    assert grown_clearance.tobytes() == grown.body_clearance(q).tobytes()
