"""``wafer-roadmap``: statistics, JSON, cache hits, progress, plots and exit codes."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cli.common import run
from wafer_planner_ros.cli.roadmap import main
from wafer_planner_ros.geometry.planar import cross2
from wafer_planner_ros.plotting import plot_roadmap
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings


def _run(capsys, *argv):
    code = run(main, list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_twice_with_the_same_seed_gives_the_same_hash_and_a_cache_hit(tmp_path, capsys):
    args = ['--nodes', '300', '--seed', '5', '--cache-dir', str(tmp_path), '--json', '-']
    code, out, err = _run(capsys, *args)
    assert code == 0
    first = json.loads(out)
    assert first['cache_hit'] is False and 'building roadmap: 300/300 nodes' in err
    code, out, err = _run(capsys, *args)
    second = json.loads(out)
    assert second['cache_hit'] is True and second['hash'] == first['hash']
    assert 'building roadmap' not in err
    assert first['nodes'] == second['nodes'] >= 300
    assert first['stations_connected'] is True
    assert set(first['samplers']) == {'uniform', 'gaussian', 'bridge'}


@pytest.mark.slow
def test_text_output_and_plot(tmp_path, capsys):
    png = tmp_path / 'roadmap.png'
    code, out, _ = _run(capsys, '--nodes', '300', '--no-cache', '--plot', str(png))
    assert code == 0
    for label in ('nodes', 'edges', 'components', 'stations', 'samplers', 'build time',
                  'cache', 'hash'):
        assert f'\n{label}' in '\n' + out
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000


@pytest.mark.slow
def test_the_roadmap_figure_names_joints_stations_and_branches_as_the_cell_does(tmp_path):
    text = default_cell_path().read_text()
    assert text.count('joint_names: [shoulder, elbow, wrist]') == 1
    cell = Cell.from_text(text.replace('joint_names: [shoulder, elbow, wrist]',
                                       'joint_names: [waist, arm, hand]'), 'renamed.yaml')
    roadmap = load_or_build(cell, RoadmapSettings(nodes=300), cache_dir=None).roadmap
    figure = plot_roadmap(cell, roadmap, tmp_path / 'roadmap.png')
    drawing, joints = figure.axes
    assert (joints.get_xlabel(), joints.get_ylabel(), joints.get_zlabel()) == (
        'waist (rad)', 'arm (rad)', 'hand (rad)')
    texts = drawing.texts
    assert {t.get_text() for t in texts} == set(cell.stations) | {'elbow right', 'elbow left'}
    # Each branch is named at its elbow, in words that match what the drawing shows: seen
    # from above, the elbow right or left of the line from the shoulder to the wrist.
    base = cell.robot.base
    elbows = []
    for station in cell.stations.values():
        for config in station.configs:
            _, elbow, wrist, _ = cell.robot.arm.joint_points(config.q)
            side = 'elbow right' if cross2(wrist - base, elbow - base) < 0 else 'elbow left'
            elbows.append((tuple(np.round(elbow, 9)), side))
    named = [(tuple(np.round(t.xy, 9)), t.get_text()) for t in texts
             if t.get_text().startswith('elbow ')]
    assert sorted(named) == sorted(elbows)
    assert {side for _, side in elbows} == {'elbow right', 'elbow left'}


def test_json_file_and_test_cell(tmp_path, capsys):
    out_file = tmp_path / 'stats.json'
    cell = os.path.join(os.path.dirname(__file__), '..', 'support', 'cells',
                        'notched.yaml')
    code, _, _ = _run(capsys, '--cell', cell, '--nodes', '300', '--no-cache', '--json',
                      str(out_file))
    assert code == 0
    stats = json.loads(out_file.read_text())
    assert stats['cell'] == 'efem-notched' and stats['cache_status'] == 'disabled'


def test_bad_cell_file_exits_2_naming_the_key(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('cell: {name: x, boundary: [[0, 0], [1, 0], [1, 1]]}\nrobot: {}\n'
                   'stations: {}\n')
    result = subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.roadmap',
                             '--cell', str(bad), '--no-cache'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert 'robot.base: missing' in result.stderr


def test_bad_node_count_exits_2(capsys):
    code, _, err = _run(capsys, '--nodes', '0', '--no-cache')
    assert code == 2 and '--nodes' in err


def test_replay_leaves_out_exactly_the_answers_a_time_budget_shaped():
    from wafer_planner_ros.cli.replay import Replayer
    from wafer_planner_ros.recording.queries import Query, Result
    from wafer_planner_ros.service.planning import within_budget

    def query(kind, values, budget=None):
        parameters = {} if budget is None else {'planning.optimise_budget': budget}
        return Query(number=0, kind=kind, topic='', received_ns=0, data=b'', request=None,
                     result=Result(0, 'r', '', values, 0), parameters=parameters)

    def _budgeted(recorded):  # what the replay asks of the planning service
        return within_budget(recorded.kind == 'station', recorded.result.values,
                             recorded.parameters.get('planning.optimise_budget', 0.0))
    # A successful answer says which budget it had.
    assert _budgeted(query('joint', {'code': 'OK', 'budget': '0.2'}, budget=0.0))
    assert not _budgeted(query('joint', {'code': 'OK', 'budget': '0'}, budget=0.2))
    # An error does not: a joint request planned with a budget in force counts as budgeted;
    # a station request's never does (what fails it, an unknown station or no path, does
    # not depend on the budget).
    assert _budgeted(query('joint', {'code': 'NO_PATH'}, budget=0.2))
    assert not _budgeted(query('joint', {'code': 'NO_PATH'}, budget=0.0))
    assert not _budgeted(query('station', {'code': 'NO_PATH'}, budget=0.2))
    assert not _budgeted(query('joint', {'code': 'OK', 'budget': 'nan?'}))
    # Replaying one gives no answer to compare (and needs no roadmap to say so).
    assert Replayer(None, quiet=True).answer(
        query('joint', {'code': 'OK', 'budget': '0.2'})) == ('', None)
