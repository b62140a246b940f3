"""
An independent check of a planned trajectory, sharing no code with the planner's own.

The spline is evaluated by scipy's BSpline from the knots and control points as exported;
a move through ports (kind ``through-ports``) by its parts: the transfer the same way, each
way through a port from its profile's jerks integrated here and the inverse kinematics of
the straight line solved here (law of cosines; derivatives from the Jacobian written here);
the wafer acceleration comes from second differences of forward-kinematics positions and
the jerk from first differences of the acceleration (weighted averages of the true values,
so never above their peaks); collisions are checked
by python-fcl at configurations no more than 1 mrad apart in any joint; the port tolerances
(``port_ratios``) from the stations as written, at every step.
"""

import numpy as np
from scipy.interpolate import BSpline

STEP = 1e-4  # s, time step of the checks


def check(cell, plan: dict, start: np.ndarray, goal: np.ndarray, moving=None) -> dict:
    """
    Assert everything a user relies on; return the measured ratios.

    ``moving``: the velocity and acceleration a curve that continues a motion (kind
    ``continuing-b-spline``) must start with; None: it starts at rest.
    """
    robot = cell.robot
    limits = robot.limit_sets[plan['load']]  # loaded: the wafer limit too; empty: not
    curve = _curve(plan['spline'])
    duration = curve.duration
    points = curve.ends
    assert np.isclose(duration, plan['cycle_time'], rtol=0, atol=1e-12)
    t = np.linspace(0.0, duration, int(np.ceil(duration / STEP)) + 1)
    q, qd, qdd = curve(t), curve(t, 1), curve(t, 2)
    # Start and goal exact; at rest at both ends.
    assert np.array_equal(points[0], start) and np.array_equal(points[-1], goal)
    assert np.allclose(q[[0, -1]], [start, goal], rtol=0, atol=1e-12)
    # scipy's recursion divides by spans as short as 1 ms: zero comes out as ~1e-9.
    begins = np.zeros((2, len(start))) if moving is None else np.asarray(moving, float)
    assert np.abs(qd[0] - begins[0]).max() < 1e-6 and np.abs(qd[-1]).max() < 1e-6
    assert np.abs(qdd[0] - begins[1]).max() < 1e-6 and np.abs(qdd[-1]).max() < 1e-6
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


def _curve(described: dict):
    """Return the exported curve as a callable curve(t, order) with duration and ends."""
    if described.get('kind', 'cubic-b-spline') in ('cubic-b-spline', 'continuing-b-spline'):
        return _Spline(described)
    assert described['kind'] == 'through-ports', described.get('kind')
    return _PortMove(described)


class _Spline:
    def __init__(self, described):
        knots = np.array(described['knots'])
        points = np.array(described['control_points'])
        self.spline, self.duration = BSpline(knots, points, 3), float(knots[-1])
        self.ends = points[[0, -1]]

    def __call__(self, t, order=0):
        return self.spline(np.clip(t, 0.0, self.duration), order)


class _Way:
    """sigma(t) from the profile's jerks alone, and q(sigma) by the law of cosines."""

    def __init__(self, described):
        profile, channel = described['profile'], described['channel']
        self.starts, self.jerks = np.array(profile['starts']), np.array(profile['jerks'])
        state = np.zeros(3)
        self.states = [state]
        for tau, j in zip(np.diff(self.starts), self.jerks):
            p, v, a = state
            state = np.array([p + v * tau + a * tau ** 2 / 2 + j * tau ** 3 / 6,
                              v + a * tau + j * tau ** 2 / 2, a + j * tau])
            self.states.append(state)
        self.states = np.array(self.states)
        self.duration = float(self.starts[-1])
        self.base, self.lengths = np.array(channel['base']), np.array(channel['link_lengths'])
        self.inside, self.mouth = np.array(channel['inside']), np.array(channel['mouth'])
        self.direction = np.array(channel['direction'])
        self.length = float(channel['length'])
        theta = np.cumsum(self.inside)
        self.centre = self.base + np.array([self.lengths @ np.cos(theta),
                                            self.lengths @ np.sin(theta)])
        self.heading = float(np.sum(self.inside))
        assert abs(self.states[-1, 0] - self.length) < 1e-9

    def sigma(self, t):
        t = np.clip(t, 0.0, self.duration)
        k = np.clip(np.searchsorted(self.starts, t, side='right') - 1, 0, len(self.jerks) - 1)
        tau, (p, v, a), j = t - self.starts[k], self.states[k].T, self.jerks[k]
        return (p + v * tau + a * tau ** 2 / 2 + j * tau ** 3 / 6,
                v + a * tau + j * tau ** 2 / 2, a + j * tau, j)

    def q(self, s):
        l1, l2, l3 = self.lengths
        centre = self.centre + s[:, None] * self.direction
        wrist = centre - l3 * np.array([np.cos(self.heading), np.sin(self.heading)])
        d = wrist - self.base
        q2 = np.sign(self.inside[1]) * np.arccos(
            (np.sum(d * d, axis=1) - l1 ** 2 - l2 ** 2) / (2 * l1 * l2))
        q1 = np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
        q = np.stack([q1, q2, self.heading - q1 - q2], axis=1)
        near = self.inside + (s / self.length)[:, None] * (self.mouth - self.inside)
        q += 2 * np.pi * np.round((near - q) / (2 * np.pi))
        q[s <= 0.0], q[s >= self.length] = self.inside, self.mouth
        return q

    def __call__(self, t, order):
        s, s1, s2, _ = self.sigma(t)
        q = self.q(s)
        if order == 0:
            return q
        # The wafer centre moves along the direction at speed s1, accelerating by s2, and
        # does not turn: J q' = d s1, sum q' = 0, and J q'' + (dJ/dt) q' = d s2.
        theta = np.cumsum(q, axis=1)
        c = np.cumsum((self.lengths * np.cos(theta))[:, ::-1], axis=1)[:, ::-1]
        n = np.cumsum((self.lengths * np.sin(theta))[:, ::-1], axis=1)[:, ::-1]
        full = np.stack([-n, c, np.ones_like(c)], axis=1)
        right = np.concatenate([self.direction * s1[:, None], np.zeros((len(s), 1))], axis=1)
        qd = np.linalg.solve(full, right[..., None])[..., 0]
        if order == 1:
            return qd
        w = np.cumsum(qd, axis=1)
        spin = self.lengths * w ** 2
        bend = -np.stack([(spin * np.cos(theta)).sum(1), (spin * np.sin(theta)).sum(1)], axis=1)
        right = np.concatenate([self.direction * s2[:, None] - bend, np.zeros((len(s), 1))],
                               axis=1)
        return np.linalg.solve(full, right[..., None])[..., 0]


class _PortMove:
    def __init__(self, described):
        self.transfer = _Spline(described['transfer'])
        self.out = None if described['out'] is None else _Way(described['out'])
        self.into = None if described['into'] is None else _Way(described['into'])
        self.first = 0.0 if self.out is None else self.out.duration
        self.last = self.first + self.transfer.duration
        self.duration = self.last + (0.0 if self.into is None else self.into.duration)
        self.ends = np.array([self(np.zeros(1))[0], self(np.array([self.duration]))[0]])

    def __call__(self, t, order=0):
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        out = np.empty((len(t), 3))
        first = (t <= self.first) if self.out is not None else np.zeros(len(t), bool)
        last = (t >= self.last) & ~first if self.into is not None else np.zeros(len(t), bool)
        middle = ~(first | last)
        if first.any():
            out[first] = self.out(t[first], order)
        if middle.any():
            out[middle] = self.transfer(t[middle] - self.first, order)
        if last.any():
            out[last] = self.into(self.duration - t[last], order) * (-1.0) ** order
        return out


def _wafer_centre(robot, q):
    """Return the wafer centre by summing the links: no planner code involved."""
    theta = np.cumsum(q, axis=-1)
    lengths = robot.link_lengths
    return robot.base + np.stack([(lengths * np.cos(theta)).sum(-1),
                                  (lengths * np.sin(theta)).sum(-1)], axis=-1)
