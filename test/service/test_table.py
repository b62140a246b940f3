"""The station table: built, stored, loaded and checked; a bad file is never trusted."""

from collections import namedtuple
from dataclasses import replace
import json
import re
import time

from independent import check
import numpy as np
import pytest
from sampling import sampled_every
from tampered import digest, tamper

from wafer_planner_ros.cell.limits import EMPTY, LOADED
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.report import plan_json, roadmap_json
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service import table as table_module
from wafer_planner_ros.service.adoption import adopted
from wafer_planner_ros.service.planning import PlanningService, whole_curve
from wafer_planner_ros.service.settings import settings_from
from wafer_planner_ros.service.table import build_and_store_table, inherited_table
from wafer_planner_ros.service.table import build_table, load_or_build_table, load_table
from wafer_planner_ros.service.table import lacking, port_pairs
from wafer_planner_ros.service.table import table_key
from wafer_planner_ros.service.table import table_pairs, TableError
from wafer_planner_ros.service.table_store import save_table, table_path
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.methods import WholeCurve
from wafer_planner_ros.trajectory.verify import verify

_Request = namedtuple('_Request', 'start goal')


@pytest.fixture(scope='module')
def planner(default_cell, default_roadmap):
    """Return a corridor-curve planner: the table works with any method, and this is fast."""
    return Planner(default_cell, default_roadmap)


@pytest.fixture(scope='module')
def built(planner):
    """Return the default cell's table, built once."""
    return build_table(planner)


def test_the_table_holds_every_station_pair_as_planned(planner, built, default_cell,
                                                       roadmap_cache):
    assert set(built.entries) == set(station_pairs(default_cell)) and not built.failures
    info = roadmap_json(load_or_build(default_cell, cache_dir=roadmap_cache))
    for start, goal in station_pairs(default_cell)[:3]:
        answer = built.answer(planner, start, goal)
        fresh = planner.plan(start, goal)
        assert answer.cycle_time == fresh.cycle_time
        assert np.array_equal(answer.positions, fresh.positions)
        assert answer.verification.proof.certified and answer.metrics['source'] == 'table'
        check(default_cell, plan_json(answer, info, default_cell.robot.joint_names),
              answer.start_q, answer.goal_q)
    assert built.answer(planner, 'loadport1', 'loadport2') is None  # not a table pair


def test_the_way_back_is_the_way_there_backwards(planner, built, default_cell, roadmap_cache):
    there = built.answer(planner, 'loadport1', 'loadlock2')
    back = built.answer(planner, 'loadlock2', 'loadport1')
    assert back.metrics['reversed'] and 'reversed' not in there.metrics
    assert back.cycle_time == pytest.approx(there.cycle_time, rel=1e-12)
    assert back.branches == there.branches[::-1]
    t = np.linspace(0.0, there.cycle_time, 1001)
    assert np.allclose(back.trajectory.evaluate(t), there.trajectory.evaluate(t[::-1]),
                       rtol=0, atol=1e-12)
    assert np.array_equal(back.start_q, there.goal_q)
    assert back.verification.proof.certified
    info = roadmap_json(load_or_build(default_cell, cache_dir=roadmap_cache))
    check(default_cell, plan_json(back, info, default_cell.robot.joint_names), back.start_q,
          back.goal_q)


def test_a_stored_table_loads_to_the_same_answers(planner, built, tmp_path):
    path = save_table(built, tmp_path)
    assert path == table_path(tmp_path, table_key(planner))
    loaded = load_table(planner, tmp_path)
    assert loaded.loaded and set(loaded.entries) == set(built.entries)
    for pair in built.entries:
        assert loaded.answer(planner, *pair).cycle_time == built.answer(planner, *pair).cycle_time
    # Another sample period shares the table; other planner settings do not.
    other = Planner(planner.cell, planner.roadmap, PlannerSettings(sample_period=0.02))
    assert table_key(other) == table_key(planner)
    assert sampled_every(load_table(other, tmp_path).answer(
        other, 'loadport1', 'loadlock1').times, 0.02)
    paper = Planner(planner.cell, planner.roadmap, PlannerSettings.paper())
    with pytest.raises(TableError, match='no table file'):
        load_table(paper, tmp_path)


@pytest.mark.parametrize('damage, words', [
    (lambda doc: doc['entries'][0]['trajectory']['knots'].__setitem__(5, 0.5), 'digest'),
    (lambda doc: doc.__setitem__('key', '0' * 64), 'another cell'),
    (lambda doc: doc.pop('entries'), 'unreadable'),
    (lambda doc: doc.__setitem__('failures', [['loadport1', 'loadlock1']]), 'unreadable'),
])
def test_a_damaged_or_foreign_file_is_refused(planner, built, tmp_path, damage, words):
    path = save_table(built, tmp_path)
    document = json.loads(path.read_text())
    damage(document)
    path.write_text(json.dumps(document))
    with pytest.raises(TableError, match=words):
        load_table(planner, tmp_path)


def test_an_entry_that_does_not_join_its_stations_is_rejected(planner, built, tmp_path):
    swapped = replace(built, entries=dict(built.entries))
    pairs = sorted(built.entries)
    swapped.entries[pairs[0]] = built.entries[pairs[1]]  # digest consistent, curve wrong
    save_table(swapped, tmp_path)
    loaded = load_table(planner, tmp_path)
    assert set(loaded.rejected) == {pairs[0]} and set(loaded.entries) == set(pairs[1:])
    assert 'not the goal' in loaded.rejected[pairs[0]]
    # load_or_build_table then plans it again and stores a good table.
    rebuilt = load_or_build_table(planner, tmp_path)
    assert not rebuilt.loaded and set(rebuilt.entries) == set(pairs)
    again = load_table(planner, tmp_path)
    assert again.loaded and not again.rejected and set(again.entries) == set(pairs)


def test_a_request_is_answered_from_the_table_or_within_the_budget(planner, built):
    budget = replace(settings_from({}), optimise_budget=0.3).optimise_budget
    deadline = time.monotonic() + 60.0
    held = PlanningService(planner, built, budget).answer('loadport1', 'loadlock1', deadline)
    assert held.metrics['source'] == 'table' and set(held.timings_ms) == {'table', 'total'}
    # A station pair the table does not hold, or no table yet: the whole-curve optimisation
    # within the budget, as for joint angles; without a budget, the corridor curve.
    for table, request in ((built, _Request('loadport1', 'loadport2')),
                           (None, _Request('loadport1', 'loadlock1'))):
        answer = PlanningService(planner, table, budget).answer(*request, deadline)
        assert answer.metrics['method'] == 'whole-curve' and 'source' not in answer.metrics
        assert answer.metrics['budget'] == budget and answer.verification.proof.certified
        corridor = PlanningService(planner, table, 0.0).answer(*request, deadline)
        assert corridor.metrics['method'] == 'knot-timing'
        assert answer.cycle_time < corridor.cycle_time
    # Joint angles: the whole-curve optimisation within the budget, verified and proven.
    angles = _Request(list(planner.cell.stations['loadport1'].configs[0].q), 'loadlock2')
    budgeted = PlanningService(planner, built, budget).answer(*angles, deadline)
    assert budgeted.metrics['method'] == 'whole-curve' and budgeted.metrics['budget'] == budget
    assert budgeted.verification.ok and budgeted.verification.proof.certified
    corridor = PlanningService(planner, built, 0.0).answer(*angles, deadline)
    assert corridor.metrics['method'] == 'knot-timing'
    # Unbudgeted (the tools, a replay): the planner's own method, as long as it takes.
    whole = PlanningService(whole_curve(planner)).answer(*angles, deadline)
    assert whole.metrics['method'] == 'whole-curve' and 'budget' not in whole.metrics
    assert budgeted.cycle_time <= corridor.cycle_time


def test_a_port_move_within_the_budget_blends_and_beats_stopping_at_the_mouths(
        default_cell, default_roadmap):
    # A first start: no table yet. Within the packaged budget the move through the ports is
    # still the blended one (its transfer planned in up to 3/4 of the time to the deadline:
    # the budget alone made it slower than stopping), faster than the move that stops.
    budget = settings_from({}).optimise_budget
    start, goal = 'loadport1:inside', 'loadlock2:inside'
    service = PlanningService(Planner(default_cell, default_roadmap), budget=budget)
    answer = service.answer(start, goal, time.monotonic() + 20.0)
    assert answer.metrics['method'] == 'whole-curve' and answer.metrics['budget'] == budget
    assert answer.verification.ok and answer.metrics['stops'] == 0
    stopping = Planner(default_cell, default_roadmap, PlannerSettings(
        method=WholeCurve)).stop_and_go(start, goal, branches=answer.branches)
    assert stopping.metrics['stops'] == 2
    assert answer.cycle_time < stopping.cycle_time


def test_the_service_answers_from_its_table_once_it_is_set(planner, built):
    # The node's way: the service serves before its table is planned, then the table is set.
    service = PlanningService(planner)
    assert not service.holds('loadport1', 'loadlock1')
    service.table = built
    assert service.holds('loadport1', 'loadlock1')
    assert not service.holds('loadport1', 'loadport2')          # not a pair of the table
    assert not service.holds(list(planner.cell.stations['loadport1'].configs[0].q),
                             'loadlock1')                        # joint angles
    # A request's own budget and sample period: the same table answers.
    coarse = service.using(0.3, 0.05)
    assert coarse.table is built and coarse.budget == 0.3
    answer = coarse.answer('loadport1', 'loadlock1')
    assert answer.metrics['source'] == 'table'
    assert sampled_every(answer.times, 0.05)


def test_a_table_missing_pairs_is_completed_a_colliding_curve_rejected(
        planner, built, tmp_path):
    pairs = sorted(built.entries)
    short = replace(built, entries={pair: built.entries[pair] for pair in pairs[1:]})
    save_table(short, tmp_path)
    loaded = load_table(planner, tmp_path)  # a build stopped half-way: kept, completed
    assert lacking(loaded, station_pairs(planner.cell)) == [pairs[0]]
    assert lacking(loaded, port_pairs(planner.cell)) == port_pairs(planner.cell)
    completed = load_or_build_table(planner, tmp_path)
    assert set(completed.entries) == set(pairs) and not lacking(completed, pairs)
    assert completed.entries[pairs[1]] == built.entries[pairs[1]]  # kept, not planned again
    # A curve through the back wall, its digest consistent and its stored proof "certified".
    entry = json.loads(json.dumps(built.entries[pairs[0]]))
    points = entry['trajectory']['control_points']
    points[len(points) // 2] = [-np.pi / 2, 0.0, 0.0]
    save_table(replace(built, entries=dict(built.entries) | {pairs[0]: entry}), tmp_path)
    loaded = load_table(planner, tmp_path)
    assert pairs[0] not in loaded.entries
    assert 'not proven collision-free' in loaded.rejected[pairs[0]]


def test_a_reversed_entry_names_its_own_branches(roadmap_cache):
    from conftest import CELL_FILES
    from wafer_planner_ros.cell.model import Cell
    cell = Cell.from_yaml(CELL_FILES['pillar'])  # a station given by joint angles
    table = build_table(Planner(cell, load_or_build(cell, cache_dir=roadmap_cache).roadmap))
    reversed_entries = [e for e in table.entries.values() if e['metrics'].get('reversed')]
    assert len(reversed_entries) == len(table.entries) // 2
    assert any(e['branches'] != e['branches'][::-1] for e in reversed_entries)
    for entry in table.entries.values():
        assert entry['metrics']['branches'] == entry['branches']


TAMPERED = ('loadport1', 'loadlock2')
"""The pair whose entry the tests edit."""


@pytest.mark.parametrize('kind, words', [
    ('halved', 'reaches [0-9.]+ x its limit'),
    ('shifted', r'the first four knots are \[0.3, 0.3, 0.3, 0.3\], not 0'),
    ('nudged', 'control point 1 is .*, not the start .*: the motion does not start at rest'),
    ('nan', 'control point [0-9]+ is .*nan.*, not finite'),
    ('slowed', r'its curve lasts [0-9.]+ s, over 60 s'),
    ('initial', 'its initial cycle time nan is not a finite time'),
    ('counted', 'its planning counts are not all finite numbers or flags'),
    ('path', "its roadmap_path is not a path from its stations' retracted poses to its end"),
])
def test_a_tampered_entry_is_rejected_never_published(planner, built, default_cell,
                                                      roadmap_cache, tmp_path, kind, words):
    """An entry edited, its digest recomputed: verified in full, rejected, planned again."""
    save_table(built, tmp_path)
    tamper(table_path(tmp_path, built.key), {TAMPERED: kind})
    loaded = load_table(planner, tmp_path)
    answer = loaded.answer(planner, *TAMPERED)
    if answer is not None:  # what the table gives must hold, checked independently
        info = roadmap_json(load_or_build(default_cell, cache_dir=roadmap_cache))
        check(default_cell, plan_json(answer, info, default_cell.robot.joint_names),
              answer.start_q, answer.goal_q)
    assert answer is None and TAMPERED not in loaded.entries
    assert set(loaded.rejected) == {TAMPERED}
    assert re.search(words, loaded.rejected[TAMPERED]), loaded.rejected[TAMPERED]
    assert set(loaded.entries) == set(built.entries) - {TAMPERED}
    # load_or_build_table plans it again (no rejected pair is ever answered from the file)
    # and stores the table whole.
    completed = load_or_build_table(planner, tmp_path)
    assert set(completed.rejected) == {TAMPERED} and not completed.loaded
    assert set(completed.entries) == set(built.entries)
    again = completed.answer(planner, *TAMPERED)  # here the way back, backwards
    assert again.verification.ok and again.cycle_time == pytest.approx(
        built.answer(planner, *TAMPERED).cycle_time, rel=1e-12)
    stored = load_table(planner, tmp_path)
    assert stored.loaded and not stored.rejected and set(stored.entries) == set(built.entries)


def test_a_forged_method_is_not_reported(planner, built, tmp_path):
    """What an answer measures on its curve (method, lengths, counts of it) is never read."""
    save_table(built, tmp_path)
    document = json.loads(table_path(tmp_path, built.key).read_text())
    for entry in document['entries']:
        entry['metrics'].update(method='forged', joint_path_length=-1.0, control_points=0)
    document['digest'] = digest(document['entries'], document['failures'])
    table_path(tmp_path, built.key).write_text(json.dumps(document))
    loaded = load_table(planner, tmp_path)
    assert not loaded.rejected
    for pair in built.entries:
        metrics, truth = loaded.answer(planner, *pair).metrics, built.answer(planner, *pair)
        assert metrics['method'] == planner.method.name == truth.metrics['method'] \
            == loaded.method
        assert metrics['joint_path_length'] == pytest.approx(
            truth.metrics['joint_path_length'], rel=1e-12)
        assert metrics['control_points'] == len(truth.trajectory.control_points)


def test_the_figures_published_are_the_curves_own(planner, built, default_cell, tmp_path):
    """The file stores no figure: the load verifies every curve and answers with that."""
    path = save_table(built, tmp_path)
    document = json.loads(path.read_text())
    assert document['format'] == 2
    assert not any('verification' in entry for entry in document['entries'])
    loaded = load_table(planner, tmp_path)
    for pair in built.entries:
        answer = loaded.answer(planner, *pair)
        fresh = verify(answer.trajectory, default_cell, answer.start_q, answer.goal_q)
        assert fresh.ok and answer.verification.ratios == fresh.ratios
        assert answer.verification.min_clearance == fresh.min_clearance
        assert answer.verification.proof.certified


def test_a_file_of_the_first_format_is_planned_again(planner, built, tmp_path):
    """Format 1 kept its figures, a NaN among them here: the whole file is refused."""
    path = save_table(built, tmp_path)
    document = json.loads(path.read_text())
    document.pop('format', None)
    for entry in document['entries']:
        entry['verification'] = {'ratios': {'velocity': float('nan')}}
    document['digest'] = digest(document['entries'], document['failures'])
    path.write_text(json.dumps(document))
    with pytest.raises(TableError, match='format 1'):
        load_table(planner, tmp_path)
    assert not load_or_build_table(planner, tmp_path).loaded
    assert load_table(planner, tmp_path).loaded


def test_a_retaught_station_replans_only_its_own_pairs(default_cell, tmp_path, monkeypatch):
    """Moved loadport2: its 4 pairs are planned; the other 8 inherited, each verified."""
    cache = tmp_path / 'cache'
    first = Planner(default_cell, load_or_build(default_cell, cache_dir=cache).roadmap)
    build_and_store_table(first, cache)
    text = default_cell_path().read_text().replace(
        'loadport2: {wafer_center: [0.0, 0.26]', 'loadport2: {wafer_center: [0.005, 0.26]')
    (tmp_path / 'cell.yaml').write_text(text)
    moved = Cell.from_yaml(tmp_path / 'cell.yaml')
    assert moved.digest != default_cell.digest
    second = Planner(moved, load_or_build(moved, cache_dir=cache).roadmap)
    planned, checked = [], []
    plan, verified = second.plan, table_module.verified_entry
    monkeypatch.setattr(second, 'plan', lambda *a, **k: planned.append(a[:2]) or plan(*a, **k))
    monkeypatch.setattr(table_module, 'verified_entry',
                        lambda p, pair, entry: checked.append(pair) or verified(p, pair, entry))
    table = build_and_store_table(second, cache)
    assert set(table.entries) == set(station_pairs(moved)) and not table.failures
    assert all('loadport2' in pair for pair in planned) and len(planned) == 2  # + 2 reversed
    inherited = [pair for pair in station_pairs(moved) if 'loadport2' not in pair]
    assert sorted(checked) == sorted(inherited)  # every inherited entry verified
    assert load_table(second, cache).entries.keys() == table.entries.keys()
    for pair in station_pairs(moved):
        answer = table.answer(second, *pair)
        assert answer.verification.ok and np.array_equal(answer.positions[-1], answer.goal_q)
    # Another robot (a limit changed): nothing is inherited.
    robot = moved.robot
    slower = replace(moved, robot=robot.with_limit_set(replace(robot.limit_set, joints=replace(
        robot.limits, velocity=0.9 * robot.limits.velocity))))
    assert inherited_table(Planner(slower, second.roadmap), cache) is None


def test_an_entry_of_an_unknown_kind_of_curve_is_rejected(planner, built, tmp_path):
    save_table(built, tmp_path)
    document = json.loads(table_path(tmp_path, built.key).read_text())
    document['entries'][0]['trajectory']['kind'] = 'quintic'
    document['digest'] = digest(document['entries'], document['failures'])
    table_path(tmp_path, built.key).write_text(json.dumps(document))
    loaded = load_table(planner, tmp_path)
    pair = tuple(document['entries'][0]['pair'])
    assert pair not in loaded.entries
    assert "unknown kind of curve 'quintic'" in loaded.rejected[pair]
    assert len(loaded.entries) == len(built.entries) - 1


@pytest.fixture(scope='module')
def through_ports(planner):
    """Return the default cell's port pairs planned loaded and empty: {load: table}."""
    return {load: build_table(planner.for_load(load), pairs=port_pairs(planner.cell))
            for load in (LOADED, EMPTY)}


@pytest.mark.slow
def test_the_table_holds_the_moves_through_the_ports_loaded_and_empty(
        planner, through_ports, default_cell, roadmap_cache, tmp_path):
    """Inside one port to inside another, each limit set's own table, stored and loaded."""
    ports = port_pairs(default_cell)
    assert len(ports) == len(station_pairs(default_cell))  # every station has a port here
    assert ('loadport1:inside', 'loadlock2:inside') in ports
    assert table_pairs(default_cell) == station_pairs(default_cell) + ports
    info = roadmap_json(load_or_build(default_cell, cache_dir=roadmap_cache))
    for load, table in through_ports.items():
        assert table.load == load and set(table.entries) == set(ports) and not table.failures
        assert table_key(planner.for_load(load)) == table.key
        save_table(table, tmp_path)
        loaded = load_table(planner.for_load(load), tmp_path)
        assert loaded.loaded and not loaded.rejected and set(loaded.entries) == set(ports)
        # The knot timing does not blend a move into its ways through the ports: each stops
        # at both port mouths (the whole curve's do not: test_port_moves).
        assert all(entry['metrics']['stops'] == 2 for entry in loaded.entries.values())
        for start, goal in ports:
            answer = loaded.answer(planner, start, goal)  # the table's load, whatever asks
            assert answer.load == load and answer.metrics['source'] == 'table'
            assert np.array_equal(answer.start_q, planner.endpoint(start, 'start').configs[
                [elbow for elbow, _ in planner.endpoint(start, 'start').configs].index(
                    answer.branches[0])][1])
            figures = check(planner.for_load(load).cell,
                            plan_json(answer, info, default_cell.robot.joint_names),
                            answer.start_q, answer.goal_q)  # port tolerances every 1 ms
            # Straight by construction: on the axis, on the heading, to rounding.
            assert figures['port_lateral'] < 1e-6 and figures['port_heading'] < 1e-6
    assert through_ports[LOADED].key != through_ports[EMPTY].key  # one file per limit set
    # The service answers a move from the table of its limit set only.
    service = PlanningService(planner, tables=through_ports)
    request = ('loadport1:inside', 'loadlock1:inside')
    for load in (LOADED, EMPTY):
        assert service.holds(*request, load=load)
        assert service.answer(*request, load=load).load == load
    alone = PlanningService(planner, tables={EMPTY: through_ports[EMPTY]})
    assert not alone.holds(*request) and alone.holds(*request, load=EMPTY)
    assert alone.answer(*request).metrics.get('source') != 'table'
    with pytest.raises(ValueError, match='loadport1->loadport2 is not a pair'):
        build_table(planner, pairs=[('loadport1', 'loadport2')])


def test_no_move_through_the_ports_is_slower_than_stopping_at_their_mouths(
        planner, through_ports, default_cell):
    """Each entry against the same move stopping at both port mouths."""
    for load, table in through_ports.items():
        for pair, entry in table.entries.items():
            duration = Trajectory.from_description(entry['trajectory']).duration
            stopping = planner.stop_and_go(*pair, load=load)
            assert stopping.metrics['stops'] == 2 and stopping.verification.ok
            assert duration <= stopping.cycle_time * (1.0 + 1e-9), (load, pair)
    with pytest.raises(PlanningError) as info:
        planner.stop_and_go('loadport1', 'loadlock1')
    assert info.value.code is ErrorCode.INVALID_REQUEST and 'does not stop' in \
        info.value.message


def test_a_port_entry_turned_askew_is_rejected_never_published(
        planner, through_ports, tmp_path):
    """Out of a port the blade turns off its heading: rejected on load."""
    table = through_ports[EMPTY]
    pair = ('loadport1:inside', 'loadlock2:inside')
    save_table(table, tmp_path)
    tamper(table_path(tmp_path, table.key), {pair: 'askew'})
    loaded = load_table(planner.for_load(EMPTY), tmp_path)
    assert pair not in loaded.entries and loaded.answer(planner, *pair) is None
    # A move through ports is its straight ways and a transfer: the way out turned at the
    # mouth is no longer the straight line it names.
    assert re.search(r'the way out of the port: its mouth configuration \[.*\] is not where '
                     r'the straight line puts the arm', loaded.rejected[pair]), \
        loaded.rejected[pair]
    assert set(loaded.entries) == set(table.entries) - {pair}


def test_a_donor_tables_faster_curve_is_taken_only_when_it_verifies(planner, default_cell,
                                                                    default_roadmap):
    """The loaded moves' curves serve the empty table where faster; never the other way."""
    pairs = [('loadport1', 'loadlock2'), ('loadlock2', 'loadport1')]
    fast = build_table(planner.for_load(EMPTY), pairs=pairs)  # knot timing, empty
    slow = Planner(default_cell, default_roadmap, PlannerSettings.paper()).for_load(EMPTY)
    taken = build_table(slow, pairs=pairs, donor=fast)  # the paper's timing is slower
    for pair in pairs:
        answer, donated = taken.answer(slow, *pair), fast.answer(planner, *pair)
        assert answer.metrics['adopted'] and answer.load == EMPTY
        assert answer.cycle_time == donated.cycle_time < slow.plan(*pair).cycle_time
        assert answer.verification.ok
    # The empty curves break the wafer limit: a loaded table never takes them.
    kept = build_table(planner, pairs=pairs, donor=fast)
    for pair in pairs:
        answer = kept.answer(planner, *pair)
        assert 'adopted' not in answer.metrics and answer.load == LOADED
        assert answer.cycle_time > fast.answer(planner, *pair).cycle_time
        assert adopted(planner, fast.answer(planner, *pair)) is None
    # Adopted backwards: from the other's goal to its start, on its branches reversed.
    there = planner.plan(*pairs[0])
    back = adopted(planner.for_load(EMPTY), there, backwards=True)
    assert (back.start.label, back.goal.label) == pairs[1] and back.load == EMPTY
    assert back.branches == there.branches[::-1] and back.metrics['reversed']
    assert np.array_equal(back.positions[0], there.goal_q)
    assert np.array_equal(back.positions[-1], there.start_q)


def test_a_station_given_by_joint_angles_is_answered_from_the_table(roadmap_cache):
    """Its entries name no elbow branch (None): answered, and taken by the empty table."""
    from conftest import CELL_FILES
    cell = Cell.from_yaml(CELL_FILES['pillar'])
    assert 'joints' in cell.stations['loadlock2'].spec
    planner = Planner(cell, load_or_build(cell, cache_dir=roadmap_cache).roadmap)
    pairs = [('loadport1', 'loadlock2'), ('loadport1:inside', 'loadlock2:inside')]
    loaded = build_table(planner, pairs=pairs)
    for pair in pairs:
        answer = loaded.answer(planner, *pair)
        assert answer.verification.ok and answer.branches[1] is None
        assert answer.metrics['control_points'] > 0
    empty = build_table(planner.for_load(EMPTY), pairs=pairs, donor=loaded)
    assert set(empty.entries) == set(pairs) and not empty.failures
