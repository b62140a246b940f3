"""Moves from and to inside a port: requested, planned through the channel, checked."""

import copy
import dataclasses
from pathlib import Path

from independent import check, port_ratios
import numpy as np
import pytest
from wafer_planner_ros.cell.limits import EMPTY
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.moves.channel import Channel, channel_bounds
from wafer_planner_ros.moves.timing import profile
from wafer_planner_ros.planner import candidates, Planner, PlannerSettings
from wafer_planner_ros.report import plan_json, roadmap_json
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.trajectory import shape as shape_module
from wafer_planner_ros.trajectory.methods import KnotTiming, WholeCurve
from wafer_planner_ros.trajectory.tuning import ShapeSettings
import yaml

CELL_DIR = Path(__file__).resolve().parents[1] / 'support' / 'cells'


def _planner(cell, roadmap_cache, method=KnotTiming):
    cached = load_or_build(cell, cache_dir=roadmap_cache)
    return Planner(cell, cached.roadmap, PlannerSettings(method=method)), roadmap_json(cached)


def _ports_first_loadport_to_loadlock(cell):
    names = sorted(cell.stations)
    return (next(n for n in names if n.startswith('loadport')),
            next(n for n in names if n.startswith('loadlock')))


def _mouth_speed(cell, result, station):
    """Return the wafer's speed (m/s) where it crosses the mouth of ``station``'s port."""
    port = cell.stations[station].port
    t = np.linspace(0.0, result.cycle_time, 20001)
    q = result.trajectory.evaluate(t)
    s = port.offsets(cell.robot.arm.wafer_center(q))[0]
    k = int(np.argmin(np.abs(s)))
    around = np.clip([t[k] - 1e-4, t[k] + 1e-4], 0.0, result.cycle_time)
    a, b = cell.robot.arm.wafer_center(result.trajectory.evaluate(around))
    return float(np.linalg.norm(b - a) / np.diff(around)[0])


def test_a_move_from_inside_a_port_to_inside_another_passes_the_independent_check(
        cell, roadmap_cache):
    planner, info = _planner(cell, roadmap_cache)
    loadport, loadlock = _ports_first_loadport_to_loadlock(cell)
    result = planner.plan(f'{loadport}:inside', f'{loadlock}:inside')
    plan = plan_json(result, info, cell.robot.joint_names)
    ratios = check(cell, plan, result.start_q, result.goal_q)
    assert result.verification.ok
    inside = {c.elbow: c.q for c in cell.stations[loadport].inside}
    assert np.array_equal(result.start_q, inside[result.branches[0]])
    inside = {c.elbow: c.q for c in cell.stations[loadlock].inside}
    assert np.array_equal(result.goal_q, inside[result.branches[1]])
    # It went through both channels: the wafer was deep inside each port.
    q = result.trajectory.evaluate(np.linspace(0.0, result.cycle_time, 2001))
    where = cell.port_model.inside(q)
    ports = [p.station for p in cell.port_model.ports]
    assert where[0] == ports.index(loadport) and where[-1] == ports.index(loadlock)
    assert 0.0 < ratios['port_lateral'] <= 1.0 and ratios['port_heading'] <= 1.0


def test_a_move_through_the_ports_is_never_slower_than_stopping_at_their_mouths(
        cell, roadmap_cache):
    planner, info = _planner(cell, roadmap_cache)
    loadport, loadlock = _ports_first_loadport_to_loadlock(cell)
    start, goal = f'{loadport}:inside', f'{loadlock}:inside'
    result = planner.plan(start, goal)
    # The same move as a controller without non-stop moves makes it: straight out of the
    # port along its axis, transfer, straight in, each from rest to rest, on every elbow
    # branch that reaches into the ports.

    def way(station, elbow):
        port, configs = cell.stations[station].port, cell.stations[station].configs
        inside = {c.elbow: c.q for c in cell.stations[station].inside}[elbow]
        channel = Channel.out_of(cell.robot.arm, inside, port.axis, port.depth,
                                 mouth={c.elbow: c.q for c in configs}[elbow])
        return profile(channel.length, 0.0,
                       channel_bounds(channel, cell.robot).at(0.0, 0.0)).duration

    chains = []
    for elbow_a, _ in planner.endpoint(start, 'start').configs:
        for elbow_b, _ in planner.endpoint(goal, 'goal').configs:
            transfer = planner.plan(loadport, loadlock, branches=(elbow_a, elbow_b))
            assert transfer.metrics['stops'] == 0
            chains.append(way(loadport, elbow_a) + transfer.cycle_time + way(loadlock, elbow_b))
    assert result.cycle_time <= min(chains) * (1.0 + 1e-12)
    assert result.timings_ms['stopping'] > 0.0
    if result.metrics['stops']:
        # Stopping was the faster: the answer is at rest at both port mouths, and sound.
        assert result.metrics['stops'] == 2
        assert _mouth_speed(cell, result, loadport) < 1e-3
        assert _mouth_speed(cell, result, loadlock) < 1e-3
        check(cell, plan_json(result, info, cell.robot.joint_names), result.start_q,
              result.goal_q)
        assert result.verification.ok and result.cycle_time == pytest.approx(min(chains))
    # Within a time budget the move is made the same way: straight through both ports.
    budgeted = planner.plan(start, goal, budget=0.1)
    assert budgeted.verification.ok
    assert budgeted.verification.port_ratios['lateral'] < 1e-6
    assert budgeted.metrics['in_port_time'] > 0.0


def test_joint_angles_inside_a_port_are_a_pose_inside_it(default_cell, roadmap_cache):
    planner, info = _planner(default_cell, roadmap_cache)
    inside = default_cell.stations['loadlock1'].inside[0].q
    result = planner.plan(inside.tolist(), 'loadport2')
    check(default_cell, plan_json(result, info, default_cell.robot.joint_names),
          result.start_q, result.goal_q)
    # The roadmap path starts at the retracted pose: the move left the port first.
    assert len(planner.endpoint(inside.tolist(), 'start').channels) == 1
    assert np.array_equal(result.path[0], inside)
    assert default_cell.port_model.inside(result.path[1:2])[0] == -1


def _off_axis(cell, station, s, offset):
    port = cell.stations[station].port
    centre = port.retracted + s * port.axis + offset * port.normal
    return [c for c in cell.robot.arm.inverse(centre, port.heading, cell.robot.limits.position)
            if c.elbow == 1][0].q


def test_joint_angles_inside_a_port_but_off_its_axis_are_refused(default_cell, default_roadmap):
    q = _off_axis(default_cell, 'loadport2', 0.2, 0.002)
    assert port_ratios(default_cell, q[None])['port_lateral'] == pytest.approx(2.0)
    with pytest.raises(PlanningError) as info:
        Planner(default_cell, default_roadmap).plan(q.tolist(), 'loadlock1')
    assert info.value.code is ErrorCode.OUT_OF_LIMITS
    assert 'inside the port of loadport2 2.00 mm off its axis (tolerance 1.00 mm)' in \
        info.value.message


def test_inside_names_a_known_station_with_a_port(default_cell, default_roadmap):
    document = yaml.safe_load(open(default_cell.source))
    without = copy.deepcopy(document)
    without['stations']['loadport1'].pop('port')
    cell = Cell.from_dict(without)
    with pytest.raises(PlanningError) as info:
        Planner(cell, default_roadmap).endpoint('loadport1:inside', 'start')
    assert info.value.code is ErrorCode.INVALID_REQUEST
    assert 'station loadport1 has no port' in info.value.message
    with pytest.raises(PlanningError) as info:
        Planner(default_cell, default_roadmap).plan('loadport9:inside', 'loadlock1')
    assert info.value.code is ErrorCode.UNKNOWN_STATION
    assert "'loadport9:inside'" in info.value.message


@pytest.mark.slow
def test_the_whole_curve_leaves_and_enters_the_ports_without_stopping(default_cell,
                                                                      roadmap_cache):
    stop_and_go, _ = _planner(default_cell, roadmap_cache)
    planner, info = _planner(default_cell, roadmap_cache, WholeCurve)
    start, goal = 'loadport2:inside', 'loadlock1:inside'
    result = planner.plan(start, goal)
    check(default_cell, plan_json(result, info, default_cell.robot.joint_names),
          result.start_q, result.goal_q)
    assert result.metrics['optimised'] and result.verification.ok
    assert result.metrics['stops'] == 0
    # The corridor curve stops at both retracted poses; the whole curve does not.
    stopping = stop_and_go.plan(start, goal)
    assert _mouth_speed(default_cell, stopping, 'loadport2') < 1e-3
    assert _mouth_speed(default_cell, result, 'loadport2') > 0.05
    assert _mouth_speed(default_cell, result, 'loadlock1') > 0.05
    assert result.cycle_time < 0.8 * stopping.cycle_time


@pytest.mark.slow
def test_a_move_through_the_ports_takes_the_transfer_its_station_pair_finished(
        default_cell, roadmap_cache, monkeypatch):
    """The station pair's other elbow-branch combinations serve as transfers, verified."""
    planner, _ = _planner(default_cell, roadmap_cache, WholeCurve)
    fresh, _ = _planner(default_cell, roadmap_cache, WholeCurve)
    start, goal, branches = 'loadport1:inside', 'loadlock2:inside', (1, 1)
    pair = planner.plan('loadport1', 'loadlock2')
    assert pair.branches != branches and pair.metrics['candidates'] == 4
    planned, verified = [], []
    real_planned, real_verified = Planner._planned, candidates.verified

    def spy_planned(self, a, b, *rest):
        planned.append((a.label, b.label))
        return real_planned(self, a, b, *rest)

    def spy_verified(planner, candidate, stage_ms):
        verified.append(candidate.pair.branches)
        return real_verified(planner, candidate, stage_ms)

    monkeypatch.setattr(Planner, '_planned', spy_planned)
    monkeypatch.setattr(candidates, 'verified', spy_verified)
    result = planner.plan(start, goal, branches=branches)
    # The transfer between the mouths was not planned again: verified, then blended.
    assert planned == [(start, goal)] and verified == [branches]
    assert result.verification.ok and result.metrics['stops'] == 0
    monkeypatch.undo()
    alone = fresh.plan(start, goal, branches=branches)
    assert result.cycle_time == pytest.approx(alone.cycle_time, rel=1e-9)
    # One that fails its verification is planned again.
    planner, _ = _planner(default_cell, roadmap_cache, WholeCurve)
    planner.plan('loadport1', 'loadlock2')
    refused = []

    def failing(planner, candidate, stage_ms):
        refused.append(candidate.pair.branches)
        raise PlanningError(ErrorCode.VERIFICATION_FAILED, 'refused by the test')

    monkeypatch.setattr(candidates, 'verified', failing)
    monkeypatch.setattr(Planner, '_planned', spy_planned)
    planned.clear()
    with pytest.raises(PlanningError):
        planner.plan(start, goal, branches=branches)   # every candidate is refused
    assert refused[0] == branches and planned[1] == ('loadport1', 'loadlock2')


@pytest.mark.slow
@pytest.mark.parametrize('seed', [1, 2])
def test_a_move_round_a_notch_blends_into_both_ports(roadmap_cache, seed):
    """
    The notched cell's loadport1 -> loadlock1 goes round its notch: a path of 12 vertices.

    Its transfer between the mouths, fitted with 8 spans, cut the notch's corners and was
    never proven; the move then stopped at both mouths on the corridor curve, more than
    twice as slow as it is now (seed 2). On seed 1's roadmap, with the elbow flipped, the
    transfer sweeps past loadlock2's mouth with its blade turned: its optimum sat on the
    tip of that port's wedge, nothing was proven, and the move stopped at both mouths on
    the corridor curve until the optimiser kept a disc round that mouth.
    """
    cell = Cell.from_yaml(CELL_DIR / 'notched.yaml')
    cached = load_or_build(cell, seed=seed, cache_dir=roadmap_cache)
    planner = Planner(cell, cached.roadmap, PlannerSettings(method=WholeCurve))
    start, goal = 'loadport1:inside', 'loadlock1:inside'
    result = planner.plan(start, goal, load=EMPTY)
    check(cell, plan_json(result, roadmap_json(cached), cell.robot.joint_names),
          result.start_q, result.goal_q)
    assert result.metrics['stops'] == 0
    assert _mouth_speed(cell, result, 'loadport1') > 0.05
    assert _mouth_speed(cell, result, 'loadlock1') > 0.05
    stopping = planner.stop_and_go(start, goal, load=EMPTY)
    assert result.cycle_time <= stopping.cycle_time
    # Its transfer between the mouths, too, is the whole curve's, not the corridor curve.
    corridor = Planner(cell, cached.roadmap, PlannerSettings(method=KnotTiming)).plan(
        start, goal, load=EMPTY)
    assert stopping.cycle_time < 0.6 * corridor.cycle_time


@pytest.mark.slow
def test_a_transfer_round_a_pillar_is_proven_by_its_coarse_stage(roadmap_cache):
    """
    A coarse stage that proves nothing is tried again, with more clearance samples.

    The pillar cell, roadmap seed 1, empty, loadport1:inside -> loadlock1:inside, the elbow
    flipped on the way: with four clearance samples on each of its eight coarse spans, an
    arm link swung 5 cm into a wall between samples, each round chased the last one's
    collision, and the coarse stage proved nothing in six rounds; the fine stage then
    started from the corridor curve (13 s to plan, 3.718 s, where 3.652 s is found).
    """
    cell = Cell.from_yaml(CELL_DIR / 'pillar.yaml')
    cached = load_or_build(cell, seed=1, cache_dir=roadmap_cache)
    planner = Planner(cell, cached.roadmap, PlannerSettings(method=WholeCurve))
    result = planner.plan('loadport1:inside', 'loadlock1:inside', load=EMPTY)
    check(cell, plan_json(result, roadmap_json(cached), cell.robot.joint_names),
          result.start_q, result.goal_q)
    assert result.metrics['stops'] == 0
    assert 'coarse_cycle_time' in result.metrics   # the coarse stage proved a curve
    assert result.metrics['coarse_cycle_time'] < 1.1 * result.metrics['transfer_time']


def test_joint_angles_at_a_mouth_are_not_inside_its_port(roadmap_cache):
    """
    A station's retracted pose given as joint angles is at its mouth, not inside its port.

    The pillar cell's loadlock1 pose on the elbow-left branch puts the wafer a rounding
    (3e-16 m) past its mouth: taken as inside, its way out of zero length ended where
    the mouth's inverse kinematics put it, 4e-16 rad from the angles asked, and every
    move to those angles failed verification.
    """
    cell = Cell.from_yaml(CELL_DIR / 'pillar.yaml')
    cached = load_or_build(cell, seed=0, cache_dir=roadmap_cache)
    start, goal = ([c.q for c in cell.stations[name].configs if c.elbow == elbow][0]
                   for name, elbow in (('loadport1', 1), ('loadlock1', -1)))
    assert cell.port_model.inside(goal[None])[0] >= 0   # the rounding is still there
    result = Planner(cell, cached.roadmap, PlannerSettings(method=KnotTiming)).plan(
        start, goal)
    assert result.verification.ok and 'in_port_time' not in result.metrics
    assert np.array_equal(result.goal_q, goal)


@pytest.mark.slow
def test_a_solve_that_fails_to_push_its_start_out_of_a_keep_out_drops_it(
        default_cell, default_roadmap, monkeypatch):
    """
    A blend whose first solve fails under the keep-outs is solved under the port rule alone.

    The default cell, empty, loadport1:inside -> loadlock2:inside: on the elbow-right
    branches the transfer between the mouths passes near another port's mouth, and the
    blend has to push it out of the keep-out round it. Where that first solve failed, the
    combination was lost, and the move came to 2.785 s where it is 2.581 s without
    keep-outs (1.079 times). Whether that solve fails depends on rounding (it did on the
    machine this was found on, not on another since), so here it is made to fail: each
    such blend goes on under the port rule alone, and the move keeps the branches and,
    within what the keep-outs cost elsewhere in it (none and 0.16 % on those two
    machines), the time of the move planned without keep-outs.
    """
    real, failed = shape_module._solve, []

    def failing(problem, start, *rest, **options):
        solved = real(problem, start, *rest, **options)
        if any(end is not None for end in problem.ends) and start is problem.start \
                and problem.clearance.model is not problem.model:
            failed.append(problem)
            return dataclasses.replace(solved, points=np.full_like(solved.points, np.nan))
        return solved

    def planned(shape):
        planner = Planner(default_cell, default_roadmap,
                          PlannerSettings(method=WholeCurve, shape=shape))
        return planner.plan('loadport1:inside', 'loadlock2:inside', load=EMPTY)

    plain = planned(ShapeSettings(port_keep_out=0.0))
    monkeypatch.setattr(shape_module, '_solve', failing)
    kept = planned(ShapeSettings())
    assert failed and all(problem.clearance.model is problem.model for problem in failed)
    assert kept.verification.ok and kept.metrics['stops'] == 0
    assert kept.branches == plain.branches
    assert kept.cycle_time <= 1.01 * plain.cycle_time


@pytest.mark.slow
def test_a_start_near_a_mouth_gets_a_second_opinion_under_the_port_rule(roadmap_cache):
    """
    Where the way past another port's mouth is narrow, the keep-out round it is dropped.

    The default cell with loadport1 re-taught 5 mm along x, loaded, from loadport1 on the
    elbow-right branch to loadlock1 on the left: the coarse stage's start passes turned
    within the keep-out round another port's mouth; pushed out of it, its first proven
    curve took 4.159 s and the fine stage found nothing faster in six rounds (15 s), where
    without keep-outs the move takes 2.62 s.
    """
    document = yaml.safe_load(default_cell_path().read_text())
    document['stations']['loadport1']['wafer_center'][0] += 0.005
    cell = Cell.from_dict(document)
    roadmap = load_or_build(cell, cache_dir=roadmap_cache).roadmap
    start, goal = ([c.q for c in cell.stations[name].configs if c.elbow == elbow][0]
                   for name, elbow in (('loadport1', 1), ('loadlock1', -1)))

    def planned(shape):
        planner = Planner(cell, roadmap, PlannerSettings(method=WholeCurve, shape=shape))
        return planner.plan(start, goal)

    kept = planned(ShapeSettings())
    assert kept.verification.ok and kept.verification.proof.certified
    assert kept.cycle_time <= 1.005 * planned(ShapeSettings(port_keep_out=0.0)).cycle_time
