"""
``wafer-study``: study files, variants, the results directory, the executors and the CLI.

The end-to-end tests vary a cell with one loadport and one loadlock (a variant in a few
seconds) and run the real planner in worker processes.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest
from study_tasks import flaky
from wafer_planner_ros.cell.document import read_cell_file, read_cell_yaml
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.study import parameters
from wafer_planner_ros.study.evaluate import evaluate
from wafer_planner_ros.study.executors import LocalExecutor
from wafer_planner_ros.study.results import read_rows, Results, ResultsError, without_cost
from wafer_planner_ros.study.runner import run_variants
from wafer_planner_ros.study.spec import Study, StudyError, Variant
import yaml

CELLS = Path(__file__).resolve().parents[1] / 'support' / 'cells'
EXAMPLE = default_cell_path().parent / 'example_study.yaml'


def base_document() -> dict:
    return read_cell_yaml(read_cell_file(default_cell_path()), 'default')


def small_study(tmp_path: Path) -> Path:
    """Write a study of six variants of the two-station cell, one of them invalid."""
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump({'study': {
        'name': 'small', 'base': str(CELLS / 'two_stations.yaml'),
        'roadmap': {'nodes': 300, 'seed': 0},
        'method': 'knot-timing',  # milliseconds a move: what is checked is the bookkeeping
        'grid': {'robot.link_lengths[0]': [0.35, 0.37], 'boundary.width': [1.6, 1.8]},
        'list': [{'robot.link_lengths[0]': 0.30}],  # loadport2 out of reach: invalid
    }}))
    return path


def study_cli(*args, **kwargs):
    return subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.study', *map(str, args)],
                          capture_output=True, text=True, timeout=900, **kwargs)


# ----------------------------------------------------------------- parameters and files

def test_a_key_path_parameter_changes_that_number_only():
    base = base_document()
    varied = parameters.apply(base, {'robot.link_lengths[0]': 0.4,
                                     'stations.loadport1.heading': 1.5})
    assert varied['robot']['link_lengths'] == [0.4, 0.36, 0.22]
    assert varied['stations']['loadport1']['heading'] == 1.5
    assert base['robot']['link_lengths'][0] == 0.36  # the base is untouched
    varied['robot']['link_lengths'] = base['robot']['link_lengths']
    varied['stations']['loadport1']['heading'] = base['stations']['loadport1']['heading']
    assert varied == base


def test_moving_a_station_along_its_wall_moves_its_pocket_and_nothing_else():
    base = base_document()
    varied = parameters.apply(base, {'stations.loadlock1.x': -0.45})
    assert varied['stations']['loadlock1']['wafer_center'] == pytest.approx([-0.45, -0.26])
    moved = [(a, b) for a, b in zip(base['cell']['boundary'], varied['cell']['boundary'])
             if a != b]
    assert sorted(round(a[0], 3) for a, _ in moved) == [-0.66, -0.66, -0.34, -0.34]
    assert all(b[0] == pytest.approx(a[0] + 0.05) and b[1] == pytest.approx(a[1], abs=1e-6)
               for a, b in moved)
    Cell.from_dict(varied)  # still a valid cell: the pocket came along


def test_the_enclosure_resizes_by_its_walls_and_the_footprint_follows():
    base = base_document()
    assert parameters.value(base, 'boundary.width') == pytest.approx(1.7)
    wide = parameters.apply(base, {'boundary.width': 1.9})
    assert parameters.value(wide, 'boundary.width') == pytest.approx(1.9)
    assert parameters.footprint(wide) == pytest.approx(1.9 * 1.54)
    deep = parameters.apply(base, {'boundary.depth': 1.64})
    assert parameters.value(deep, 'boundary.depth') == pytest.approx(1.64)
    assert deep['stations']['loadport1']['wafer_center'][1] == pytest.approx(0.31)
    assert deep['stations']['loadlock1']['wafer_center'][1] == pytest.approx(-0.31)
    for document in (wide, deep):
        Cell.from_dict(document)


@pytest.mark.parametrize('name, words', [
    ('robot.link_lengths[5]', 'has no robot.link_lengths[5]'),
    ('robot.joint_names[0]', 'not a number'),
    ('stations.loadport9.x', "no station 'loadport9'"),
    ('robot..base', 'not a key path')])
def test_a_parameter_that_names_nothing_is_refused_by_name(tmp_path, name, words):
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump({'study': {'base': str(default_cell_path()),
                                              'grid': {name: [1.0]}}}))
    with pytest.raises(StudyError, match='study.grid') as caught:
        Study.from_file(path)
    assert words in str(caught.value)


@pytest.mark.parametrize('study, words', [
    ({'grid': {'robot.link_lengths[0]': []}}, 'non-empty list'),
    ({'random': {'samples': 3}}, 'need study.ranges'),
    ({'ranges': {'robot.link_lengths[0]': [0.4, 0.3]}}, 'low must be below high'),
    ({'method': 'fast'}, 'study.method'),
    ({'roadmap': {'nodes': -1}}, 'study.roadmap.nodes'),
    ({'colour': 'red'}, 'study.colour: unknown key'),
    ({'base': 'nowhere.yaml'}, 'study.base')])
def test_a_bad_study_file_is_refused_naming_the_key(study, words):
    with pytest.raises(StudyError, match=words.replace('.', r'\.')):
        Study.from_dict({'study': {'base': str(default_cell_path()), **study}}
                        if 'base' not in study else {'study': study}, Path('/nowhere/s.yaml'))


def test_the_variants_are_the_base_the_grid_the_list_and_seeded_samples_each_cell_once():
    study = Study.from_dict({'study': {
        'grid': {'robot.link_lengths[0]': [0.35, 0.36], 'boundary.width': [1.6, 1.7]},
        'list': [{'robot.link_lengths[0]': 0.36}],  # the base cell again
        'random': {'samples': 3, 'seed': 7},
        'ranges': {'robot.link_lengths[1]': [0.3, 0.4]}}})
    variants = study.variants()
    assert variants[0].values == {}
    assert [v.values for v in variants[1:4]] == [
        {'robot.link_lengths[0]': 0.35, 'boundary.width': 1.6},
        {'robot.link_lengths[0]': 0.35, 'boundary.width': 1.7},
        {'robot.link_lengths[0]': 0.36, 'boundary.width': 1.6}]
    assert len(variants) == 7  # (0.36, 1.7) and the listed one are the base cell
    assert [v.index for v in variants] == list(range(7))
    again = Study.from_dict({'study': {'random': {'samples': 3, 'seed': 7},
                                       'ranges': {'robot.link_lengths[1]': [0.3, 0.4]}}})
    assert [v.key for v in again.variants()[1:]] == [v.key for v in variants[4:]]


def test_the_example_study_reads():
    study = Study.from_file(EXAMPLE)
    assert len(study.variants()) == 6
    assert study.method == 'whole-curve'


@pytest.mark.slow
def test_a_variant_runs_the_motion_the_node_runs_by_default():
    # The default method is the node's: its moves through the ports do not stop at the
    # mouths, and the stop-and-go cycle they are compared with does, at both, each way.
    study = Study.from_dict({'study': {'base': str(CELLS / 'two_stations.yaml'),
                                       'roadmap': {'nodes': 300, 'seed': 0}}})
    assert study.method == 'whole-curve'
    variant = study.variants()[0]
    row = evaluate(variant.key, variant.index, variant.values, variant.document,
                   study.nodes, study.seed, study.method)
    assert row['status'] == 'planned', row['reason']
    (swap,) = row['swaps']
    assert swap['cycle'] < swap['stop_and_go']
    assert row['swap_cycle'] == swap['cycle']


# ----------------------------------------------------------------- the results directory

ABOUT = {'name': 'x', 'signature': 'aaaa'}


def test_a_directory_in_use_or_of_another_study_is_refused(tmp_path):
    with Results(tmp_path, ABOUT):
        with pytest.raises(ResultsError, match='being written by another study'):
            Results(tmp_path, ABOUT)
    with pytest.raises(ResultsError, match='another study'):
        Results(tmp_path, {'name': 'y', 'signature': 'bbbb'})
    Results(tmp_path, ABOUT).close()  # free again


def test_a_cut_off_last_line_is_dropped_and_any_other_bad_line_refused(tmp_path):
    with Results(tmp_path, ABOUT) as results:
        results.add({'variant': 'v1', 'index': 1})
        results.add({'variant': 'v0', 'index': 0})
    path = tmp_path / 'results.jsonl'
    with open(path, 'a') as stream:
        stream.write('{"variant": "v2", "ind')
    said = []
    with Results(tmp_path, ABOUT, said.append) as results:
        assert set(results.rows) == {'v0', 'v1'} and 'cut off' in said[0]
        results.sort(lambda row: (row['index'],))
    assert [r['variant'] for r in read_rows(tmp_path)] == ['v0', 'v1']
    path.write_text('{"variant": "v0"}\nnot json\n')
    with pytest.raises(ResultsError, match='line 2'):
        Results(tmp_path, ABOUT)
    assert path.read_text() == '{"variant": "v0"}\nnot json\n'  # left as it was


# ----------------------------------------------------------------- executors and retries

def test_a_dead_worker_s_variant_is_retried_and_one_failing_twice_is_recorded(tmp_path):
    study = Study.from_dict({'study': {}})
    marks = tmp_path / 'marks'
    marks.mkdir()
    variants = [Variant(key, n, {'n': n}, {}) for n, key in
                enumerate(['ok0', 'die1', 'bad2', 'ok3', 'die4'])]
    executor = LocalExecutor(2, flaky)
    original = executor.submit
    executor.submit = lambda key, payload: original(key, {**payload, 'marks': str(marks)})
    try:
        with Results(tmp_path / 'out', ABOUT) as results:
            run_variants(study, variants, executor, results)
    finally:
        executor.close()
    rows = {r['variant']: r for r in read_rows(tmp_path / 'out')}
    assert set(rows) == {v.key for v in variants}
    assert rows['die1']['status'] == rows['die4']['status'] == 'planned'  # the second time
    assert rows['bad2']['status'] == 'failed'
    assert rows['bad2']['reason'].count('cannot be evaluated') == 2
    assert {p.name for p in marks.iterdir()} == {'die1', 'die4'}


# ----------------------------------------------------------------- end to end

@pytest.fixture(scope='module')
def uninterrupted(tmp_path_factory):
    """Run the small study on the local cores, once for the module."""
    folder = tmp_path_factory.mktemp('study')
    done = study_cli(small_study(folder), '--out', folder / 'out')
    return folder, done


@pytest.mark.slow
def test_a_study_plans_every_variant_and_records_the_invalid_one(uninterrupted):
    folder, done = uninterrupted
    assert done.returncode == 0, done.stderr
    rows = read_rows(folder / 'out')
    assert [r['index'] for r in rows] == list(range(6))  # in the study's order
    by_status = {}
    for row in rows:
        by_status.setdefault(row['status'], []).append(row)
    assert len(by_status['invalid']) == 1
    assert 'unreachable' in by_status['invalid'][0]['reason']
    assert len(by_status['planned']) == 5
    for row in by_status['planned']:
        assert row['swap_cycle'] > 0 and row['wafers_per_hour'] == pytest.approx(
            3600 / row['swap_cycle'])
        assert row['min_clearance'] > 0 and len(row['peak_jerk']) == 3
        assert [(p['from'], p['to']) for p in row['pairs']] == [
            ('loadport2', 'loadlock1'), ('loadlock1', 'loadport2')]
        assert row['swaps'][0]['cycle'] == row['swap_cycle']
    assert 'study small: 6 variants: 5 planned' in done.stdout
    assert '/6 variants' in done.stderr and 'left' in done.stderr  # progress with the time left


@pytest.mark.slow
def test_a_killed_study_resumes_with_only_the_missing_variants_and_the_same_file(
        uninterrupted, tmp_path):
    folder, done = uninterrupted
    out = tmp_path / 'out'
    study = small_study(tmp_path)
    first = subprocess.Popen([sys.executable, '-m', 'wafer_planner_ros.cli.study', str(study),
                              '--out', str(out), '--workers', '1'],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while len(read_rows(out)) < 2 and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.2)
    second = study_cli(study, '--out', out)  # meanwhile: refused, not interleaved
    assert second.returncode == 2 and 'being written by another study' in second.stderr
    first.send_signal(signal.SIGKILL)
    first.communicate()
    held = len(read_rows(out))
    assert 2 <= held < 6
    resumed = study_cli(study, '--out', out)
    assert resumed.returncode == 0, resumed.stderr
    assert f'6 variants, {held} already in' in resumed.stderr
    assert [without_cost(r) for r in read_rows(out)] == \
        [without_cost(r) for r in read_rows(folder / 'out')]


@pytest.mark.slow
def test_the_report_lists_the_best_variants_and_draws_three_figures(uninterrupted):
    folder, _ = uninterrupted
    report = study_cli('--report', folder / 'out', '--best', '3')
    assert report.returncode == 0, report.stderr
    assert 'base cell:' in report.stdout and 'invalid:' in report.stdout
    assert len([line for line in report.stdout.splitlines()
                if line[:3].strip().isdigit()]) == 3
    for name in ('heatmap.png', 'pareto.png', 'best.png'):
        assert (folder / 'out' / 'figures' / name).stat().st_size > 10_000


@pytest.mark.slow
def test_a_search_runs_its_trials_into_the_same_results(tmp_path):
    pytest.importorskip('optuna')
    study = small_study(tmp_path)
    text = yaml.safe_load(study.read_text())
    text['study']['ranges'] = {'robot.link_lengths[0]': [0.35, 0.37],
                               'stations.loadlock1.x': [-0.52, -0.46]}
    study.write_text(yaml.safe_dump(text))
    done = study_cli(study, '--out', tmp_path / 'out', '--search', '3')
    assert done.returncode == 0, done.stderr
    rows = read_rows(tmp_path / 'out')
    assert [r.get('trial') for r in rows] == [None, 1, 2, 3]
    assert 'search: the best of 3 trials' in done.stdout
    again = study_cli(study, '--out', tmp_path / 'out', '--search', '3')  # nothing new
    assert again.returncode == 0 and 'every variant is in the results' in again.stderr
    assert [without_cost(r) for r in read_rows(tmp_path / 'out')] == \
        [without_cost(r) for r in rows]


@pytest.mark.slow
def test_the_same_study_on_a_local_ray_cluster_gives_the_same_rows(uninterrupted, tmp_path):
    pytest.importorskip('ray')
    folder, _ = uninterrupted
    port = 20000 + os.getpid() % 20000
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED='0')
    temp = Path(os.path.realpath('/tmp')) / f'ray{os.getpid()}'
    head = subprocess.Popen(
        [Path(sys.executable).parent / 'ray', 'start', '--head', '--block',
         f'--port={port}', '--num-cpus=1', '--include-dashboard=false',
         f'--temp-dir={temp}', '--object-store-memory=100000000', '--node-ip-address=127.0.0.1'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    worker = None
    try:
        worker = subprocess.Popen(
            [Path(sys.executable).parent / 'ray', 'start', '--block',
             f'--address=127.0.0.1:{port}', '--num-cpus=1', '--node-ip-address=127.0.0.1',
             '--object-store-memory=100000000'],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 180  # until both nodes have joined: 2 CPUs
        while '/2.0 CPU' not in subprocess.run(
                [Path(sys.executable).parent / 'ray', 'status', f'--address=127.0.0.1:{port}'],
                env=env, capture_output=True, text=True, timeout=60).stdout:
            assert time.monotonic() < deadline and head.poll() is None, 'no Ray cluster'
            time.sleep(1)
        done = study_cli(small_study(tmp_path), '--out', tmp_path / 'out', '--ray',
                         f'127.0.0.1:{port}', env=env)
        assert done.returncode == 0, done.stdout + done.stderr
        assert '(2 CPUs)' in done.stderr  # the head and the second node
        rows = read_rows(tmp_path / 'out')
        assert [without_cost(r) for r in rows] == \
            [without_cost(r) for r in read_rows(folder / 'out')]
        assert len({r['cost']['worker'] for r in rows}) >= 2
    finally:
        for process in (worker, head):
            if process is not None:
                process.send_signal(signal.SIGTERM)
                try:
                    process.communicate(timeout=60)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.communicate()


def test_a_ray_address_where_nothing_answers_is_refused_at_once(tmp_path):
    pytest.importorskip('ray')
    done = study_cli(small_study(tmp_path), '--out', tmp_path / 'out', '--ray', '127.0.0.1:1')
    assert done.returncode == 2 and 'no Ray cluster answers at 127.0.0.1:1' in done.stderr
