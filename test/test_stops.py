"""A motion that stops on its way: legs joined into one curve, at rest where they meet."""

import numpy as np
import pytest
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.trajectory.bspline import DEGREE
from wafer_planner_ros.trajectory.stops import joined_points, stopping_curve
from wafer_planner_ros.trajectory.verify import verify


def test_the_pose_where_two_legs_meet_stands_three_times():
    a = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 0, 0]], float)
    b = np.array([[2, 0, 0], [2, 0, 0], [2, 0, 0], [2, 0, 0], [3, 1, 0], [4, 1, 0],
                  [4, 1, 0]], float)
    points = joined_points([a, b])
    assert points.tolist() == [[0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 0, 0],
                               [2, 0, 0], [3, 1, 0], [4, 1, 0], [4, 1, 0]]


def test_legs_that_do_not_meet_are_refused():
    a = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]], float)
    b = np.array([[1, 0, 1e-9], [1, 0, 1e-9], [2, 0, 0], [2, 0, 0]], float)
    with pytest.raises(ValueError, match='leg 1 starts at'):
        joined_points([a, b])


def test_the_joined_curve_stops_where_the_legs_meet_and_meets_every_limit(
        default_cell, default_roadmap):
    planner = Planner(default_cell, default_roadmap)
    there = planner.plan('loadport1', 'loadlock1', branches=(1, 1))
    back = planner.plan('loadlock1', 'loadport2', branches=(1, 1))
    curve = stopping_curve([there.trajectory, back.trajectory], default_cell.robot,
                           planner.settings.timing)
    checked = verify(curve, default_cell, there.start_q, back.goal_q)
    assert checked.ok, checked.problems
    # The knot where the three copies of the pose act alone: at rest, no acceleration.
    points = curve.control_points
    m = next(k for k in range(len(points) - 2)
             if np.array_equal(points[k], there.goal_q)
             and np.array_equal(points[k + 2], there.goal_q))
    q, qd, qdd = curve.evaluate_orders(curve.knots[m + DEGREE])
    assert np.allclose(q[0], there.goal_q, atol=1e-12)
    assert np.abs(qd).max() < 1e-9 and np.abs(qdd).max() < 1e-6
    # No longer than the two legs one after the other: its timing starts from theirs.
    assert curve.duration <= 1.001 * (there.cycle_time + back.cycle_time)
