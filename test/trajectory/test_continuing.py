"""A curve that continues a motion: its start is the moving robot's state, exactly."""

import numpy as np
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.continuing import Continuing, draft, pinned_start
from wafer_planner_ros.trajectory.curve import Trajectory


def _moving_curve(rng) -> CubicBSpline:
    """Return a cubic that starts in motion (its first three control points apart)."""
    points = np.cumsum(rng.uniform(-0.3, 0.3, (9, 3)), axis=0)
    points[-3:] = points[-3]
    return CubicBSpline.from_intervals(points, rng.uniform(0.05, 0.3, 6))


def test_a_pinned_start_sets_the_velocity_and_acceleration_whatever_the_spans():
    rng = np.random.default_rng(3)
    for _ in range(20):
        q, qd, qdd = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3), rng.uniform(-9, 9, 3)
        end = pinned_start(qd, qdd)
        v, a = end.pinned
        assert end.clipped(0.0, -end.braking) == (v, a) == end.clipped(np.inf, 0.0)
        h1, h2 = rng.uniform(0.005, 0.5, 2)
        p1, p2, _ = end.points(q, h1, h2, v, a)
        points = np.vstack([q, p1, p2, np.repeat(rng.uniform(-1, 1, (1, 3)), 3, axis=0)])
        curve = Continuing.from_intervals(points, np.array([h1, h2, 0.3]))
        _, v0, a0 = (x[0] for x in curve.evaluate_orders([0.0], range(3)))
        assert np.abs(v0 - qd).max() <= 1e-12 * max(1.0, np.abs(qd).max())
        assert np.abs(a0 - qdd).max() <= 1e-9
    assert pinned_start(np.zeros(3), np.ones(3)) is None  # at rest: nothing to pin


def test_a_draft_starts_in_the_state_and_ends_at_rest_near_the_curve_it_fits():
    rng = np.random.default_rng(5)
    curve = _moving_curve(rng)
    q, qd, qdd = (x[0] for x in curve.evaluate_orders([0.0], range(3)))
    fitted = draft(curve, qd, qdd, np.full(12, curve.duration / 12))
    (q0, q1), (v0, v1), (a0, a1) = fitted.evaluate_orders([0.0, fitted.duration], range(3))
    assert np.array_equal(q0, q) and np.array_equal(q1, curve.evaluate([curve.duration])[0])
    assert np.abs(v0 - qd).max() <= 1e-9 and np.abs(a0 - qdd).max() <= 1e-9
    assert np.abs(np.concatenate([v1, a1])).max() <= 1e-9
    t = np.linspace(0.0, curve.duration, 101)
    assert np.abs(fitted.evaluate(t) - curve.evaluate(t)).max() < 0.05


def test_only_a_continuing_curve_may_start_in_motion_and_it_must_end_at_rest():
    curve = _moving_curve(np.random.default_rng(7))
    points = curve.control_points
    start, goal = points[0], points[-1]
    assert 'does not start at rest' in curve.ill_formed(start, goal)
    moving = Continuing(curve.knots, points)
    assert moving.ill_formed(start, goal) is None
    assert 'not the start' in moving.ill_formed(start + 1e-9, goal)
    stopped_late = points.copy()
    stopped_late[-2] += 1e-6
    assert 'does not end at rest' in Continuing(curve.knots, stopped_late).ill_formed(
        start, goal)
    # Written and read back as its own kind.
    again = Trajectory.from_description(moving.describe())
    assert type(again) is Continuing and again.ill_formed(start, goal) is None
    assert np.array_equal(again.control_points, points)
