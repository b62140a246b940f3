"""The Foxglove live view: a WebSocket client sees what the node publishes, latched markers too."""

import asyncio
import collections
import json
import socket
import struct
import sys
from types import SimpleNamespace

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from node_harness import Harness, isolate_dds, values, wait_for
import pytest
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from wafer_planner_ros.node import markers
from wafer_planner_ros.node.live import LiveView
from wafer_planner_ros.recording.msgdefs import definition

pytest.importorskip('foxglove')
websockets = pytest.importorskip('websockets')

# The SDK speaks the Foxglove WebSocket protocol under its own subprotocol name; the
# Foxglove app offers both.
SUBPROTOCOLS = ['foxglove.sdk.v1', 'foxglove.websocket.v1']
TOPICS = {'/wafer_planner/roadmap_markers': MarkerArray,
          '/wafer_planner/path_markers': MarkerArray,
          '/wafer_planner/trajectory': JointTrajectory,
          '/wafer_planner/result': DiagnosticStatus,
          '/diagnostics': DiagnosticArray}
TYPES = {MarkerArray: 'visualization_msgs/msg/MarkerArray',
         JointTrajectory: 'trajectory_msgs/msg/JointTrajectory',
         DiagnosticStatus: 'diagnostic_msgs/msg/DiagnosticStatus',
         DiagnosticArray: 'diagnostic_msgs/msg/DiagnosticArray'}
FRAMES = '/wafer_planner/frames'
"""Where the joint-space frame stands (foxglove.FrameTransform, kept as bytes here)."""
MESSAGE_DATA = 0x01
"""The opcode of a binary message-data frame (server to client)."""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


@pytest.fixture(scope='module')
def harness(roadmap_cache, tmp_path_factory):
    """Yield a running node with the live view on a free port (this module's own node)."""
    isolate_dds(tmp_path_factory.mktemp('dds'))
    running = Harness({'roadmap.cache_dir': str(roadmap_cache), 'planning.timeout': 30.0,
                       'recording.enabled': False, 'live.host': '127.0.0.1',
                       'live.port': _free_port()})
    yield running
    running.close()


class Client:
    """A Foxglove WebSocket client: the channels the server advertises, subscriptions."""

    def __init__(self, connection):
        """Wrap an open connection."""
        self.connection = connection
        self.channels = {}
        """topic -> the advertised channel (JSON)."""
        self.topics = {}
        """subscription id -> topic."""
        self.inbox = collections.defaultdict(list)
        """topic -> the messages received and not yet asked for."""

    @classmethod
    async def connect(cls, url: str) -> 'Client':
        """Connect, read serverInfo and the advertisements of every expected topic."""
        client = cls(await websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None))
        assert client.connection.subprotocol in SUBPROTOCOLS
        info = json.loads(await asyncio.wait_for(client.connection.recv(), 20))
        assert info['op'] == 'serverInfo' and info['name'] == '/wafer_planner'
        while not set(TOPICS) | {FRAMES} <= set(client.channels):
            message = json.loads(await asyncio.wait_for(client.connection.recv(), 20))
            if message['op'] == 'advertise':
                client.channels.update({c['topic']: c for c in message['channels']})
        return client

    async def subscribe(self, *topics: str) -> None:
        """Subscribe to ``topics`` (ids 1, 2, ... in the order first subscribed)."""
        start = len(self.topics) + 1
        subscriptions = [{'id': start + k, 'channelId': self.channels[topic]['id']}
                         for k, topic in enumerate(topics)]
        self.topics.update({s['id']: topic for s, topic in zip(subscriptions, topics)})
        await self.connection.send(json.dumps({'op': 'subscribe',
                                               'subscriptions': subscriptions}))

    async def receive(self, topic: str, accept=lambda msg: True, timeout: float = 60.0):
        """Return the next message on ``topic`` that ``accept``s, decoded from its CDR."""
        async def wait():
            while True:
                while self.inbox[topic]:
                    msg = self.inbox[topic].pop(0)
                    if accept(msg):
                        return msg
                frame = await self.connection.recv()
                if isinstance(frame, str):
                    continue  # status, (un)advertise
                assert frame[0] == MESSAGE_DATA
                subscription, log_time = struct.unpack_from('<IQ', frame, 1)
                assert log_time > 0
                kind = self.topics[subscription]
                self.inbox[kind].append(frame[13:] if kind == FRAMES else
                                        deserialize_message(frame[13:], TOPICS[kind]))
        return await asyncio.wait_for(wait(), timeout)

    async def close(self) -> None:
        """Close the connection."""
        await self.connection.close()


def _url(harness) -> str:
    url = harness.status()['live']
    assert url, harness.status()['live_error']
    return url


def test_the_channels_carry_the_recordings_schemas_as_cdr(harness):
    async def run():
        client = await Client.connect(_url(harness))
        await client.close()
        return client.channels
    channels = asyncio.run(run())
    for topic, msg_type in TOPICS.items():
        name = TYPES[msg_type]
        assert channels[topic]['encoding'] == 'cdr'
        assert channels[topic]['schemaEncoding'] == 'ros2msg'
        assert channels[topic]['schemaName'] == name
        assert channels[topic]['schema'] == definition(name)  # the full concatenated text
    assert 'MSG: visualization_msgs/Marker' in channels['/wafer_planner/roadmap_markers'][
        'schema']


def test_a_late_client_gets_the_roadmap_markers_and_every_answer(harness):
    inbox = harness.subscribe_markers()  # what DDS delivers, to compare with
    wait_for(lambda: inbox, 20)
    assert harness.status()['live'] == f'ws://127.0.0.1:{harness.node.settings.live_port}'

    async def run():
        # The markers were published long before anyone connected: they are latched.
        first = await Client.connect(_url(harness))
        await first.subscribe('/wafer_planner/roadmap_markers', '/wafer_planner/result',
                              '/wafer_planner/trajectory', '/wafer_planner/path_markers',
                              '/diagnostics')
        markers = await first.receive('/wafer_planner/roadmap_markers')
        second = await Client.connect(_url(harness))  # and again for a second client
        await second.subscribe('/wafer_planner/roadmap_markers')
        again = await second.receive('/wafer_planner/roadmap_markers')
        await second.close()
        harness.send_stations({'id': 'live1', 'from': 'loadport2', 'to': 'loadlock1'})
        result = await first.receive('/wafer_planner/result', lambda m: m.name == 'live1')
        trajectory = await first.receive('/wafer_planner/trajectory',
                                         lambda m: m.header.frame_id == 'live1')
        path = await first.receive('/wafer_planner/path_markers')
        health = await first.receive('/diagnostics')
        await first.close()
        return markers, again, result, trajectory, path, health

    markers, again, result, trajectory, path, health = asyncio.run(run())
    assert markers == inbox[0] and again == inbox[0]  # the bytes DDS delivers
    namespaces = {m.ns for m in markers.markers}
    assert {'enclosure', 'stations', 'roadmap_nodes', 'roadmap_edges'} <= namespaces
    nodes = next(m for m in markers.markers if m.ns == 'roadmap_nodes')
    assert len(nodes.points) == harness.status()['nodes']
    assert result == harness.result('live1')
    assert result.level == DiagnosticStatus.OK and values(result)['code'] == 'OK'
    wait_for(lambda: any(t.header.frame_id == 'live1' for t in harness.trajectories), 10)
    assert trajectory == next(t for t in harness.trajectories if t.header.frame_id == 'live1')
    assert len(trajectory.points) > 100
    assert {'path_joint_space', 'wafer_trace', 'robot'} <= {m.ns for m in path.markers}
    assert health.status[0].name == 'wafer_planner: health'
    assert values(health.status[0])['ready'] == 'True'


def test_a_late_client_gets_where_the_joint_space_frame_stands(harness):
    async def run():
        client = await Client.connect(_url(harness))
        await client.subscribe(FRAMES)
        data = await client.receive(FRAMES)
        await client.close()
        return client.channels[FRAMES], data

    channel, data = asyncio.run(run())
    assert channel['schemaName'] == 'foxglove.FrameTransform'
    # Protobuf keeps strings and doubles as they are: the frames, then the offset.
    assert b'\x12\x04efem' in data and b'\x1a\x10efem_joint_space' in data
    offset = markers.joint_space_offset(harness.node._worker.cell)
    for value in offset[:2]:
        assert struct.pack('<d', value) in data


def test_a_client_that_never_reads_does_not_hold_the_node_up(harness):
    async def run():
        stalled = await Client.connect(_url(harness))
        await stalled.subscribe(*TOPICS)
        # From here on nothing reads this connection (the event loop is blocked below): the
        # markers alone fill its socket's buffers, and the server's outbox after them.
        for k in range(20):
            harness.send_stations({'id': f'stall{k}', 'from': 'loadport1', 'to': 'loadlock2'})
        answers = [harness.result(f'stall{k}') for k in range(20)]
        await stalled.close()
        return answers
    answers = asyncio.run(run())
    assert [values(a)['code'] for a in answers] == ['OK'] * 20


def test_a_port_in_use_is_reported_and_the_node_serves_on(harness):
    with socket.socket() as busy:
        busy.bind(('127.0.0.1', 0))
        busy.listen()
        port = busy.getsockname()[1]
        set_port = harness.node.set_parameters([Parameter('live.port', value=port)])
        assert set_port[0].successful
        status = harness.status()
        assert status['live'] == ''
        assert f'ws://127.0.0.1:{port} (live.port {port})' in status['live_error']
        assert 'in use' in status['live_error']
        harness.send_stations({'id': 'busy1', 'from': 'loadport3', 'to': 'loadlock1'})
        assert values(harness.result('busy1'))['code'] == 'OK'
    # Set again once the port is free: it serves there, the markers still latched.
    assert harness.node.set_parameters([Parameter('live.port', value=port)])[0].successful
    status = harness.status()
    assert status['live'] == f'ws://127.0.0.1:{port}' and status['live_error'] == ''

    async def run():
        client = await Client.connect(f'ws://127.0.0.1:{port}')
        await client.subscribe('/wafer_planner/roadmap_markers')
        markers = await client.receive('/wafer_planner/roadmap_markers')
        await client.close()
        return markers
    assert len(asyncio.run(run()).markers) > 10


def test_without_the_sdk_the_live_view_says_so_and_stays_off(monkeypatch):
    monkeypatch.setitem(sys.modules, 'foxglove', None)  # import foxglove: ImportError
    errors = []
    log = SimpleNamespace(error=errors.append, info=lambda text: None)
    publisher = SimpleNamespace(topic_name='/wafer_planner/roadmap_markers',
                                msg_type=MarkerArray)
    view = LiveView('/wafer_planner', [publisher], publisher, log)
    assert not view.start('0.0.0.0', 8765)
    assert errors == ['live view not served on ws://0.0.0.0:8765 (live.port 8765): '
                      'foxglove-sdk is not installed (pip install foxglove-sdk==0.30.3)'
                      '; the node serves on without it']
    view.publish(publisher, b'markers')  # nothing to serve them to: no error
    assert view.status() == {'live': '', 'live_error': errors[0].split(';')[0],
                             'live_clients': 0}
    assert not view.start('0.0.0.0', 0) and len(errors) == 1  # off: the SDK is not needed
