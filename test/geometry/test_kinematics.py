"""Forward and inverse kinematics, Jacobian and wafer-centre acceleration."""

import numpy as np
import pytest

from wafer_planner_ros.geometry.kinematics import wrap_into_limits


def test_joint_points_of_a_straight_and_a_folded_arm(default_cell):
    arm = default_cell.robot.arm
    assert np.allclose(arm.joint_points(np.zeros(3)),
                       [[0, 0], [0.36, 0], [0.72, 0], [0.94, 0]])
    folded = arm.joint_points(np.array([np.pi / 2, np.pi, np.pi / 2]))
    assert np.allclose(folded, [[0, 0], [0, 0.36], [0, 0], [0.22, 0]])
    assert np.isclose(arm.heading(np.array([0.1, 0.2, 0.3])), 0.6)


def test_jacobian_matches_finite_differences(cell):
    arm = cell.robot.arm
    rng = np.random.default_rng(3)
    q = rng.uniform(-3, 3, (50, 3))
    h = 1e-6
    numeric = np.stack([(arm.wafer_center(q + h * e) - arm.wafer_center(q - h * e)) / (2 * h)
                        for e in np.eye(3)], axis=-1)
    assert np.allclose(arm.jacobian(q), numeric, atol=1e-8)


def test_wafer_acceleration_matches_second_differences_of_positions(cell):
    arm = cell.robot.arm
    rng = np.random.default_rng(4)
    a, b, w = rng.uniform(-2, 2, (3, 3))

    def q_of(t):
        return a + b * np.sin(w * t[:, None])

    t = rng.uniform(0, 3, 40)
    qd = b * w * np.cos(w * t[:, None])
    qdd = -b * w ** 2 * np.sin(w * t[:, None])
    h = 1e-4
    numeric = (arm.wafer_center(q_of(t + h)) - 2 * arm.wafer_center(q_of(t))
               + arm.wafer_center(q_of(t - h))) / h ** 2
    assert np.allclose(arm.wafer_acceleration(q_of(t), qd, qdd), numeric, atol=1e-5)
    assert np.allclose(arm.wafer_velocity(q_of(t), qd),
                       (arm.wafer_center(q_of(t + h)) - arm.wafer_center(q_of(t - h))) / (2 * h),
                       atol=1e-6)


def test_wafer_jerk_matches_differences_of_the_acceleration(cell):
    arm = cell.robot.arm
    rng = np.random.default_rng(5)
    a, b, w = rng.uniform(-2, 2, (3, 3))
    t = rng.uniform(0, 3, 40)[:, None]

    def state(t):
        return (a + b * np.sin(w * t), b * w * np.cos(w * t), -b * w ** 2 * np.sin(w * t),
                -b * w ** 3 * np.cos(w * t))

    h = 1e-5
    numeric = (arm.wafer_acceleration(*state(t + h)[:3])
               - arm.wafer_acceleration(*state(t - h)[:3])) / (2 * h)
    jerk = arm.wafer_jerk(*state(t))
    assert jerk.shape == (40, 2)
    assert np.allclose(jerk, numeric, atol=1e-5)
    # One state alone, as (3,) arrays.
    assert np.allclose(arm.wafer_jerk(*(x[7] for x in state(t))), jerk[7])


def test_inverse_kinematics_returns_both_branches_that_reproduce_the_pose(cell):
    arm, limits = cell.robot.arm, cell.robot.limits.position
    rng = np.random.default_rng(5)
    both = 0
    for q in rng.uniform(limits[:, 0], limits[:, 1], (300, 3)):
        centre, heading = arm.wafer_center(q), arm.heading(q)
        solutions = arm.inverse(centre, heading, limits)
        assert any(np.allclose(s.q, q, atol=1e-9) for s in solutions)
        for s in solutions:
            assert np.allclose(arm.wafer_center(s.q), centre, atol=1e-9)
            assert np.isclose(np.cos(arm.heading(s.q) - heading), 1.0)
            assert np.all(s.q >= limits[:, 0]) and np.all(s.q <= limits[:, 1])
            assert np.sign(s.q[1]) == s.elbow
        both += len(solutions) == 2
    assert both > 200  # most poses have both elbow branches inside the limits


def test_inverse_kinematics_unreachable_pose_gives_nothing(default_cell):
    arm = default_cell.robot.arm
    assert arm.inverse([2.0, 0.0], 0.0, default_cell.robot.limits.position) == []


@pytest.mark.parametrize('q, limits, expected', [
    ([3.5, 0.0, -3.5], [[-np.pi, np.pi]] * 3, [3.5 - 2 * np.pi, 0.0, 2 * np.pi - 3.5]),
    ([6.0, 0.1, 0.2], [[-3.0, 3.0]] * 3, [6.0 - 2 * np.pi, 0.1, 0.2]),
    ([2.95, 0.0, 0.0], [[-2.9, 2.9]] * 3, None),
])
def test_wrap_into_limits(q, limits, expected):
    result = wrap_into_limits(np.array(q), np.array(limits))
    if expected is None:
        assert result is None
    else:
        assert np.allclose(result, expected)
