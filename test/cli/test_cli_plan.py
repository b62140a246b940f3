"""``wafer-plan``: one pair, all pairs, JSON schema, plots and exit codes."""

from dataclasses import replace
import json
import shutil

from independent import check
import numpy as np
import pytest
from tampered import tamper

from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.cli.common import run
from wafer_planner_ros.cli.plan import main
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.plotting import plot_trajectory
from wafer_planner_ros.service.table import build_table, table_key
from wafer_planner_ros.service.table_store import save_table, table_path
from wafer_planner_ros.trajectory.stopping import hold_demand, hold_motion


def _run(capsys, *argv):
    code = run(main, list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_one_pair_as_json(roadmap_cache, capsys):
    code, out, _ = _run(capsys, 'loadport2', 'loadlock2', '--cache-dir', str(roadmap_cache),
                        '--json', '-')
    assert code == 0
    plan = json.loads(out)
    for key in ('status', 'code', 'message', 'from', 'to', 'joint_names', 'cycle_time',
                'initial_cycle_time', 'spline', 'points', 'path', 'metrics', 'timings_ms',
                'roadmap'):
        assert key in plan
    assert plan['status'] == 'ok' and plan['from'] == 'loadport2'
    assert set(plan['spline']) == {'kind', 'degree', 'knots', 'control_points'}
    assert plan['spline']['kind'] == 'cubic-b-spline'
    assert set(plan['points'][0]) == {'t', 'q', 'qd', 'qdd'}
    assert set(plan['roadmap']) == {'nodes', 'edges', 'hash', 'seed', 'cache_hit'}
    assert plan['roadmap']['nodes'] >= 1500 and plan['roadmap']['seed'] == 0


def test_joint_angles_and_plot(roadmap_cache, capsys, tmp_path, default_cell):
    start = ','.join(str(v) for v in default_cell.stations['loadport1'].configs[0].q)
    png = tmp_path / 'plan.png'
    code, out, _ = _run(capsys, start, 'loadlock1', '--cache-dir', str(roadmap_cache),
                        '--plot', str(png))
    assert code == 0 and 'ok, cycle time' in out
    assert png.read_bytes()[:4] == b'\x89PNG' and png.stat().st_size > 50_000


def test_the_plan_figure_marks_the_verified_closest_approach_and_names_branches(
        default_cell, default_roadmap, tmp_path):
    planner = Planner(default_cell, default_roadmap)  # the corridor curve: milliseconds
    words = {1: 'elbow right', -1: 'elbow left'}
    jerk = default_cell.robot.limits.jerk
    for branches in ((1, 1), (-1, 1)):
        result = planner.plan('loadport2', 'loadlock1', branches=branches)
        figure = plot_trajectory(default_cell, result, tmp_path / 'plan.png')
        motion, bar = figure.axes[:2]
        assert motion.get_title().startswith(
            f'loadport2 ({words[branches[0]]}) -> loadlock1 ({words[branches[1]]}): '
            f'cycle time {result.cycle_time:.3f} s')
        legend = [text.get_text() for text in motion.get_legend().get_texts()]
        closest = [text for text in legend if text.startswith('closest approach')]
        assert closest == [f'closest approach: {result.min_clearance * 1000:.1f} mm, '
                           + closest[0].split(' mm, ')[1]]
        # Marked where it is: the gap drawn ends on the wall, the distance shown beside it.
        gap = next(line for line in motion.lines if line.get_label() == closest[0])
        wall = np.array([gap.get_xdata()[1], gap.get_ydata()[1]])
        assert any(text.get_text() == f'{result.min_clearance * 1000:.1f} mm'
                   and np.allclose(text.xy, wall) for text in motion.texts)
        assert abs(abs(wall[1]) - 0.45) < 1e-9 or abs(abs(wall[0]) - 0.85) < 1e-9
        assert set(default_cell.stations) <= {text.get_text() for text in motion.texts}
        # Each port's axis, dashed, from its mouth to its pick/place pose.
        dashed = [np.column_stack([line.get_xdata(), line.get_ydata()])
                  for line in motion.lines if line.get_linestyle() == '--']
        for port in default_cell.port_model.ports:
            assert any(np.allclose(axis, [port.retracted, port.inside_center])
                       for axis in dashed), port.station
        assert bar.get_ylabel() == 'time of the robot outlines (s)'
        assert bar.get_ylim() == pytest.approx((0.0, result.cycle_time))
        panel = next(axis for axis in figure.axes if axis.get_ylabel().startswith('jerk'))
        assert panel.get_ylabel() == 'jerk (rad/s³)'
        assert sorted(line.get_ydata()[0] for line in panel.lines
                      if line.get_linestyle() == '--') == sorted(np.concatenate([-jerk, jerk]))


@pytest.mark.slow
def test_all_pairs_table_and_json_file(roadmap_cache, capsys, tmp_path):
    out_file = tmp_path / 'pairs.json'
    code, out, _ = _run(capsys, '--all-pairs', '--cache-dir', str(roadmap_cache), '--json',
                        str(out_file))
    assert code == 0
    rows = json.loads(out_file.read_text())
    assert len(rows) == 12 and all(r['status'] == 'ok' for r in rows)
    pairs = {(r['from'], r['to']) for r in rows}
    assert {('loadport1', 'loadlock2'), ('loadlock2', 'loadport1')} <= pairs
    assert 'λ-scaled' in out and out.count(' ok ') == 12


def test_the_swap_cycle_of_every_loadport_loadlock_pair(roadmap_cache, capsys, tmp_path):
    out_file, png = tmp_path / 'cycle.json', tmp_path / 'cycle.png'
    # The corridor curve (knot timing) keeps it to seconds; what is checked is the bookkeeping.
    code, out, err = _run(capsys, '--cycle', '--method', 'knot-timing', '--cache-dir',
                          str(roadmap_cache), '--json', str(out_file), '--plot', str(png))
    assert code == 0, out + err
    rows = json.loads(out_file.read_text())
    assert [(r['loadport'], r['loadlock']) for r in rows] == [
        (f'loadport{a}', f'loadlock{b}') for a in (1, 2, 3) for b in (1, 2)]
    for row in rows:
        out_move, back = row['moves']
        assert (out_move['from'], out_move['to'], out_move['load']) == (
            f"{row['loadport']}:inside", f"{row['loadlock']}:inside", 'loaded')
        assert (back['from'], back['to'], back['load']) == (
            out_move['to'], out_move['from'], 'empty')
        assert back['branches'] == out_move['branches'][::-1]  # the cycle repeats
        # Never slower back empty than out loaded: the way out backwards verifies empty.
        assert back['cycle_time'] <= out_move['cycle_time']
        assert back['adopted'] == (back['cycle_time'] == out_move['cycle_time'])
        assert row['cycle'] == pytest.approx(out_move['cycle_time'] + back['cycle_time'])
        chain = row['stop_and_go_moves']
        assert [m['load'] for m in chain] == ['loaded'] * 2
        assert [(m['from'], m['to']) for m in chain] == [
            (out_move['from'], out_move['to']), (back['from'], back['to'])]
        assert chain[0]['stops'] == chain[1]['stops'] == 2   # at both mouths, each way
        assert chain[1]['branches'] == chain[0]['branches'][::-1]
        assert row['stop_and_go'] == pytest.approx(sum(m['cycle_time'] for m in chain))
        assert row['wafers_per_hour'] == pytest.approx(3600.0 / row['cycle'])
        assert row['gain'] == pytest.approx(row['stop_and_go'] / row['cycle'])
    assert 'loadport1 <-> loadlock1' in out and 'wafers/h' in out
    assert png.read_bytes()[:4] == b'\x89PNG'
    code, _, err = _run(capsys, '--cycle', '--all-pairs')
    assert code == 2 and 'not both' in err
    code, _, err = _run(capsys, '--cycle', '--load', 'empty')
    assert code == 2 and 'no --load' in err


def test_planning_failure_exits_1_and_usage_errors_exit_2(roadmap_cache, capsys):
    code, out, _ = _run(capsys, 'loadport9', 'loadlock1', '--cache-dir', str(roadmap_cache))
    assert code == 1 and 'UNKNOWN_STATION' in out
    code, _, err = _run(capsys, 'a,b,c', 'loadlock1', '--cache-dir', str(roadmap_cache))
    assert code == 2 and 'neither a station' in err
    code, _, err = _run(capsys, 'loadport1', '--cache-dir', str(roadmap_cache))
    assert code == 2
    code, _, err = _run(capsys, 'loadport1', 'loadlock1', '--sample-period', '0')
    assert code == 2 and 'sample_period' in err


_BOMB = ('&a [x, x, x, x, x, x, x, x, x, x]', *(
    f'&{chr(98 + i)} [{", ".join([f"*{chr(97 + i)}"] * 10)}]' for i in range(8)))
HAZARDS = [
    # (old text of the default cell, new text, what the message must name)
    ('name: efem-3lp-2ll', f'name: [{", ".join(_BOMB)}]', 'cell.name'),
    ('loadlock2: {', 'loadlock1: {', 'stations.loadlock1: duplicate key'),
    ('wafer_radius: 0.15', f'wafer_radius: 1{"0" * 399}', 'robot.wafer_radius: '),
    ('acceleration: [8.4,', 'acceleration: [1.0e-300,', 'robot.joint_limits.acceleration[0]'),
    ('[0.66, -0.45], [0.85, -0.45],\n             [0.85, 0.45]',
     '[0.66, -0.45], [0.85, 0.45],\n             [0.85, -0.45]',
     'cell.boundary: self-intersecting'),
    ('[0.85, -0.45],\n             [0.85, 0.45]', '[0.85, -0.45],\n             [1e400, 0.45]',
     'cell.boundary[10][0]'),
]


def test_every_cell_hazard_exits_2_with_a_short_message_naming_the_key(tmp_path, capsys):
    text = default_cell_path().read_text()
    for old, new, named in HAZARDS:
        assert text.count(old) == 1, old
        path = tmp_path / 'cell.yaml'
        path.write_text(text.replace(old, new))
        code, _, err = _run(capsys, '--cell', str(path), '--no-cache', 'loadport1',
                            'loadlock1')
        assert code == 2, err
        assert named in err and len(err.encode()) < 4096, err[:500]
        assert 'Traceback' not in err


def test_options_out_of_range_exit_2_naming_them(capsys):
    for option, value in (('--seed', '-5'), ('--seed', '1' * 40), ('--nodes', '1' * 30),
                          ('--sample-period', '1e-300')):
        code, _, err = _run(capsys, option, value, '--no-cache', 'loadport1', 'loadlock1')
        assert code == 2 and option in err and len(err) < 4096, err


def test_a_closed_ring_is_accepted_with_a_warning(roadmap_cache, tmp_path, capsys):
    text = default_cell_path().read_text()
    old = '[-0.85, 0.45]]'
    path = tmp_path / 'closed.yaml'
    path.write_text(text.replace(old, '[-0.85, 0.45], [-0.85, -0.45]]', 1))
    code, out, err = _run(capsys, '--cell', str(path), '--cache-dir', str(roadmap_cache),
                          '--json', '-', 'loadport2', 'loadlock2')
    assert code == 0, err
    assert (f'warning: {path}: cell.boundary: the last point repeats the first (a closed '
            'ring) and was dropped') in err
    # The same cell as the default one: the same roadmap.
    default = json.loads(_run(capsys, '--cache-dir', str(roadmap_cache), '--json', '-',
                              'loadport2', 'loadlock2')[1])
    assert json.loads(out)['roadmap']['hash'] == default['roadmap']['hash']


def test_joint_angles_that_start_with_a_minus_are_ends_not_options(
        roadmap_cache, capsys, default_cell):
    q = default_cell.stations['loadport1'].configs[1].q  # elbow -1: every angle negative
    assert np.all(q < 0)
    start = ','.join(repr(float(v)) for v in q)
    code, out, err = _run(capsys, start, 'loadlock1', '--method', 'knot-timing',
                          '--cache-dir', str(roadmap_cache), '--json', '-')
    assert code == 0, err
    plan = json.loads(out)
    assert plan['status'] == 'ok' and np.allclose(plan['points'][0]['q'], q, atol=1e-12)
    # Also as the goal, and a mistyped one is named, not taken for an unknown option.
    code, _, err = _run(capsys, 'loadlock1', start, '--method', 'knot-timing',
                        '--cache-dir', str(roadmap_cache))
    assert code == 0, err
    code, _, err = _run(capsys, '-1,x,2', 'loadlock1', '--cache-dir', str(roadmap_cache))
    assert code == 2 and '"-1,x,2" is neither a station name' in err
    assert 'unrecognized arguments' not in err


def test_a_tampered_table_entry_is_planned_instead_with_a_warning(
        roadmap_cache, tmp_path, capsys, default_cell, default_roadmap):
    """A stored entry edited (every knot halved, the digest recomputed) is never printed."""
    cache = tmp_path / 'cache'
    shutil.copytree(roadmap_cache, cache, ignore=shutil.ignore_patterns('table-*'))
    # The table wafer-plan loads (whole-curve), its curves from the corridor method: any
    # verified curve will do, and these take milliseconds.
    whole = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    table = replace(build_table(Planner(default_cell, default_roadmap)), key=table_key(whole))
    save_table(table, cache)
    pair = ('loadport2', 'loadlock2')
    edited = tamper(table_path(cache, table.key), {pair: 'halved'})[pair]
    code, out, err = _run(capsys, *pair, '--cache-dir', str(cache), '--json', '-')
    assert code == 0, err
    plan = json.loads(out)
    assert plan['status'] == 'ok' and plan['metrics'].get('source') != 'table'
    assert plan['spline']['knots'] != edited['trajectory']['knots']
    start, goal = (np.array(plan['spline']['control_points'][i]) for i in (0, -1))
    stations = default_cell.stations
    assert any(np.array_equal(c.q, start) for c in stations[pair[0]].configs)
    assert any(np.array_equal(c.q, goal) for c in stations[pair[1]].configs)
    check(default_cell, plan, start, goal)
    assert 'loadport2 -> loadlock2' in err and 'rejected' in err and 'x its limit' in err, err


def test_stop_at_stops_the_move_on_its_path_and_says_what_a_hold_would_demand(
        roadmap_cache, capsys, default_cell):
    code, out, _ = _run(capsys, 'loadport1', 'loadlock2', '--cache-dir', str(roadmap_cache),
                        '--stop-at', '0.4', '--json', '-')
    assert code == 0
    move, stop = json.loads(out)
    assert stop['status'] == 'ok' and stop['spline']['kind'] == 'retimed'
    assert stop['spline']['base'] == move['spline']
    assert stop['metrics']['stopped_at'] == 0.4 and stop['metrics']['timing'] == 'braked'
    assert stop['cycle_time'] < move['cycle_time'] - 0.4
    assert max(stop['metrics']['limit_ratios'].values()) <= 1.0
    limit = default_cell.robot.limit_set.wafer.xy.max()
    assert stop['metrics']['hold_wafer_acceleration'] > 2.0 * limit
    # The stop starts where the move is at 0.4 s: its samples continue the move's.
    at = next(p for p in move['points'] if abs(p['t'] - 0.4) < 1e-9)
    assert np.allclose(stop['points'][0]['q'], at['q'], rtol=0, atol=1e-12)
    assert np.allclose(stop['points'][0]['qd'], at['qd'], rtol=0, atol=1e-9)
    code, out, _ = _run(capsys, 'loadport1', 'loadlock2', '--cache-dir', str(roadmap_cache),
                        '--stop-at', '99')
    assert code == 1 and 'OUTSIDE_TRAJECTORY' in out
    code, _, err = _run(capsys, '--all-pairs', '--stop-at', '1', '--cache-dir',
                        str(roadmap_cache))
    assert code == 2 and '--stop-at' in err


def test_stop_at_with_plot_draws_the_move_and_the_stop_against_the_hold(
        roadmap_cache, capsys, tmp_path):
    png = tmp_path / 'move.png'
    code, _, err = _run(capsys, 'loadport1', 'loadlock2', '--cache-dir', str(roadmap_cache),
                        '--method', 'knot-timing', '--stop-at', '0.4', '--plot', str(png))
    assert code == 0
    stop = tmp_path / 'move_stop.png'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['move.png', 'move_stop.png']
    for drawn in (png, stop):
        assert drawn.read_bytes()[:4] == b'\x89PNG' and drawn.stat().st_size > 30_000
        assert f'plot: {drawn}' in err


def test_the_abrupt_hold_brakes_each_joint_alone_at_its_limit_and_peaks_at_hold_demand(
        default_cell, default_roadmap):
    robot = default_cell.robot
    move = Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock2').trajectory
    braking = robot.limit_set.joints.acceleration
    for at in (0.4, 0.5 * move.duration):
        t, q, qd, qdd = hold_motion(move, at, robot)
        q0, v0 = (x[0] for x in move.evaluate_orders([at], (0, 1)))
        assert t[0] == 0.0 and np.array_equal(q[0], q0) and np.array_equal(qd[0], v0)
        rests = np.abs(v0) / braking
        assert t[-1] == pytest.approx(rests.max(), rel=1e-12)
        for j in range(3):
            moving = t < rests[j]
            # Exactly at its limit against its motion until it rests, then still.
            assert np.all(qdd[moving, j] == -np.sign(v0[j]) * braking[j])
            assert np.all(qdd[~moving, j] == 0.0)
            assert np.allclose(np.abs(qd[moving, j]), np.abs(v0[j]) - braking[j] * t[moving],
                               rtol=0, atol=1e-12)
            assert np.abs(qd[~moving, j]).max(initial=0.0) <= 1e-12
        assert np.abs(qd[-1]).max() <= 1e-12
        # Positions: the speeds integrated (exact but in the step where a joint comes to rest).
        steps = 0.5 * (qd[1:] + qd[:-1]) * np.diff(t)[:, None]
        assert np.allclose(q[1:], q0 + np.cumsum(steps, axis=0), rtol=0, atol=1e-6)
        wafer = robot.arm.wafer_acceleration(q, qd, qdd)
        assert float(np.abs(wafer).max()) == hold_demand(move, at, robot)
        assert hold_demand(move, at, robot) > 2.0 * robot.limit_set.wafer.xy.max()
