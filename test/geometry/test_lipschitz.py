"""Lipschitz constants: no point of the robot moves more than sum_i c_i |dq_i| (Eq. 2)."""

import numpy as np

from wafer_planner_ros.geometry.lipschitz import box_half_widths, joint_constants


def _body_points(robot, q, rng, per_body=64):
    """Return random points on (and inside) every body at q, fixed in the body's frame."""
    points = robot.arm.joint_points(q)
    angles = robot.arm.absolute_angles(q)
    out = []
    for k, radius in enumerate(robot.body_radii):
        a = points[..., k, :]
        b = points[..., min(k + 1, 3), :]
        along = rng.random(per_body)[:, None, None] if k < 3 else np.zeros((per_body, 1, 1))
        # Offsets rotate with the body: fixed in its frame, so the same material point.
        r = radius * np.sqrt(rng.random(per_body))[:, None]
        phi = rng.uniform(0, 2 * np.pi, per_body)[:, None]
        heading = angles[..., min(k, 2)]
        offset = np.stack([r * np.cos(phi + heading), r * np.sin(phi + heading)], axis=-1)
        out.append((a + along * (b - a) + offset, (along, r, phi)))
    return out


def _same_points(robot, q, draws):
    points = robot.arm.joint_points(q)
    angles = robot.arm.absolute_angles(q)
    out = []
    for k, (along, r, phi) in enumerate(draws):
        a, b = points[..., k, :], points[..., min(k + 1, 3), :]
        heading = angles[..., min(k, 2)]
        offset = np.stack([r * np.cos(phi + heading), r * np.sin(phi + heading)], axis=-1)
        out.append(a + along * (b - a) + offset)
    return out


def test_no_point_moves_more_than_the_lipschitz_bound(cell):
    robot = cell.robot
    rng = np.random.default_rng(21)
    limits = robot.limits.position
    q = rng.uniform(limits[:, 0], limits[:, 1], (400, 3))
    scale = rng.choice([1e-3, 0.05, 0.5, 3.0], size=(400, 1))
    q2 = np.clip(q + scale * rng.normal(size=(400, 3)), limits[:, 0], limits[:, 1])
    paper = joint_constants(robot.link_lengths, robot.body_radii)
    worst = 0.0
    samples = _body_points(robot, q, rng)
    after = _same_points(robot, q2, [draws for _, draws in samples])
    dq = np.abs(q2 - q)
    for k, ((before, _), moved_to) in enumerate(zip(samples, after)):
        moved = np.linalg.norm(moved_to - before, axis=-1)       # (per_body, N)
        body_bound = dq @ robot.lipschitz[k]
        assert np.all(moved <= body_bound + 1e-12), f'body {k}'
        assert np.all(moved <= dq @ paper + 1e-12)
        worst = max(worst, float(np.max(moved / np.maximum(body_bound, 1e-15))))
    # The bound is not vacuous: some points move close to it.
    assert worst > 0.9


def test_constants_of_the_default_arm(default_cell):
    c = joint_constants(default_cell.robot.link_lengths, default_cell.robot.body_radii)
    # Wafer edge: 0.36 + 0.36 + 0.22 + 0.15 from the shoulder, and so on down the chain.
    assert np.allclose(c, [1.09, 0.73, 0.37])


def test_box_of_eq_3_keeps_every_point_within_the_clearance(default_cell):
    robot = default_cell.robot
    c = joint_constants(robot.link_lengths, robot.body_radii)
    d = 0.05
    half = box_half_widths(d, c)
    assert np.allclose(half, d / (3 * c))
    rng = np.random.default_rng(22)
    q = rng.uniform(-3, 3, (200, 3))
    q2 = q + rng.uniform(-1, 1, (200, 3)) * half
    samples = _body_points(robot, q, rng)
    after = _same_points(robot, q2, [draws for _, draws in samples])
    for (before, _), moved_to in zip(samples, after):
        assert np.all(np.linalg.norm(moved_to - before, axis=-1) < d)
