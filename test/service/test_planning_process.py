"""Requests planned in a child process: the very answers planned in process, the table's here."""

import logging

from independent import check
import numpy as np
import pytest
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.report import plan_json
from wafer_planner_ros.service.planning import PlanningService
from wafer_planner_ros.service.planning_process import PlanningProcess
from wafer_planner_ros.service.table import build_table
from wafer_planner_ros.trajectory.methods import WholeCurve


@pytest.fixture
def process():
    made = PlanningProcess()
    yield made
    made.close()


@pytest.fixture(scope='module')
def planner(default_cell, default_roadmap):
    return Planner(default_cell, default_roadmap, PlannerSettings(method=WholeCurve))


def test_a_request_planned_in_the_child_is_the_one_planned_in_process(process, planner,
                                                                      default_cell):
    local = PlanningService(planner)
    service = process.service(process.key(), local)
    for start, goal in (('loadport1', 'loadlock2'), ((-1.2, 2.4, 1.3), (1.0, -2.0, -1.0))):
        there, here = service.answer(start, goal), local.answer(start, goal)
        assert there.verification.ok and there.branches == here.branches
        assert there.cycle_time == pytest.approx(here.cycle_time, rel=1e-9)
        assert np.array_equal(there.positions, here.positions)
        check(default_cell, plan_json(there, {}, default_cell.robot.joint_names),
              there.start_q, there.goal_q)
    # What the child's planner raises is raised here, with its code.
    with pytest.raises(PlanningError) as raised:
        service.answer('loadport1', 'nowhere')
    assert raised.value.code is ErrorCode.UNKNOWN_STATION and 'nowhere' in raised.value.message
    assert process.started == 1


def test_a_divert_is_planned_in_the_child_from_the_moving_state(process, planner,
                                                                station_move):
    move = station_move.trajectory
    at = 0.5 * move.duration
    diverted = process.service(process.key(), PlanningService(planner)).divert(
        move, at, 'loadport2', 'the move')
    assert diverted.verification.ok and diverted.metrics['divert'] in (
        'blended-divert', 'stop-then-move')
    curve = diverted.trajectory
    (q0, v0, a0), (q, qd, qdd) = (
        [x[0] for x in trajectory.evaluate_orders([t], range(3))]
        for trajectory, t in ((curve, 0.0), (move, at)))
    assert np.array_equal(q0, q)
    assert np.abs(v0 - qd).max() <= 1e-9 and np.abs(a0 - qdd).max() <= 1e-9


def test_a_pair_the_table_holds_is_answered_here_without_a_child(process, planner):
    table = build_table(planner, pairs=[('loadport1', 'loadlock2')])
    service = process.service(process.key(), PlanningService(planner, table=table))
    answer = service.answer('loadport1', 'loadlock2')
    assert answer.verification.ok and service.holds('loadport1', 'loadlock2')
    assert process.started == 0  # no plan: no child


def test_a_child_that_ends_fails_one_request_and_the_next_hands_the_roadmap_over_again(
        process, planner):
    key = process.key()
    process.hold(key, planner)
    service = process.service(key, PlanningService(planner))
    child = process._child._process
    child.kill()
    child.wait()
    alive, child.poll = child.poll, lambda: None  # ended, its end not seen yet
    with pytest.raises(RuntimeError, match='the planning process ended'):
        service.answer('loadport1', 'loadlock2')
    child.poll = alive
    assert service.answer('loadport1', 'loadlock2').verification.ok
    assert process.started == 2


def test_what_the_child_s_planner_logs_is_logged_here(process, planner, monkeypatch, caplog):
    from wafer_planner_ros.service import planning_process
    said = logging.getLogger('wafer_planner_ros.planner.candidates')
    # As in a process of its own (a node in this one sends them to its log instead).
    monkeypatch.setattr(logging.getLogger('wafer_planner_ros'), 'propagate', True)
    monkeypatch.setattr(said, 'disabled', False)  # as a linter's logging set-up leaves it

    def answer(service, start, goal, *arguments):
        said.warning('a curve failed; trying the next')
        raise PlanningError(ErrorCode.NO_PATH, 'none')
    # The child's side, run here: what is logged while it plans goes back with the answer.
    child = planning_process._Planning()
    try:
        monkeypatch.setattr(PlanningService, 'answer', answer)
        child.reply(('hold', 0, planner.cell, planner.roadmap, planner.settings))
        reply = child.reply(('plan', 0, None, planner.settings.sample_period, 'answer',
                             'loadport1', 'loadlock2', None, 'loaded', None))
    finally:
        logging.getLogger('wafer_planner_ros').removeHandler(child.said)
    assert reply[:3] == ('planning', 'NO_PATH', 'none')
    assert reply[3] == [(said.name, logging.WARNING, 'a curve failed; trying the next')]
    # The parent's: logged under the same logger, then the error raised.
    monkeypatch.setattr(process._child, 'exchange', lambda messages, wait=None: [reply])
    caplog.clear()
    with caplog.at_level(logging.WARNING), pytest.raises(PlanningError):
        process.service(process.key(), PlanningService(planner)).answer('loadport1', 'x')
    assert [(r.name, r.getMessage()) for r in caplog.records] == [
        (said.name, 'a curve failed; trying the next')]


def test_a_roadmap_the_child_could_not_take_is_handed_over_again(process, planner):
    from types import SimpleNamespace
    key = process.key()
    broken = SimpleNamespace(cell=None, roadmap=planner.roadmap, settings=planner.settings)
    with pytest.raises(RuntimeError, match='the planning process failed'):
        process.hold(key, broken)
    # Not counted as held: the first request under that key hands its planner over.
    service = process.service(key, PlanningService(planner))
    assert service.answer('loadport1', 'loadlock2').verification.ok
    assert process.started == 1  # the same child throughout


def test_the_child_keeps_its_answers_as_optima_stores_them_and_reads_them_back(
        process, default_cell, default_roadmap, tmp_path):
    fresh = Planner(default_cell, default_roadmap)  # the node's: knot-timing by default
    start, goal = np.array([-1.2, 2.4, 1.3]), np.array([1.0, -2.0, -1.0])
    key = process.key()
    budgeted = process.service(key, PlanningService(fresh, budget=0.12))
    first = budgeted.answer(start, goal)
    assert first.metrics.get('from_optimum') is not True
    assert not len(fresh.optima)  # learnt in the child, not here
    stored = process.store_optima(key, fresh, tmp_path)
    assert [load for load, _ in stored] == ['loaded']
    # Another roadmap key (a new child planner, nothing kept): read back, verified a few
    # at a time, and the request near the first starts from it.
    other = process.key()
    read = process.read_optima(other, fresh, tmp_path)
    assert read[0][0] == 'loaded' and read[0][1] == stored[0][1] and read[0][2] == 1
    assert read[1][0] == 'empty' and 'no optima file' in read[1][1]
    done, left = process.verify_optima(other, fresh, 4)
    assert done == [('loaded', 1, [])] and left == 0
    near = process.service(other, PlanningService(fresh, budget=0.12)).answer(
        start + 0.03, goal - 0.03)
    assert near.metrics.get('from_optimum') is True and near.verification.ok
