"""The node's station table: planned in the worker at start-up, then answering station pairs."""

from dataclasses import replace
import shutil

from diagnostic_msgs.msg import DiagnosticStatus
from node_harness import values, wait_for
import numpy as np
import pytest
from tampered import tamper

from wafer_planner_ros.cell.limits import EMPTY, LOADED, LOADS
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.optima_store import load_optima, optima_path
from wafer_planner_ros.service.settings import settings_from
from wafer_planner_ros.service.table import build_table, load_table, table_key
from wafer_planner_ros.service.table import port_pairs, table_pairs
from wafer_planner_ros.service.table_store import save_table, table_path


@pytest.mark.slow
def test_station_requests_are_answered_from_the_table_the_node_planned(
        roadmap_cache, tmp_path, default_cell):
    from node_harness import Harness  # ROS only for the tests that use it
    cache = _roadmaps_only(roadmap_cache, tmp_path)  # the roadmap cached, the table not yet
    assert not list(cache.glob('table-*.json'))
    node = Harness({'roadmap.cache_dir': str(cache), 'planning.station_table': True,
                    'planning.station_table_ports': False,
                    'planning.optimise_budget': 0.2, 'planning.timeout': 30.0})
    try:
        pairs = len(station_pairs(default_cell))
        wait_for(lambda: (lambda s: s['station_table'] == pairs
                          and s['busy_with'] != 'station_table')(node.status()), 300)
        # The table the node stored is the one it answers from.
        roadmap = load_or_build(default_cell, cache_dir=cache).roadmap
        stored_planner = Planner(default_cell, roadmap, PlannerSettings(method='whole-curve'))
        stored = load_table(stored_planner, cache)
        node.send_stations({'id': 't1', 'from': 'loadport1', 'to': 'loadlock2'})
        result = node.result('t1')
        assert result.level == DiagnosticStatus.OK, result.message
        got = values(result)
        assert got['source'] == 'table' and got['method'] == 'whole-curve'
        assert got['certified'] == 'True'
        entry = stored.entries[('loadport1', 'loadlock2')]
        knots = np.asarray(entry['trajectory']['knots'])
        assert float(got['cycle_time']) == pytest.approx(knots[-1] - knots[0], rel=1e-12)
        # A joint request is optimised within its budget, never from the table.
        start = default_cell.stations['loadport1'].configs[0].q
        node.send_joints('t2', start, start + np.array([0.3, -0.2, 0.1]))
        got = values(node.result('t2'))
        assert got['code'] == 'OK', got
        assert got['source'] == 'planned' and got['method'] == 'whole-curve'
        assert float(got['budget']) == pytest.approx(0.2)
        # Near a station pair the table holds: started from its curve, kept as an optimum.
        curve = stored.entries[('loadport1', 'loadlock2')]['trajectory']['control_points']
        node.send_joints('t3', *(_near(stored_planner, q, role) for q, role in (
            (curve[0], 'start'), (curve[-1], 'goal'))))
        got = values(node.result('t3'))
        assert got['code'] == 'OK' and got['from_optimum'] == 'True', got
        assert got['certified'] == 'True'
        assert float(got['cycle_time']) == pytest.approx(knots[-1] - knots[0], rel=0.05)
    finally:
        node.close()
    # Stored when the node stopped: the table's curves and the answers, each verified again
    # on load, all passing.
    again = Planner(default_cell, roadmap, PlannerSettings(method='whole-curve'))
    loaded = load_optima(again, cache)
    assert loaded.rejected == () and loaded.kept >= pairs + 2
    assert loaded.path == optima_path(cache, table_key(again))


def _near(planner, q, role: str) -> np.ndarray:
    """Return joint angles 0.03-0.05 rad from ``q`` on each joint, a valid end of a request."""
    from wafer_planner_ros.errors import PlanningError
    for signs in np.array(np.meshgrid(*[[1.0, -1.0]] * 3)).reshape(3, -1).T:
        moved = np.asarray(q, float) + signs * np.array([0.03, 0.04, 0.05])
        try:
            planner.endpoint(moved, role)  # outside every port, clear of the walls
        except PlanningError:
            continue
        return moved
    raise AssertionError(f'no valid end near {q}')


@pytest.mark.slow
def test_a_tampered_entry_is_never_published_and_is_counted(roadmap_cache, tmp_path,
                                                            default_cell, default_roadmap):
    """Both directions of a pair edited in the cached table: planned, never sent as stored."""
    from node_harness import Harness  # ROS only for the tests that use it
    cache = _roadmaps_only(roadmap_cache, tmp_path)
    # The node's table (whole-curve), its curves from the corridor method: any verified
    # curve will do, and these take milliseconds.
    whole = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    table = replace(build_table(Planner(default_cell, default_roadmap)), key=table_key(whole))
    save_table(table, cache)
    there, back = ('loadport1', 'loadlock2'), ('loadlock2', 'loadport1')
    edited = tamper(table_path(cache, table.key), {there: 'halved', back: 'shifted'})
    node = Harness({'roadmap.cache_dir': str(cache), 'planning.station_table': True,
                    'planning.station_table_ports': False,
                    'planning.timeout': 30.0})
    try:
        # Loaded before the node took over: the two entries rejected at once, so that even
        # the first requests are planned (or answered once planned again), never as stored.
        for number, (start, goal) in enumerate((there, back, there)):
            if number == 2:  # once planned again, from the table
                wait_for(lambda: (lambda s: s['station_table'] == len(station_pairs(
                    default_cell)) and s['busy_with'] != 'station_table')(node.status()), 120)
            node.send_stations({'id': f't{number}', 'from': start, 'to': goal})
            result = node.result(f't{number}')
            assert result.level == DiagnosticStatus.OK, result.message
            got = values(result)
            assert got['certified'] == 'True'
            assert all(float(v) <= 1.0 for k, v in got.items() if k.startswith('ratio_')), got
            stored_duration = edited[(start, goal)]['trajectory']['knots'][-1]
            assert float(got['cycle_time']) != pytest.approx(stored_duration, rel=1e-9)
        assert got['source'] == 'table'
        assert node.status()['station_table_rejected'] == 2
        health = values(node.health(len(node.diagnostics)))
        assert health['station_table_rejected'] == '2'
        stored = load_table(whole, cache)  # planned again and stored: nothing to reject
        assert not stored.rejected and len(stored) == len(station_pairs(default_cell))
    finally:
        node.close()


@pytest.mark.slow
def test_the_moves_through_the_ports_are_answered_from_the_tables_loaded_and_empty(
        roadmap_cache, tmp_path, default_cell, default_roadmap):
    """Both limit sets' tables cached whole: every pair, retracted and port to port, at once."""
    from node_harness import Harness  # ROS only for the tests that use it
    cache = _roadmaps_only(roadmap_cache, tmp_path)
    # The node's tables (whole-curve), their curves from the corridor method (milliseconds;
    # verified on load like any other).
    whole = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    corridor = Planner(default_cell, default_roadmap)
    pairs = table_pairs(default_cell)
    for load in LOADS:
        table = build_table(corridor.for_load(load), pairs=pairs)
        save_table(replace(table, key=table_key(whole.for_load(load))), cache)
    node = Harness({'roadmap.cache_dir': str(cache), 'planning.station_table': True,
                    'planning.timeout': 30.0})
    try:
        status = node.status()
        assert status['station_table'] == status['station_table_empty'] == len(pairs)
        assert status['busy_with'] != 'station_table'  # nothing left to plan
        for number, load in enumerate(LOADS):
            node.send_stations({'id': f'p{number}', 'from': 'loadport1:inside',
                                'to': 'loadlock2:inside', 'load': load})
            result = node.result(f'p{number}')
            assert result.level == DiagnosticStatus.OK, result.message
            got = values(result)
            assert got['source'] == 'table' and got['load'] == load, got
            assert got['certified'] == 'True'
    finally:
        node.close()


def test_the_tables_are_planned_group_by_group_each_pair_stored_and_published(
        tmp_path, default_cell, default_roadmap):
    """A pair is answered from the table as soon as it is planned; a restart goes on."""
    from wafer_planner_ros.node.serving import build_station_tables, table_groups
    from wafer_planner_ros.node.serving import table_to_plan
    ports = settings_from({'roadmap.cache_dir': str(tmp_path)})
    whole = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    stations, through = station_pairs(default_cell), port_pairs(default_cell)
    assert table_groups(whole, ports) == [
        (LOADED, stations), (EMPTY, stations), (LOADED, through), (EMPTY, through)]
    settings = replace(ports, station_table_ports=False)
    assert table_groups(whole, settings) == [(LOADED, stations)]
    # Half the table cached (a build stopped half-way): only the other half is planned.
    half = build_table(Planner(default_cell, default_roadmap), pairs=stations[:6])
    save_table(replace(half, key=table_key(whole)), tmp_path)
    cached = {LOADED: load_table(whole, tmp_path)}
    assert table_to_plan(whole, cached, settings) and len(cached[LOADED]) == 6
    published = []

    def publish(load, table):
        stored = load_table(whole.for_load(load), tmp_path)  # on disk before it is used
        published.append((load, len(table), len(stored)))

    build_station_tables(whole, settings, _Quiet(), cached, publish)
    assert published == [(LOADED, 6 + k, 6 + k) for k in range(1, 7)]
    assert not table_to_plan(whole, {LOADED: load_table(whole, tmp_path)}, settings)


class _Quiet:
    def info(self, text):
        pass

    warning = info


def test_planning_the_tables_stops_at_the_next_pair_when_asked(tmp_path, default_cell,
                                                               default_roadmap):
    """A rebuild or a stop ends the planning once the pair being planned is stored."""
    from wafer_planner_ros.node.serving import build_station_tables, table_to_plan
    settings = replace(settings_from({'roadmap.cache_dir': str(tmp_path)}),
                       station_table_ports=False)
    whole = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    published = []
    build_station_tables(whole, settings, _Quiet(), {}, lambda load, table: published.append(
        len(table)), stopped=lambda: len(published) == 2)
    assert published == [1, 2]
    stored = load_table(whole, tmp_path)
    assert len(stored) == 2 and table_to_plan(whole, {LOADED: stored}, settings)


@pytest.mark.slow
def test_a_rebuild_while_the_table_is_planned_is_queued_and_the_table_finished_after_it(
        roadmap_cache, tmp_path, default_cell, monkeypatch):
    """Never refused: the table's planning stops after its pair, the load runs again."""
    import threading
    from node_harness import Harness  # ROS only for the tests that use it
    from wafer_planner_ros.node import loader, serving
    cache = _roadmaps_only(roadmap_cache, tmp_path)
    release, planned, loads = threading.Event(), [], []
    build_and_store_table, load_or_build = serving.build_and_store_table, loader.load_or_build

    def held(*args, **kwargs):  # the first pair is planned until the test has asked
        planned.append(len(loads))
        release.wait(120)
        return build_and_store_table(*args, **kwargs)

    def counted(*args, **kwargs):
        loads.append(1)
        return load_or_build(*args, **kwargs)

    monkeypatch.setattr(serving, 'build_and_store_table', held)
    monkeypatch.setattr(loader, 'load_or_build', counted)
    node = Harness({'roadmap.cache_dir': str(cache), 'planning.station_table': True,
                    'planning.station_table_ports': False, 'planning.timeout': 30.0})
    try:
        wait_for(lambda: planned, 60)
        assert node.status()['busy_with'] == 'station_table'
        asked = node.call('rebuild_roadmap')
        assert asked.success and 'queued' in asked.message, asked.message
        release.set()
        pairs = len(station_pairs(default_cell))
        wait_for(lambda: (lambda s: s['busy_with'] is None and s['station_table'] == pairs)(
            node.status()), 300)
        # One pair planned on the first load; the rebuild's load planned the other eleven.
        assert len(loads) == 2 and planned.count(1) == 1 and planned.count(2) == pairs - 1
        assert not node.status()['rebuild_failed']
    finally:
        release.set()
        node.close()


def _roadmaps_only(roadmap_cache, tmp_path):
    """Isolate DDS in ``tmp_path``; return a copy of the session's cache without its tables."""
    from node_harness import isolate_dds  # ROS only for the tests that use it
    isolate_dds(tmp_path)
    cache = tmp_path / 'cache'
    shutil.copytree(roadmap_cache, cache, ignore=shutil.ignore_patterns('table-*'))
    return cache
