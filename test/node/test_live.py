"""The Foxglove live view: a WebSocket client sees what the node publishes, latched markers too."""

import asyncio
import base64
import collections
import json
import os
from pathlib import Path
import queue
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from node_harness import Harness, isolate_dds, values, wait_for
import pytest
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from wafer_planner_ros.node import live_server, markers
from wafer_planner_ros.node.live import LiveView
from wafer_planner_ros.node.qos import LATCHED
from wafer_planner_ros.recording.msgdefs import definition
from wafer_planner_ros.service.settings import settings_from
import yaml

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
ROBOT = {'/joint_states': JointState, '/wafer_sim/arm_markers': MarkerArray,
         '/wafer_sim/wafer_acceleration': Float64MultiArray}
"""The robot's topics the view relays (``live.robot``: the simulated arm by default)."""
TOPICS.update(ROBOT)
TYPES = {MarkerArray: 'visualization_msgs/msg/MarkerArray',
         JointTrajectory: 'trajectory_msgs/msg/JointTrajectory',
         DiagnosticStatus: 'diagnostic_msgs/msg/DiagnosticStatus',
         DiagnosticArray: 'diagnostic_msgs/msg/DiagnosticArray',
         JointState: 'sensor_msgs/msg/JointState',
         Float64MultiArray: 'std_msgs/msg/Float64MultiArray'}
FRAMES = '/wafer_planner/frames'
"""Where the joint-space frame stands (foxglove.FrameTransform, kept as bytes here)."""
MESSAGE_DATA = 0x01
"""The opcode of a binary message-data frame (server to client)."""
ROOT = Path(__file__).resolve().parents[2]
STOPPED_WITHIN = 2.0
"""s from SIGINT until the node's process has ended, whatever its clients do."""
GROWTH_MB = 150.0
"""MB the node's resident memory may grow by under clients that never read (the view's
bound with the default live.max_clients is below 100 MB; unbounded, it grew by 2 GB)."""


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


def _warnings_of(view, monkeypatch) -> list:
    """Return the list the live view's warnings go to from now on (and to its log)."""
    warnings, log = [], view.log
    monkeypatch.setattr(view, 'log', SimpleNamespace(
        info=log.info, error=log.error,
        warning=lambda text: (warnings.append(text), log.warning(text))))
    return warnings


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


@pytest.mark.slow
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


class _Raw:
    """A WebSocket client on a bare socket: it reads only when told to (never by itself)."""

    def __init__(self, port: int, receive_buffer: int = 0):
        """Connect and shake hands; ``refused`` holds the HTTP status line if refused."""
        self.sock = socket.socket()
        if receive_buffer:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        self.sock.settimeout(30)
        self.sock.connect(('127.0.0.1', port))
        self.buffer, self.channels, self.refused = b'', {}, ''
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n'
             f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n'
             f'Sec-WebSocket-Protocol: {", ".join(SUBPROTOCOLS)}\r\n\r\n').encode())
        try:
            head = self._until(b'\r\n\r\n').split(b'\r\n', 1)[0].decode()
        except (ConnectionResetError, EOFError) as exc:  # refused without an answer
            head = repr(exc)
        if ' 101 ' not in head:
            self.refused = head
            return
        while not set(TOPICS) | {FRAMES} <= set(self.channels):
            message = json.loads(self.message())
            if message['op'] == 'advertise':
                self.channels.update({c['topic']: c['id'] for c in message['channels']})

    def _more(self) -> None:
        chunk = self.sock.recv(1 << 16)
        if not chunk:
            raise EOFError('the node closed the connection')
        self.buffer += chunk

    def _until(self, end: bytes) -> bytes:
        while end not in self.buffer:
            self._more()
        head, self.buffer = self.buffer.split(end, 1)
        return head

    def _take(self, count: int) -> bytes:
        while len(self.buffer) < count:
            self._more()
        data, self.buffer = self.buffer[:count], self.buffer[count:]
        return data

    def message(self):
        """Return the next whole message, text or bytes, its fragments joined."""
        parts, kind = [], None
        while True:
            first, second = self._take(2)
            length = second & 0x7F
            if length >= 126:
                size = 2 if length == 126 else 8
                length = int.from_bytes(self._take(size), 'big')
            payload = self._take(length)
            opcode = first & 0x0F
            if opcode >= 8:  # ping, pong (close: the socket's end follows)
                continue
            kind = kind or opcode
            parts.append(payload)
            if first & 0x80:
                data = b''.join(parts)
                return data.decode() if kind == 1 else data

    def send(self, message: dict) -> None:
        """Send ``message`` as JSON (a masked text frame)."""
        data = json.dumps(message).encode()
        mask = os.urandom(4)
        length = bytes([0x80 | len(data)]) if len(data) < 126 else \
            bytes([0x80 | 126]) + struct.pack('>H', len(data))
        self.sock.sendall(bytes([0x81]) + length + mask +
                          bytes(b ^ mask[k % 4] for k, b in enumerate(data)))

    def subscribe(self, topics, first: int = 1) -> None:
        """Subscribe to ``topics`` (subscription ids from ``first`` on)."""
        self.send({'op': 'subscribe', 'subscriptions': [
            {'id': first + k, 'channelId': self.channels[t]} for k, t in enumerate(topics)]})

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


def _dds_env(tmp_path) -> dict:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'log'), PYTHONUNBUFFERED='1')
    env.setdefault('ROS_DOMAIN_ID', str(200 + os.getpid() % 30))
    return env


def _resident_mb(pid: int) -> float:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    raise AssertionError(f'no VmRSS for process {pid}')


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='reads /proc')
@pytest.mark.parametrize('clients', [1, 20])
def test_clients_that_subscribe_and_unsubscribe_without_reading_neither_grow_nor_hold_the_node(
        clients, roadmap_cache, default_roadmap, tmp_path):
    # The node as its own process, the packaged live.* defaults but the port.
    port = _free_port()
    node = subprocess.Popen(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
         '-p', 'planning.station_table:=false', '-p', 'recording.enabled:=false',
         '-p', f'roadmap.cache_dir:={roadmap_cache}', '-p', f'live.port:={port}'],
        env=_dds_env(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in node.stdout],
                     daemon=True).start()
    stalled, stop = [], threading.Event()
    try:
        log = []
        while not any('ready: ' in line for line in log):
            log.append(lines.get(timeout=240))
        first = _Raw(port)  # a client that reads: the roadmap markers are there to be sent
        first.subscribe(['/wafer_planner/roadmap_markers'])
        assert len(first.message()) > 1_000_000
        first.close()
        before = _resident_mb(node.pid)
        stalled = [_Raw(port) for _ in range(clients)]
        admitted = [c for c in stalled if not c.refused]

        def churn(client) -> None:
            # As fast as it can, never reading: each subscribe asks for the 2 MB markers.
            markers_id = client.channels['/wafer_planner/roadmap_markers']
            try:
                while not stop.is_set():
                    client.send({'op': 'subscribe',
                                 'subscriptions': [{'id': 1, 'channelId': markers_id}]})
                    client.send({'op': 'unsubscribe', 'subscriptionIds': [1]})
            except OSError:
                pass  # the socket is full (the node reads it at its pace) or closed

        threads = [threading.Thread(target=churn, args=(c,), daemon=True) for c in admitted]
        for thread in threads:
            thread.start()
        began, grown = time.monotonic(), 0.0
        while time.monotonic() - began < 3.0 and grown <= GROWTH_MB:
            grown = max(grown, _resident_mb(node.pid) - before)
            time.sleep(0.05)
        stop.set()
        time.sleep(0.5)
        grown = max(grown, _resident_mb(node.pid) - before)
        # Every client still connected, the sending ones stuck in a send.
        begun = time.monotonic()
        node.send_signal(signal.SIGINT)
        try:
            node.wait(timeout=60)
        except subprocess.TimeoutExpired:
            pass
        seconds = time.monotonic() - begun
        assert grown <= GROWTH_MB and node.poll() == 0 and seconds < STOPPED_WITHIN, \
            f'{grown:.0f} MB more, ended {seconds:.2f} s after SIGINT ({node.poll()})'
        assert len(admitted) == min(clients, 4)  # the packaged live.max_clients
    finally:
        stop.set()
        node.kill()
        node.wait()
        for client in stalled:
            client.close()


def test_one_client_more_than_live_max_clients_is_refused_and_logged(harness, monkeypatch):
    view = harness.node._live
    warnings = _warnings_of(view, monkeypatch)
    assert harness.node.set_parameters([Parameter('live.max_clients', value=2)])[0].successful
    port = harness.node.settings.live_port
    for bad in (0, 65):
        result = harness.node.set_parameters([Parameter('live.max_clients', value=bad)])[0]
        assert not result.successful and 'live.max_clients' in result.reason
        assert str(bad) in result.reason
    assert harness.status()['live_clients'] == 0

    async def run():
        clients = [await Client.connect(_url(harness)) for _ in range(2)]
        assert harness.status()['live_clients'] == 2
        with pytest.raises(websockets.exceptions.InvalidStatus) as refused:
            await Client.connect(_url(harness))
        assert refused.value.response.status_code == 503
        await clients[0].close()  # a place is free again
        wait_for(lambda: harness.status()['live_clients'] == 1, 10)
        clients[0] = await Client.connect(_url(harness))
        await clients[0].subscribe('/wafer_planner/roadmap_markers')
        assert len((await clients[0].receive('/wafer_planner/roadmap_markers')).markers) > 10
        for client in clients:
            await client.close()
    asyncio.run(run())
    assert harness.node.settings.live_port == port
    assert len([w for w in warnings if 'refused' in w]) == 1, warnings  # one line a while
    assert 'a client from 127.0.0.1:' in warnings[0]
    assert '2 clients at most (live.max_clients 2)' in warnings[0]


def test_a_slow_client_loses_its_oldest_messages_its_outbox_bounded_in_bytes(monkeypatch):
    warnings = []
    log = SimpleNamespace(error=warnings.append, info=lambda text: None,
                          warning=warnings.append)
    publishers = [SimpleNamespace(topic_name=topic, msg_type=kind)
                  for topic, kind in TOPICS.items()]
    view = LiveView('/wafer_planner', publishers, publishers[0], log)
    port = _free_port()
    assert view.start('127.0.0.1', port)
    try:
        client = _Raw(port, receive_buffer=4096)
        client.subscribe(['/wafer_planner/path_markers'])
        wait_for(lambda: view.status()['live_clients'] == 1
                 and view._served.subscribed('/wafer_planner/path_markers'), 10)
        # 64 MiB published at once to a client that reads nothing meanwhile.
        path = publishers[1]
        for k in range(64):
            view.publish(path, bytes([k]) * live_server.MIB)
            queued = view._served._clients[0].queued
            assert queued <= live_server.OUTBOX_BYTES, f'{queued} bytes wait for the client'
        assert len([w for w in warnings if 'reads too slowly' in w]) == 1, warnings
        received = []
        while not received or received[-1] != 63:
            frame = client.message()
            assert frame[0] == MESSAGE_DATA and len(frame) == 13 + live_server.MIB
            received.append(frame[13])
        # The newest ones, in order; of the rest, what was on its way when they came.
        assert received == sorted(received) and len(received) < 40, received
        assert received[-16:] == list(range(48, 64))
        client.close()
    finally:
        view.stop()


def test_a_client_that_takes_nothing_is_disconnected_and_logged(harness, monkeypatch):
    view = harness.node._live
    warnings = _warnings_of(view, monkeypatch)
    monkeypatch.setattr(live_server, 'STALL', 1.0)
    stalled = _Raw(harness.node.settings.live_port, receive_buffer=4096)
    try:
        # Asked for the 2 MB markers again and again (at most once a second), never reading.
        until = time.monotonic() + 60.0
        subscription = 1
        while view.status()['live_clients'] and time.monotonic() < until:
            stalled.subscribe(['/wafer_planner/roadmap_markers'], subscription)
            time.sleep(0.2)
            stalled.send({'op': 'unsubscribe', 'subscriptionIds': [subscription]})
            subscription += 1
    except OSError:
        pass  # closed by the node while this was being sent
    finally:
        stalled.close()
    assert view.status()['live_clients'] == 0
    assert any('disconnected: it has not taken a message for 1 s' in w for w in warnings)


def test_the_view_listens_on_this_machine_unless_told_and_then_warns(harness):
    assert settings_from({}).live_host == '127.0.0.1'
    packaged = yaml.safe_load((ROOT / 'config' / 'wafer_planner.yaml').read_text())
    assert packaged['/**']['ros__parameters']['live'] == {'port': 0, 'host': '127.0.0.1',
                                                          'max_clients': 4,
                                                          'robot': '/wafer_sim'}
    lines = []
    log = SimpleNamespace(error=lines.append, info=lines.append, warning=lines.append)
    publisher = SimpleNamespace(topic_name='/wafer_planner/roadmap_markers',
                                msg_type=MarkerArray)
    view = LiveView('/wafer_planner', [publisher], publisher, log)
    port = _free_port()
    try:
        assert view.start('127.0.0.1', port) and len(lines) == 1
        assert lines[0].startswith(f'live view: Foxglove WebSocket on ws://127.0.0.1:{port} ')
        assert view.start('0.0.0.0', port) and len(lines) == 3
        assert lines[2] == (f'live view: listening on 0.0.0.0 (live.host), not only on this '
                            'machine, and the view has no authentication: anyone who reaches '
                            f'port {port} can watch (live.host 127.0.0.1 keeps it to this '
                            'machine)')
    finally:
        view.stop()


def test_the_robot_is_shown_moving_its_joint_states_arm_and_wafer_acceleration_relayed(
        harness):
    peer = harness.peer
    publishers = {topic: peer.create_publisher(kind, topic, LATCHED if kind is MarkerArray
                                               else 10) for topic, kind in ROBOT.items()}
    wait_for(lambda: all(p.get_subscription_count() for p in publishers.values()), 20)
    sent = {'/joint_states': JointState(name=['shoulder', 'elbow', 'wrist'],
                                        position=[0.1, -0.2, 0.3], velocity=[1.0, 0.0, -1.0]),
            '/wafer_sim/wafer_acceleration': Float64MultiArray(data=[0.5, -0.25, 0.56, 0.57]),
            '/wafer_sim/arm_markers': markers_of(harness)}

    async def relayed(client, topic):
        # Published until it comes through: the view subscribes the client asynchronously.
        for _ in range(200):
            publishers[topic].publish(sent[topic])
            try:
                return await client.receive(topic, timeout=0.1)
            except asyncio.TimeoutError:
                continue
        raise AssertionError(f'{topic} was not relayed')

    async def run():
        client = await Client.connect(_url(harness))
        await client.subscribe(*ROBOT)
        got = {topic: await relayed(client, topic) for topic in ROBOT}
        await client.close()
        return got

    got = asyncio.run(run())
    sent['/wafer_sim/arm_markers'] = deserialize_message(sent['/wafer_sim/arm_markers'],
                                                         MarkerArray)
    assert got == sent  # each as it was published
    assert {m.ns for m in got['/wafer_sim/arm_markers'].markers} >= {'arm', 'arm_wafer'}


def markers_of(harness) -> bytes:
    """Return the arm's markers as the simulated arm publishes them (its CDR bytes)."""
    return markers.arm_markers(harness.node._worker.cell, [0.0, 0.5, -0.5], 'efem',
                               Time(sec=1))


def test_live_robot_names_the_robot_shown_and_a_bad_name_is_refused(harness):
    node = harness.node
    bad = node.set_parameters([Parameter('live.robot', value='2arm/x-y')])[0]
    assert not bad.successful and 'live.robot' in bad.reason
    assert settings_from({'live.robot': 'arm2'}).live_robot == '/arm2'
    try:
        assert node.set_parameters([Parameter('live.robot', value='cell3/arm')])[0].successful
        relayed = set(node._live.topics) - set(TOPICS)
        assert relayed == {'/cell3/arm/arm_markers', '/cell3/arm/wafer_acceleration'}
        assert node.set_parameters([Parameter('live.robot', value='')])[0].successful
        assert '/joint_states' in node._live.topics
        assert not any(t.endswith('/arm_markers') for t in node._live.topics)
    finally:
        node.set_parameters([Parameter('live.robot', value='/wafer_sim')])
    assert set(TOPICS) <= set(node._live.topics)
    harness.send_stations({'id': 'robot1', 'from': 'loadport1', 'to': 'loadlock1'})
    assert values(harness.result('robot1'))['code'] == 'OK'
