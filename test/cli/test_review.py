"""``wafer-review``: a figure per query and an index page, from a recording made here."""

from datetime import datetime, timedelta, timezone
import json
import math
from pathlib import Path
import re
import time

from matplotlib.image import imread
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.cli.common import EXIT_OK, EXIT_USAGE, recorded_queries, run
from wafer_planner_ros.cli.review import main, render
from wafer_planner_ros.cli.review_index import THUMBNAIL_WIDTH
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.node import messages
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.recording.bag import Topic
from wafer_planner_ros.service import cdr

NODE = '/wafer_planner'
STATION, TRAJECTORY, RESULT = (f'{NODE}/{name}' for name in
                               ('plan_station_request', 'trajectory', 'result'))
MARKERS = f'{NODE}/roadmap_markers'
TOPICS = [Topic(STATION, 'std_msgs/msg/String'),
          Topic(TRAJECTORY, 'trajectory_msgs/msg/JointTrajectory'),
          Topic(RESULT, 'diagnostic_msgs/msg/DiagnosticStatus'),
          Topic(MARKERS, 'visualization_msgs/msg/MarkerArray')]
SPECIAL_ID = '<b>&"$x$'
"""A request id that HTML and matplotlib's mathtext would both misread."""
IN_THE_WALL = [-0.807004, 2.375021, 0.002779]
"""The wafer at (0.25, 0.32), between two pockets: 20 mm into the loadport wall, nothing
else."""
REQUESTS = [('q1', 'loadport1', 'loadlock1'),
            (SPECIAL_ID, 'loadlock1', 'loadport2'),
            ('q3', 'loadport1', 'nowhere'),
            ('', None, None),
            ('q5', IN_THE_WALL, 'loadlock1')]
"""(id, from, to) as a cell controller sent them; None: a request that is not JSON."""
PLANNED, REFUSED = (1, 2), (3, 4, 5)
"""The query numbers that have a trajectory, and those refused."""


def record(parent: Path, cell, roadmap, requests, crash: bool = False) -> Path:
    """
    Record under ``parent`` with the node's own recording, as the node does; return the bag.

    First the roadmap load, then each request with its answer. ``crash``: the last request
    is not answered and the file is left without its summary and footer, as when the node
    is killed.
    """
    planner = Planner(cell, roadmap)
    recording = NodeRecording('wafer_planner', TOPICS, MARKERS, print)
    bag = recording.start(parent)
    recording.loaded(Loaded(default_cell_path().read_bytes(), {
        'cell': cell.name, 'cell_file': str(default_cell_path()), 'roadmap_hash': roadmap.digest,
        'roadmap_nodes': str(roadmap.node_count), 'roadmap_seed': str(roadmap.seed)},
        time.time_ns()))
    for number, (request_id, start, goal) in enumerate(requests, 1):
        text = json.dumps({'id': request_id, 'from': start, 'to': goal}) if start else '{"id": '
        recording.request(STATION, serialize_message(String(data=text)), number, {})
        if crash and number == len(requests):
            break  # killed while planning it: a request is written with its answer
        try:
            if start is None:
                raise PlanningError('INVALID_REQUEST', 'the request is not JSON')
            result = planner.plan(start, goal)
        except PlanningError as exc:
            answer = [(RESULT, messages.result_status(
                request_id, 'error', f'{exc.code.value}: {exc.message}',
                messages.error_values(exc.code.value, roadmap, start, goal, 0.2)))]
        else:
            answer = [(TRAJECTORY, cdr.joint_trajectory(
                0, 0, request_id, cell.robot.joint_names, result.times, result.positions,
                result.velocities, result.accelerations)),
                (RESULT, messages.result_status(
                    request_id, 'ok', 'ok', messages.plan_values(result, roadmap, start, goal)))]
        assert recording.answer(number, answer)
    if crash:  # the answers before it reached the disk, then the node was killed
        assert recording._recorder.write_now([], flush=True)
        recording._recorder._writer.abandon()
    else:
        assert recording.stop() == (bag, '')
    return bag


@pytest.fixture(scope='module')
def bag(tmp_path_factory, default_cell, default_roadmap) -> Path:
    """Return a closed recording of ``REQUESTS``."""
    return record(tmp_path_factory.mktemp('review'), default_cell, default_roadmap, REQUESTS)


def review(capsys, *argv):
    """Run wafer-review; return (exit code, stdout, stderr)."""
    code = run(main, [str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_figure_per_query_and_an_index(bag, tmp_path, capsys):
    out = tmp_path / 'not' / 'yet'
    code, stdout, stderr = review(capsys, bag, '--out', out)
    assert code == EXIT_OK
    assert stdout.strip() == str(out / 'index.html')
    assert 'review: 5/5' in stderr and 'warning' not in stderr
    shapes = {}
    for number in PLANNED + REFUSED:
        png = out / f'query_{number:04d}.png'
        assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
        image = imread(png)
        assert image.ndim == 3 and image.shape[2] in (3, 4)
        assert image.shape[0] >= 400 and image.shape[1] >= 600
        assert np.std(image[..., :3]) > 0.05  # drawn on, not blank
        shapes[number] = image.shape[:2]
    # A motion is the wide figure (enclosure, joints, wafer); a refused query the enclosure.
    for number in PLANNED:
        height, width = shapes[number]
        assert width / height == pytest.approx(16 / 9, abs=0.02)
    for number in REFUSED:
        height, width = shapes[number]
        assert width / height == pytest.approx(11 / 7, abs=0.02)
    assert sorted(p.name for p in out.iterdir()) == ['index.html'] + sorted(
        [f'query_{n:04d}.png' for n in range(1, 6)]
        + [f'thumb_{n:04d}.png' for n in range(1, 6)])


def test_index_lists_every_query_escaped(bag, tmp_path, capsys, default_cell,
                                         default_roadmap):
    review(capsys, bag, '--out', tmp_path)
    page = (tmp_path / 'index.html').read_text(encoding='utf-8')
    rows = [line for line in page.splitlines() if line.startswith('<tr class=')]
    assert len(rows) == len(REQUESTS)
    for number, row in enumerate(rows, 1):
        assert f'<a href="query_{number:04d}.png">{number}</a>' in row
    assert '>q1<' in rows[0] and 'loadport1' in rows[0] and 'loadlock1' in rows[0]
    assert '&lt;b&gt;&amp;&quot;$x$' in rows[1]
    assert SPECIAL_ID not in page and '<b>' not in page
    assert 'UNKNOWN_STATION' in rows[2] and 'nowhere' in rows[2] and 'error' in rows[2]
    assert 'INVALID_REQUEST' in rows[3]
    assert 'START_IN_COLLISION' in rows[4]
    cycle = float(_column(page, rows[0], 'cycle time (s)'))
    assert cycle == pytest.approx(
        Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock1').cycle_time,
        abs=1e-3)
    assert default_cell.name in page and default_roadmap.digest in page
    assert 'INVALID_REQUEST 1, OK 2, START_IN_COLLISION 1, UNKNOWN_STATION 1' in page
    assert 'ratio wafer x' in page and '(complete)' in page


def test_a_cut_recording_is_reviewed_with_a_warning(tmp_path, capsys, default_cell,
                                                    default_roadmap):
    cut = record(tmp_path / 'cut', default_cell, default_roadmap,
                 [REQUESTS[2], REQUESTS[0], ('q-late', 'loadport2', 'loadlock2')], crash=True)
    code, _, stderr = review(capsys, cut, '--out', tmp_path / 'out')
    assert code == EXIT_OK
    assert 'warning' in stderr and 'cut off' in stderr
    assert sorted(p.name for p in (tmp_path / 'out').glob('query_????.png')) == [
        'query_0001.png', 'query_0002.png']
    page = (tmp_path / 'out' / 'index.html').read_text(encoding='utf-8')
    assert 'cut off' in page
    rows = [line for line in page.splitlines() if line.startswith('<tr class=')]
    assert [row.split('"')[1].split()[0] for row in rows] == ['error', 'ok']
    assert 'q-late' not in page  # the request being planned at the kill was not written


def test_a_recording_without_requests_is_a_usage_error(tmp_path, capsys, default_cell,
                                                       default_roadmap):
    empty = record(tmp_path / 'empty', default_cell, default_roadmap, [])
    code, stdout, stderr = review(capsys, empty, '--out', tmp_path / 'out')
    assert code == EXIT_USAGE
    assert 'no requests' in stderr and stdout == ''
    assert not (tmp_path / 'out').exists()


def test_index_shows_when_each_request_was_received(bag, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv('TZ', 'JST-9')  # a POSIX zone 9 h east of UTC: no tz database needed
    time.tzset()
    try:
        code, _, _ = review(capsys, bag, '--out', tmp_path)
    finally:
        monkeypatch.undo()
        time.tzset()
    assert code == EXIT_OK
    page = (tmp_path / 'index.html').read_text(encoding='utf-8')
    _, found = recorded_queries(str(bag), 'testing')
    rows = _rows(page)
    assert len(rows) == len(found) == len(REQUESTS)
    for query, row in zip(found, rows):
        shown = _column(page, row, 'received')
        utc = re.search(r'(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}) UTC', shown).group(1)
        local = re.search(r'<small>(\S+ \S+) JST \(UTC\+09:00\)</small>', shown).group(1)
        moment = datetime.strptime(utc, '%Y-%m-%d %H:%M:%S.%f').replace(tzinfo=timezone.utc)
        # The recorded log time of the request, to the millisecond shown.
        shown_ns = (int(moment.replace(microsecond=0).timestamp()) * 10 ** 9
                    + moment.microsecond * 1000)
        assert 0 <= query.received_ns - shown_ns < 10 ** 6
        assert abs(time.time() - moment.timestamp()) < 3600  # recorded now, not in 1970
        assert datetime.strptime(local, '%Y-%m-%d %H:%M:%S.%f') == (
            moment + timedelta(hours=9)).replace(tzinfo=None)
    assert f'received: {_utc_text(found[0])} to {_utc_text(found[-1])}' in page


def test_thumbnails_beside_the_figures_link_to_them(bag, tmp_path, capsys):
    review(capsys, bag, '--out', tmp_path)
    page = (tmp_path / 'index.html').read_text(encoding='utf-8')
    assert THUMBNAIL_WIDTH == 320
    for number, row in zip(PLANNED + REFUSED, _rows(page)):
        figure = tmp_path / f'query_{number:04d}.png'
        thumbnail = tmp_path / f'thumb_{number:04d}.png'
        assert thumbnail.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
        full, small = imread(figure), imread(thumbnail)
        assert small.shape[1] == 320
        assert small.shape[0] == round(full.shape[0] * 320 / full.shape[1])
        # The figure made small: the same picture on average, not a blank or another one.
        assert np.std(small[..., :3]) > 0.05
        assert np.abs(small[..., :3].mean(axis=(0, 1))
                      - full[..., :3].mean(axis=(0, 1))).max() < 0.01
        assert (f'<a href="query_{number:04d}.png"><img src="thumb_{number:04d}.png" '
                'alt=') in _column(page, row, 'figure')
    # A figure smaller than a thumbnail is copied at its own size, not blown up.
    review(capsys, bag, '--out', tmp_path / 'tiny', '--dpi', '20')
    for number in PLANNED + REFUSED:
        full, small = (imread(tmp_path / 'tiny' / f'{name}_{number:04d}.png')
                       for name in ('query', 'thumb'))
        assert small.shape[1] == min(320, full.shape[1])
        assert small.shape[0] == round(full.shape[0] * small.shape[1] / full.shape[1])


@pytest.mark.slow
def test_flags_mark_exactly_the_queries_beyond_the_thresholds(bag, tmp_path, capsys):
    _, found = recorded_queries(str(bag), 'testing')
    values = {query.number: query.result.values for query in found}
    clearance = {n: float(v['min_clearance']) * 1000.0 for n, v in values.items()
                 if 'min_clearance' in v}
    planning = {n: float(v['planning_time_ms']) for n, v in values.items()}
    assert sorted(clearance) == list(PLANNED) and clearance[1] != clearance[2]
    assert {planning[n] for n in REFUSED} == {0.2}  # as the recording above answers them
    low, high = sorted(clearance.values())
    closest = min(clearance, key=clearance.get)
    cases = [  # (--flag-clearance, --flag-planning), the queries flagged
        ((high, 0), {closest}),                                 # at the threshold: not below
        ((math.nextafter(high, math.inf), 0), set(PLANNED)),
        ((low, 0), set()),
        ((0, 0.2), set(PLANNED)),                               # at the threshold: not above
        ((0, max(planning[1], planning[2])), set()),
        ((0, min(planning[1], planning[2])), {max(PLANNED, key=planning.get)}),
        ((0, math.nextafter(0.2, 0.0)), set(PLANNED + REFUSED)),
    ]
    for (mm, ms), expected in cases:
        out = tmp_path / f'{mm}_{ms}'
        code, _, _ = review(capsys, bag, '--out', out, '--flag-clearance', repr(mm),
                            '--flag-planning', repr(ms))
        assert code == EXIT_OK
        page = (out / 'index.html').read_text(encoding='utf-8')
        rows = _rows(page)
        flagged = {n for n, row in zip(PLANNED + REFUSED, rows)
                   if 'flagged' in row.split('"')[1].split()}
        assert flagged == expected, (mm, ms)
        summary = page.split('<div class="flags">')[1].split('</div>')[0]
        assert f'<strong>{len(expected)} flagged</strong>' in summary
        assert set(map(int, re.findall(r'href="#q(\d+)"', summary))) == expected
        for number, row in zip(PLANNED + REFUSED, rows):
            shown = _column(page, row, 'flags')
            assert ('clearance' in shown) == (number in expected and mm > 0), (mm, ms)
            assert ('planning' in shown) == (number in expected and ms > 0), (mm, ms)
    # The defaults: 1 mm and 400 ms.
    review(capsys, bag, '--out', tmp_path / 'defaults')
    page = (tmp_path / 'defaults' / 'index.html').read_text(encoding='utf-8')
    assert '(clearance below 1 mm, planning above 400 ms)' in page


@pytest.mark.parametrize('option, value', [('--flag-clearance', '-1'),
                                           ('--flag-planning', 'nan'),
                                           ('--flag-planning', 'inf')])
def test_a_bad_flag_threshold_is_a_usage_error_naming_it(bag, tmp_path, capsys, option,
                                                         value):
    code, _, stderr = review(capsys, bag, '--out', tmp_path, option, value)
    assert code == EXIT_USAGE
    assert option in stderr and value in stderr


def test_a_motion_figure_shows_times_stations_jerk_and_the_closest_approach(
        bag, tmp_path, default_cell):
    _, found = recorded_queries(str(bag), 'testing')
    words = {1: 'elbow right', -1: 'elbow left'}
    jerk_limit = default_cell.robot.limits.jerk
    for query in found[:2]:
        values = query.result.values
        figure = render(query, default_cell, tmp_path / 'motion.png')
        motion, bar = figure.axes[:2]
        # The closest approach, found on the samples, is the one the planner verified.
        legend = [text.get_text() for text in motion.get_legend().get_texts()]
        closest = [text for text in legend if text.startswith('closest approach: ')]
        assert len(closest) == 1
        assert float(closest[0].split()[2]) == pytest.approx(
            float(values['min_clearance']) * 1000.0, abs=0.06)
        assert re.search(r'mm, ((shoulder|elbow|wrist) link|wafer) vs boundary', closest[0])
        assert {text.get_text() for text in motion.texts} >= set(default_cell.stations)
        assert bar.get_ylabel() == 'time of the robot outlines (s)'
        assert bar.get_ylim() == pytest.approx((0.0, float(values['cycle_time'])), abs=0.011)
        jerk = next(axis for axis in figure.axes if axis.get_ylabel().startswith('jerk'))
        assert jerk.get_ylabel() == 'jerk (rad/s³, from samples)'
        bounds = sorted(line.get_ydata()[0] for line in jerk.lines
                        if line.get_linestyle() == '--')
        assert bounds == pytest.approx(sorted(np.concatenate([-jerk_limit, jerk_limit])))
        start, goal = json.loads(values['branches'])
        heading = motion.get_title()
        assert (f"{values['from']} ({words[start]}) -> {values['to']} ({words[goal]})"
                in heading)
        assert 'branches' not in heading and _utc_text(query) in heading


def test_a_start_in_collision_figure_fills_the_colliding_body(bag, tmp_path, default_cell):
    _, found = recorded_queries(str(bag), 'testing')
    query = found[REFUSED[-1] - 1]
    assert query.code == 'START_IN_COLLISION'
    png = tmp_path / 'collision.png'
    figure = render(query, default_cell, png)
    axis = figure.axes[0]
    legend = [text.get_text() for text in axis.get_legend().get_texts()]
    assert 'start collides: wafer vs boundary, overlap 20.0 mm' in legend
    assert sum('collides' in text for text in legend) == 1  # the wafer alone
    # In the picture: the wafer filled light red round its centre (0.25, 0.32), the wall it
    # hits (y = 0.45) drawn pure red.
    image = imread(png)[..., :3]
    height = image.shape[0]
    scale = image.shape[1] / (figure.get_figwidth() * figure.dpi)
    pixels = axis.transData.inverted()

    def centre(mask):
        rows, columns = np.nonzero(mask)
        return pixels.transform(np.column_stack([columns, height - rows]) / scale).mean(axis=0)

    red, green, blue = image[..., 0], image[..., 1], image[..., 2]
    fill = (red > 0.95) & (np.abs(green - 0.55) < 0.06) & (np.abs(blue - 0.55) < 0.06)
    wall = (red > 0.95) & (green < 0.1) & (blue < 0.1)
    # The wall between the two pockets is 0.185 m long: a short red line.
    assert fill.sum() > 500 and wall.sum() > 100
    np.testing.assert_allclose(centre(fill), [0.25, 0.32], atol=0.02)
    assert centre(wall)[1] == pytest.approx(0.45, abs=0.01)


def _rows(page: str) -> list:
    return [line for line in page.splitlines() if line.startswith('<tr class=')]


def _column(page: str, row: str, name: str) -> str:
    """Return what a row shows under the header ``name``."""
    names = re.findall(r'<th>(.*?)</th>', page)
    return re.findall(r'<td>(.*?)</td>', row)[names.index(name)]


def _utc_text(query) -> str:
    seconds, rest = divmod(query.received_ns, 10 ** 9)
    moment = datetime.fromtimestamp(seconds, timezone.utc)
    return f'{moment:%Y-%m-%d %H:%M:%S}.{rest // 10 ** 6:03d} UTC'
