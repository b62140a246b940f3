"""``wafer-review``: a figure per query and an index page, from a recording made here."""

import json
from pathlib import Path
import time

from matplotlib.image import imread
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.cli.common import EXIT_OK, EXIT_USAGE, run
from wafer_planner_ros.cli.review import main
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
REQUESTS = [('q1', 'loadport1', 'loadlock1'),
            (SPECIAL_ID, 'loadlock1', 'loadport2'),
            ('q3', 'loadport1', 'nowhere'),
            ('', None, None)]
"""(id, from, to) as a cell controller sent them; None: a request that is not JSON."""
PLANNED, REFUSED = (1, 2), (3, 4)
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
    assert 'review: 4/4' in stderr and 'warning' not in stderr
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
    assert sorted(p.name for p in out.iterdir()) == ['index.html'] + [
        f'query_{n:04d}.png' for n in (1, 2, 3, 4)]


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
    cycle = float(rows[0].split('<td>')[8].split('<')[0])
    assert cycle == pytest.approx(
        Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock1').cycle_time,
        abs=1e-3)
    assert default_cell.name in page and default_roadmap.digest in page
    assert 'INVALID_REQUEST 1, OK 2, UNKNOWN_STATION 1' in page
    assert 'ratio wafer x' in page and '(complete)' in page


def test_a_cut_recording_is_reviewed_with_a_warning(tmp_path, capsys, default_cell,
                                                    default_roadmap):
    cut = record(tmp_path / 'cut', default_cell, default_roadmap,
                 [REQUESTS[2], REQUESTS[0], ('q-late', 'loadport2', 'loadlock2')], crash=True)
    code, _, stderr = review(capsys, cut, '--out', tmp_path / 'out')
    assert code == EXIT_OK
    assert 'warning' in stderr and 'cut off' in stderr
    assert sorted(p.name for p in (tmp_path / 'out').glob('*.png')) == [
        'query_0001.png', 'query_0002.png']
    page = (tmp_path / 'out' / 'index.html').read_text(encoding='utf-8')
    assert 'cut off' in page
    rows = [line for line in page.splitlines() if line.startswith('<tr class=')]
    assert [row.split('"')[1] for row in rows] == ['error', 'ok']
    assert 'q-late' not in page  # the request being planned at the kill was not written


def test_a_recording_without_requests_is_a_usage_error(tmp_path, capsys, default_cell,
                                                       default_roadmap):
    empty = record(tmp_path / 'empty', default_cell, default_roadmap, [])
    code, stdout, stderr = review(capsys, empty, '--out', tmp_path / 'out')
    assert code == EXIT_USAGE
    assert 'no requests' in stderr and stdout == ''
    assert not (tmp_path / 'out').exists()
