"""
An independent check of a planned trajectory, sharing no code with the planner's own.

The spline is evaluated by scipy's BSpline from the knots and control points as exported;
the wafer acceleration comes from second differences of forward-kinematics positions and
the jerk from first differences of the acceleration (weighted averages of the true values,
so never above their peaks); collisions are checked
by python-fcl at configurations no more than 1 mrad apart in any joint; the port tolerances
(``port_ratios``) from the stations as written, at every step.
"""

import numpy as np
from scipy.interpolate import BSpline

STEP = 1e-4  # s, time step of the checks


def check(cell, plan: dict, start: np.ndarray, goal: np.ndarray) -> dict:
    """Assert everything a user relies on; return the measured ratios."""
    robot = cell.robot
    limits = robot.limit_sets[plan['load']]  # loaded: the wafer limit too; empty: not
    knots = np.array(plan['spline']['knots'])
    points = np.array(plan['spline']['control_points'])
    curve = BSpline(knots, points, 3)
    duration = knots[-1]
    assert np.isclose(duration, plan['cycle_time'], rtol=0, atol=1e-12)
    t = np.linspace(0.0, duration, int(np.ceil(duration / STEP)) + 1)
    q, qd, qdd = curve(t), curve(t, 1), curve(t, 2)
    # Start and goal exact; at rest at both ends.
    assert np.array_equal(points[0], start) and np.array_equal(points[-1], goal)
    assert np.allclose(q[[0, -1]], [start, goal], rtol=0, atol=1e-12)
    # scipy's recursion divides by spans as short as 1 ms: zero comes out as ~1e-9.
    assert np.abs(qd[[0, -1]]).max() < 1e-6 and np.abs(qdd[[0, -1]]).max() < 1e-6
    # Joint limits.
    lower, upper = limits.joints.position.T
    assert np.all(q >= lower) and np.all(q <= upper)
    ratios = {'velocity': float(np.max(np.abs(qd) / limits.joints.velocity)),
              'acceleration': float(np.max(np.abs(qdd) / limits.joints.acceleration))}
    if limits.joints.jerk is not None:
        # Differences of the acceleration: averages of the jerk, never above its peak.
        jerk = np.diff(qdd, axis=0) / np.diff(t)[:, None]
        ratios['jerk'] = float(np.max(np.abs(jerk) / limits.joints.jerk))
    # Wafer acceleration from positions only.
    h = 1e-4
    inner = t[(t > h) & (t < duration - h)]
    centre = [_wafer_centre(robot, curve(inner + s)) for s in (-h, 0.0, h)]
    wafer = (centre[0] - 2 * centre[1] + centre[2]) / h ** 2
    if limits.wafer is not None:
        ratios['wafer'] = float(np.max(np.abs(wafer) / limits.wafer.xy))
    if limits.wafer is not None and limits.wafer.norm is not None:
        ratios['wafer_norm'] = float(np.max(np.hypot(*wafer.T)) / limits.wafer.norm)
    ratios.update(port_ratios(cell, q))
    for name, ratio in ratios.items():
        assert ratio <= 1.0 + 1e-6, f'{name} reaches {ratio} x its limit'
    # Collisions: consecutive checks at most 1 mrad apart.
    assert np.abs(np.diff(q, axis=0)).max() <= 1e-3
    # The wafer disc, or empty the end effector's envelope (the cell file's radius).
    assert not cell.with_load(plan['load']).fcl_model().in_collision_many(q).any()
    # The samples are the spline's.
    samples = plan['points']
    ts = np.array([p['t'] for p in samples])
    assert ts[0] == 0.0 and ts[-1] == duration and np.all(np.diff(ts) > 0)
    for key, order, tolerance in (('q', 0, 1e-9), ('qd', 1, 1e-8), ('qdd', 2, 1e-6)):
        assert np.allclose([p[key] for p in samples], curve(ts, order), rtol=0,
                           atol=tolerance), key
    assert np.array_equal(samples[-1]['q'], goal)
    return ratios


def port_ratios(cell, q: np.ndarray) -> dict:
    """
    Return the largest offset from a port's axis and turn from its heading over tolerance.

    Over the configurations ``q`` whose wafer is inside a port: its centre past the
    retracted pose along the heading by more than its offset from the axis. From the
    station as written in the cell file; 0 when the wafer enters no port.
    """
    robot = cell.robot
    centre, heading = _wafer_centre(robot, q), np.sum(q, axis=-1)
    lateral = turned = 0.0
    for station in cell.stations.values():
        port = station.spec.get('port')
        if port is None:
            continue
        if 'joints' in station.spec:
            joints = np.array(station.spec['joints'])
            mouth, towards = _wafer_centre(robot, joints), float(np.sum(joints))
        else:
            mouth, towards = np.array(station.spec['wafer_center']), station.spec['heading']
        axis = np.array([np.cos(towards), np.sin(towards)])
        past = (centre - mouth) @ axis
        off = (centre - mouth) @ np.array([-axis[1], axis[0]])
        inside = past > np.abs(off)
        if inside.any():
            turn = np.angle(np.exp(1j * (heading[inside] - towards)))
            lateral = max(lateral, np.abs(off[inside]).max() / port['lateral_tolerance'])
            turned = max(turned, np.abs(turn).max() / port['heading_tolerance'])
    return {'port_lateral': float(lateral), 'port_heading': float(turned)}


def _wafer_centre(robot, q):
    """Return the wafer centre by summing the links: no planner code involved."""
    theta = np.cumsum(q, axis=-1)
    lengths = robot.link_lengths
    return robot.base + np.stack([(lengths * np.cos(theta)).sum(-1),
                                  (lengths * np.sin(theta)).sum(-1)], axis=-1)
