"""The straight way through a port, its timing, and a move of those parts: exact, sound."""

import numpy as np
import pytest
from wafer_planner_ros.cell.document import read_cell_file, read_cell_yaml
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.moves.channel import Channel, channel_bounds
from wafer_planner_ros.moves.through import PortMove
from wafer_planner_ros.moves.timing import Bounds, profile
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.study import parameters
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.verify import verify


def _channel(cell, station, k=0):
    found = cell.stations[station]
    inside = found.inside[k]
    mouth = {c.elbow: c.q for c in found.configs}[inside.elbow]
    return Channel.out_of(cell.robot.arm, inside.q, found.port.axis, found.port.depth,
                          mouth=mouth), found.port


def test_the_channel_keeps_the_wafer_on_the_axis_and_the_blade_on_its_heading(default_cell):
    channel, port = _channel(default_cell, 'loadport1')
    sigma = np.linspace(0.0, channel.length, 1001)
    q = channel.configurations(sigma)
    arm = default_cell.robot.arm
    s, y = port.offsets(arm.wafer_center(q))
    assert np.abs(y).max() < 1e-12
    assert np.abs(arm.heading(q) - port.heading).max() < 1e-12
    assert np.allclose(s, port.depth - sigma, rtol=0, atol=1e-12)
    assert np.array_equal(q[0], channel.inside) and np.array_equal(q[-1], channel.mouth)
    # Its derivatives by the distance are those of the configurations themselves.
    h = 1e-5
    middle = sigma[1:-1:50]
    _, g1, g2, _ = channel.derivatives(middle)
    ahead, behind = channel.configurations(middle + h), channel.configurations(middle - h)
    assert np.allclose((ahead - behind) / (2 * h), g1, rtol=0, atol=1e-6)
    assert np.allclose((ahead - 2 * channel.configurations(middle) + behind) / h ** 2, g2,
                       rtol=0, atol=1e-3)


def test_the_speed_bound_holds_on_every_interval(cell):
    for station in (n for n, s in cell.stations.items() if s.port is not None):
        channel, _ = _channel(cell, station)
        edges = np.linspace(0.0, channel.length, 41)
        bound = channel.speed_bound(edges[:-1], edges[1:])
        for k in range(40):
            fine = np.linspace(edges[k], edges[k + 1], 51)
            speed = np.abs(channel.derivatives(fine)[1]).max(axis=0)
            assert np.all(speed <= bound[k]), (station, k, speed, bound[k])


FOLDED = {'robot.link_lengths[0]': 0.3821606733715736, 'robot.link_lengths[1]': 0.3439991437295541,
          'stations.loadlock1.x': -0.509760669819198, 'stations.loadlock2.x': 0.527322104929983}
"""A layout a search tried: the arm 1.9 degrees from folded at loadport2's retracted pose."""


def test_an_arm_nearly_folded_at_a_port_mouth_stops_there_in_seconds_within_every_limit():
    document = parameters.apply(read_cell_yaml(read_cell_file(default_cell_path()), 'default'),
                                FOLDED)
    cell = Cell.from_dict(document)
    channel, _ = _channel(cell, 'loadport2')
    assert np.pi - abs(channel.mouth[1]) < np.radians(2.0)
    bounds = channel_bounds(channel, cell.robot)
    # Leaving at speed, the fold sets every bound on the whole way (27 s); a stop at the
    # mouth is slow only near it (it was refused: 37.7 s, over 30 s).
    stopping = profile(channel.length, 0.0, bounds.at(0.0, 0.0))
    moving = profile(channel.length, 0.0, bounds)
    assert stopping.duration < 10.0 and stopping.duration < 0.5 * moving.duration
    # Every joint limit and the wafer's along the way, every 0.1 ms: not the bounds'
    # argument, the motion itself.
    t = np.append(np.arange(0.0, stopping.duration, 1e-4), stopping.duration)
    sigma, speed, acceleration, jerk = stopping.evaluate(t).T
    _, g1, g2, g3 = channel.derivatives(np.clip(sigma, 0.0, channel.length))
    v, a, j = speed[:, None], acceleration[:, None], jerk[:, None]
    limits = cell.robot.limits
    assert np.all(np.abs(g1 * v) <= limits.velocity)
    assert np.all(np.abs(g2 * v ** 2 + g1 * a) <= limits.acceleration)
    assert np.all(np.abs(g3 * v ** 3 + 3.0 * g2 * v * a + g1 * j) <= limits.jerk)
    limit = cell.robot.wafer_limit
    assert np.all(np.abs(acceleration[:, None] * channel.direction) <= limit.xy)
    assert limit.norm is None or np.all(np.abs(acceleration) <= limit.norm)


def test_a_profile_starts_at_rest_and_ends_at_its_mouth_state_within_its_bounds():
    bounds = Bounds(speed=1.2, acceleration=0.9, jerk=20.0)
    reach = bounds.reach(0.35)
    for speed in (0.0, 0.3, reach):
        made = profile(0.35, speed, bounds)
        assert made.ill_formed() is None
        t = np.linspace(0.0, made.duration, 20001)
        s = made.evaluate(t)
        assert np.array_equal(s[0, :3], [0.0, 0.0, 0.0])
        assert np.array_equal(s[-1, :3], [0.35, speed, 0.0])
        assert s[:, 1].min() >= 0.0 and s[:, 1].max() <= bounds.speed
        assert np.abs(s[:, 2]).max() <= bounds.acceleration * (1 + 1e-12)
        assert np.abs(s[:, 3]).max() <= bounds.jerk
        # The phases integrate: position from speed, speed from acceleration.
        assert np.allclose(np.diff(s[:, 0]), (s[1:, 1] + s[:-1, 1]) / 2 * np.diff(t),
                           rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match='cannot be left at'):
        profile(0.35, 1.01 * reach, bounds)


def test_stopping_at_the_mouths_is_a_verified_move_of_exact_parts(default_cell,
                                                                  default_roadmap):
    planner = Planner(default_cell, default_roadmap, PlannerSettings())
    result = planner.stop_and_go('loadport1:inside', 'loadlock2:inside')
    move = result.trajectory
    assert isinstance(move, PortMove) and result.metrics['stops'] == 2
    assert result.verification.ok
    assert result.verification.port_ratios['lateral'] < 1e-9
    assert result.verification.port_ratios['heading'] < 1e-9
    # It stops at each mouth: there the transfer starts and ends at rest.
    velocity = move.evaluate([move.out.duration, move.duration - move.into.duration], 1)
    assert np.abs(velocity).max() < 1e-12
    # Stored and read back it is the same motion, and backwards it is the move back.
    again = Trajectory.from_description(move.describe())
    t = np.linspace(0.0, move.duration, 777)
    for order in range(4):
        assert np.array_equal(again.evaluate(t, order), move.evaluate(t, order))
    back = verify(move.backwards(), default_cell, result.goal_q, result.start_q)
    assert back.ok, back.problems


def test_a_move_whose_parts_do_not_meet_is_refused(default_cell, default_roadmap):
    planner = Planner(default_cell, default_roadmap, PlannerSettings())
    result = planner.stop_and_go('loadport1:inside', 'loadlock2:inside')
    described = result.trajectory.describe()
    described['out']['channel']['mouth'][0] += 1e-6
    moved = Trajectory.from_description(described)
    problem = moved.ill_formed(result.start_q, result.goal_q)
    assert 'the way out of the port ends at' in problem
    checked = verify(moved, default_cell, result.start_q, result.goal_q)
    assert not checked.ok and 'ill-formed' in checked.problems[0]
    described = result.trajectory.describe()
    described['into']['profile']['jerks'][0] *= 1.5    # it no longer covers its channel
    checked = verify(Trajectory.from_description(described), default_cell, result.start_q,
                     result.goal_q)
    assert not checked.ok


def test_a_free_end_moves_the_transfer_as_its_rows_jacobian_says(default_cell, default_roadmap):
    """The whole-curve rows with free ends: their Jacobian against finite differences."""
    from wafer_planner_ros.moves.through import free_end
    from wafer_planner_ros.trajectory.shape_problem import ShapeProblem
    from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings
    planner = Planner(default_cell, default_roadmap, PlannerSettings())
    transfer = planner.plan('loadport1', 'loadlock2').trajectory
    ends = []
    for station, k in (('loadport1', 0), ('loadlock2', 0)):
        channel, _ = _channel(default_cell, station, k)
        ends.append(free_end(channel, channel_bounds(channel, default_cell.robot)))
    problem = ShapeProblem(transfer, default_cell, ShapeSettings(), TimingSettings(), ends)
    scale = problem.start.intervals.copy()
    x = problem.pack(problem.start.control_points, problem.start.intervals, scale)
    columns = [problem._end_columns(n) for n in range(2)]
    for v, a, tau in columns:   # moving on at both mouths, braking a little
        x[v], x[a], x[tau] = 0.3, -0.2, 1.0
    spans = problem.spans
    wafer = (np.arange(spans), np.full(spans, 0.5))
    clearance = (np.arange(spans), np.full(spans, 0.5), np.zeros(spans, np.int64),
                 np.full(spans, 0.002))
    values, jacobian = problem.rows(x, wafer, clearance, scale)
    # The curve leaves its start along the channel at 0.3 m/s, braking at 0.2 m/s^2.
    points, intervals = problem.unpack(x, scale)
    assert np.allclose(problem.speeds(points, intervals), [(0.3, -0.2)] * 2, atol=1e-9)
    step = 1e-7
    durations = problem._duration_column[[0, 1, spans // 2, -2, -1]]  # the ends' spans too
    for column in [0, 1, *durations, *columns[0], *columns[1]]:
        moved = x.copy()
        moved[column] += step
        ahead = problem.rows(moved, wafer, clearance, scale)[0]
        moved[column] -= 2 * step
        behind = problem.rows(moved, wafer, clearance, scale)[0]
        numeric = (ahead - behind) / (2 * step)
        assert np.allclose(jacobian[:, column], numeric, rtol=1e-4, atol=1e-4), column
