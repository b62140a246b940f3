"""The node's recording in-process: what it holds, ``~/set_recording``, failures reported."""

from pathlib import Path
import shutil

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from node_harness import values, wait_for
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
from sampling import sampled_every
from std_srvs.srv import SetBool

from wafer_planner_ros.recording.queries import queries
from wafer_planner_ros.recording.reading import read
import yaml


def _stop(harness) -> Path:
    answer = harness.call('set_recording', SetBool.Request(data=False))
    assert answer.success and answer.message.startswith('recording closed: '), answer.message
    return Path(answer.message.split(': ', 1)[1])


def _start(harness) -> Path:
    answer = harness.call('set_recording', SetBool.Request(data=True))
    assert answer.success, answer.message
    return Path(answer.message.split('recording to ', 1)[1])


def test_set_recording_closes_and_opens_self_contained_bags(harness, default_cell_file):
    first = Path(harness.status()['recording_directory'])
    assert harness.status()['recording'] and first.parent == Path(harness.recordings)
    harness.send_stations({'id': 'r1', 'from': 'loadport1', 'to': 'loadlock1'})
    harness.result('r1')
    assert _stop(harness) == first
    assert (first / 'metadata.yaml').is_file() and not harness.status()['recording']
    assert harness.node.get_parameter('recording.enabled').value is False
    assert 'not recording' in harness.call('set_recording', SetBool.Request(data=False)).message
    harness.send_stations({'id': 'unrecorded', 'from': 'loadport1', 'to': 'loadlock2'})
    harness.result('unrecorded')
    second = _start(harness)
    assert second != first and harness.status()['recording']
    assert harness.node.get_parameter('recording.enabled').value is True
    harness.send_stations({'id': 'r2', 'from': 'loadport2', 'to': 'loadlock2'})
    harness.send_stations({'id': 'r3', 'from': 'loadport2', 'to': 'nowhere'})
    harness.result('r2')
    harness.result('r3')
    assert _stop(harness) == second
    # The second bag alone holds what it needs: cell, parameters, roadmap, markers.
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(second) as reader:
        topics = {}
        for connection, _, raw in reader.messages():
            topics.setdefault(connection.topic, []).append(
                store.deserialize_cdr(raw, connection.msgtype))
    assert [m.name for m in topics['/wafer_planner/result']] == ['r2', 'r3']
    assert [m.header.frame_id for m in topics['/wafer_planner/trajectory']] == ['r2']
    assert len(topics['/wafer_planner/plan_station_request']) == 2
    assert len(topics['/wafer_planner/roadmap_markers']) == 1
    recording = read(second)
    attachments = {a.name: a.data for a in recording.attachments}
    assert attachments['cell.yaml'] == default_cell_file.read_bytes()
    parameters = yaml.safe_load(attachments['parameters.yaml'])['wafer_planner']
    assert parameters['ros__parameters']['planning.timeout'] == 30.0
    (load,) = [m.metadata for m in recording.metadata if m.name == 'wafer_planner']
    assert load['roadmap_hash'] == harness.status()['hash']
    found = queries(recording)
    assert [(q.request_id, q.code) for q in found] == [('r2', 'OK'), ('r3', 'UNKNOWN_STATION')]
    assert found[0].trajectory.positions.shape[1] == 3
    _start(harness)


def test_a_parameter_change_is_recorded_for_the_queries_after_it(harness):
    node = harness.node
    assert node.set_parameters([Parameter('trajectory.sample_period', value=0.02)])[0] \
        .successful
    harness.send_stations({'id': 'p1', 'from': 'loadport3', 'to': 'loadlock1'})
    result = harness.result('p1')
    assert node.set_parameters([Parameter('trajectory.sample_period', value=0.01)])[0] \
        .successful
    bag = _stop(harness)
    _start(harness)
    (query,) = [q for q in queries(read(bag)) if q.request_id == 'p1']
    assert query.parameters['trajectory.sample_period'] == 0.02
    assert query.cycle_time == float(values(result)['cycle_time'])
    assert sampled_every(query.trajectory.times, 0.02)
    assert not sampled_every(query.trajectory.times, 0.01)


def test_an_unwritable_directory_is_reported_and_planning_goes_on(harness, tmp_path):
    blocker = tmp_path / 'a_file'
    blocker.write_text('not a directory')
    _stop(harness)
    inbox = []
    harness.peer.create_subscription(DiagnosticArray, '/diagnostics', inbox.append, 10)
    node = harness.node
    moved = Parameter('recording.directory', value=str(blocker / 'recordings'))
    assert node.set_parameters([moved])[0].successful
    answer = harness.call('set_recording', SetBool.Request(data=True))
    assert not answer.success and str(blocker) in answer.message
    assert node.get_parameter('recording.enabled').value is False
    status = harness.status()
    assert not status['recording'] and str(blocker) in status['recording_error']

    def reported() -> bool:
        return any(str(blocker) in s.message and s.level == DiagnosticStatus.WARN
                   for array in inbox for s in array.status)
    wait_for(reported, 10)
    harness.send_stations({'id': 'still-planning', 'from': 'loadport1', 'to': 'loadlock1'})
    assert values(harness.result('still-planning'))['code'] == 'OK'
    back = Parameter('recording.directory', value=harness.recordings)
    assert node.set_parameters([back])[0].successful
    _start(harness)
    assert harness.status()['recording'] and not harness.status()['recording_error']


def test_the_enabled_parameter_closes_and_starts_recordings(harness):
    before = Path(harness.status()['recording_directory'])
    node = harness.node
    assert node.set_parameters([Parameter('recording.enabled', value=False)])[0].successful
    assert not harness.status()['recording'] and (before / 'metadata.yaml').is_file()
    assert node.set_parameters([Parameter('recording.enabled', value=True)])[0].successful
    after = Path(harness.status()['recording_directory'])
    assert harness.status()['recording'] and after != before


def test_an_answer_is_in_the_file_before_it_is_published(harness):
    """What a client receives, a crash right after cannot take out of the recording."""
    node = harness.node
    bag = Path(harness.status()['recording_directory'])
    seen = []
    original = {pub: pub.publish for pub in (node._trajectory_pub, node._result_pub)}

    def watch(publisher):
        def publish(data):
            # Read the file as another process would, now, before the message goes out.
            message = deserialize_message(data, publisher.msg_type)
            request_id = message.name if publisher is node._result_pub \
                else message.header.frame_id
            in_file = [(m.sequence, recording.channels[m.channel_id].topic)
                       for recording in [read(bag)] for m in recording.messages]
            seen.append((publisher.topic_name, request_id, in_file))
            original[publisher](data)
        return publish
    try:
        for publisher in original:
            publisher.publish = watch(publisher)
        harness.send_stations({'id': 'd1', 'from': 'loadport1', 'to': 'loadlock2'})
        harness.send_stations({'id': 'd2', 'from': 'loadport1', 'to': 'nowhere'})
        harness.result('d1')
        harness.result('d2')
    finally:
        for publisher, publish in original.items():
            publisher.publish = publish
    assert [(topic, request_id) for topic, request_id, _ in seen] == [
        ('/wafer_planner/trajectory', 'd1'), ('/wafer_planner/result', 'd1'),
        ('/wafer_planner/result', 'd2')]
    recording = read(bag)
    numbers = {q.request_id: q.number for q in queries(recording)}
    for topic, request_id, in_file in seen:
        assert (numbers[request_id], topic) in in_file
    trajectory_at_publish = seen[0][2]
    assert (numbers['d1'], '/wafer_planner/result') in trajectory_at_publish  # both at once


def test_a_deleted_recording_directory_shows_as_warn_within_one_request(harness):
    """``rm -rf`` of the bag being written: stopped, said so, counted; planning goes on."""
    inbox = []
    harness.peer.create_subscription(DiagnosticArray, '/diagnostics', inbox.append, 10)
    bag = Path(harness.status()['recording_directory'])
    assert harness.status()['recording'] and bag.is_dir()
    before = harness.status()['answers_before_recorded']
    shutil.rmtree(bag)
    harness.send_stations({'id': 'into-the-void', 'from': 'loadport2', 'to': 'loadlock1'})
    assert values(harness.result('into-the-void'))['code'] == 'OK'
    status = harness.status()
    assert not status['recording'] and status['recording_lost'] == 1
    assert status['answers_before_recorded'] == before  # lost, not recorded late
    assert status['recording_error'] == \
        f'recording stopped: {bag} was deleted; 1 answer not recorded'

    def warned() -> bool:
        return any(s.level == DiagnosticStatus.WARN and f'{bag} was deleted' in s.message
                   for array in inbox for s in array.status)
    wait_for(warned, 5)  # published once a second
    # recording.enabled follows: a recording that stopped by itself is not enabled.
    wait_for(lambda: harness.node.get_parameter('recording.enabled').value is False, 5)
    assert not bag.exists()
    assert _start(harness) != bag
    assert harness.node.get_parameter('recording.enabled').value is True
    assert harness.status()['recording'] and not harness.status()['recording_error']
