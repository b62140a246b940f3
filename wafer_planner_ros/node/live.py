"""
The live view: the node's side of an optional Foxglove WebSocket server showing what it publishes.

With ``live.port`` set, the node serves the Foxglove WebSocket protocol (subprotocol
``foxglove.websocket.v1``) so that Foxglove shows it live on a machine without ROS. Each
published topic is a channel with the ``ros2msg`` schema the recording writes (the full
concatenated definition, ``recording.msgdefs``) and ``cdr`` messages: the very bytes that go
out on DDS. The roadmap markers are latched as on DDS: whoever subscribes is sent the last
ones. So is where the joint-space frame stands beside the cell
(``markers.joint_space_offset``), on ``<node>/frames`` as a ``foxglove.FrameTransform``
(``foxglove-sdk`` encodes it, in its own protobuf schema): without ROS there is no
``/tf_static``, and Foxglove needs it to show joint space beside the cell.

The view serves through its own WebSocket server (``live_server``: the protocol, the clients,
their bounded outboxes, who is admitted) in a thread of its own; this adapter is what the node
uses: it starts and stops that server as the ``live.*`` parameters say, hands it what the node
publishes and where the joint-space frame stands, and reports its address, error and clients in
the status. So what the view holds per client is at most its outbox, the message being sent
(once more, in the socket's buffer) and ``live_server.INCOMING`` of what it sent
(doc/operations.md, "Live view in Foxglove").
``foxglove-sdk`` and ``websockets`` are imported only when the view starts: without them,
or when the port cannot be bound, the error is logged naming the port, shown in the status,
and the node serves on.
"""

import ipaddress
import threading
from typing import Dict, Optional, Sequence

from rclpy.serialization import serialize_message

from wafer_planner_ros.node.faults import reason_of
from wafer_planner_ros.node.live_server import Client, Server

SDK = 'foxglove-sdk==0.30.3'
"""The SDK version the live view's frame transform is made with (requirements.txt)."""
WEBSOCKETS = 'websockets==17.4'
"""The WebSocket library the live view serves with (requirements.txt)."""


def type_name(msg_type) -> str:
    """Return ``pkg/msg/Type`` of a generated message class."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def local_only(host: str) -> bool:
    """Return whether listening on ``host`` keeps the view to this machine."""
    if host == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class LiveView:
    """Serve the node's topics to Foxglove while started; see the module's description."""

    def __init__(self, name: str, publishers: Sequence, latched, log):
        """
        Remember the topics of ``publishers``; serve nothing yet.

        ``latched`` is the publisher (one of them) whose last message a new subscriber gets;
        ``log`` a logger that never raises (``faults.SafeLogger``).
        """
        self.name = name
        self.topics = {p.topic_name: type_name(p.msg_type) for p in publishers}
        self._own = dict(self.topics)
        self.latched_topic = latched.topic_name
        self.log = log
        self._lock = threading.Lock()
        self._served: Optional[Server] = None
        self._latched = None
        """The last latched message's bytes."""
        self._latched_lock = threading.Lock()
        self._failed = set()
        """Topics whose logging failed (logged once per start)."""
        self.frames_topic = f'{name.rstrip("/")}/frames'
        self._frame = None
        """(parent, child, translation) of the joint-space frame, latched like the markers."""
        self.error = ''

    def start(self, host: str, port: int, max_clients: int = 4) -> bool:
        """(Re)start serving on ``host:port`` (0: stop); return whether it serves."""
        with self._lock:
            self._stop()
            self.error, self._failed = '', set()
            if port == 0:
                return False
            try:
                self._served = Server(self, host, port, max_clients)
            except Exception as exc:  # noqa: B902 - the node serves on without it
                if isinstance(exc, ImportError):
                    needed = WEBSOCKETS if (exc.name or '').startswith('websockets') else SDK
                    reason = f"{needed.split('==')[0]} is not installed (pip install {needed})"
                else:
                    reason = reason_of(exc, False)
                self.error = (f'live view not served on ws://{host}:{port} (live.port {port}): '
                              f'{reason}')
                self.log.error(f'{self.error}; the node serves on without it')
                return False
            url = self._served.url
        local = f', ws://localhost:{port} from this machine' if host == '0.0.0.0' else ''
        self.log.info(f'live view: Foxglove WebSocket on {url}{local} (Foxglove: Open '
                      f'connection, Foxglove WebSocket; at most {max_clients} clients, '
                      'live.max_clients)')
        if not local_only(host):
            self.log.warning(f'live view: listening on {host} (live.host), not only on this '
                             'machine, and the view has no authentication: anyone who reaches '
                             f'port {port} can watch (live.host 127.0.0.1 keeps it to this '
                             'machine)')
        return True

    def relay(self, subscriptions: Sequence) -> None:
        """
        Serve the topics of ``subscriptions`` too (another node's, ``live_robot``), not others.

        They are advertised from the next ``start`` on; their messages come to ``publish``.
        """
        self.topics = {**self._own, **{s.topic_name: type_name(s.msg_type)
                                       for s in subscriptions}}

    def stop(self) -> None:
        """Stop serving (the clients are disconnected at once)."""
        with self._lock:
            self._stop()

    def publish(self, publisher, data) -> None:
        """Hand what ``publisher`` has just published (bytes or a message) on; never raise."""
        topic = ''
        try:
            topic = publisher.topic_name
            if topic == self.latched_topic:
                with self._latched_lock:  # never sent to anyone after a newer one
                    self._latched = data if isinstance(data, bytes) else serialize_message(data)
                    served = self._served
                    if served is not None and served.subscribed(topic):
                        served.log(topic, self._latched)
                return
            served = self._served
            if served is None or not served.subscribed(topic):
                return  # nothing to serialise it for
            served.log(topic, data if isinstance(data, bytes) else serialize_message(data))
        except Exception as exc:  # noqa: B902 - the live view must not stop an answer
            if topic not in self._failed:
                self._failed.add(topic)
                self.log.error(f'live view: {topic} not served: {reason_of(exc)} '
                               '(logged once per topic)')

    def frame(self, parent: str, child: str, translation) -> None:
        """Hand on where frame ``child`` stands in ``parent`` (m, not rotated); never raise."""
        try:
            with self._latched_lock:
                self._frame = (parent, child, tuple(float(v) for v in translation))
                served = self._served
                if served is not None and served.subscribed(self.frames_topic):
                    served.log_frame(self._frame)
        except Exception as exc:  # noqa: B902 - the live view must not stop the node
            if self.frames_topic not in self._failed:
                self._failed.add(self.frames_topic)
                self.log.error(f'live view: {self.frames_topic} not served: {reason_of(exc)} '
                               '(logged once)')

    def status(self) -> Dict:
        """Return the live view's URL ('' when off), why it does not serve, its clients."""
        served = self._served
        return {'live': served.url if served is not None else '', 'live_error': self.error,
                'live_clients': served.clients() if served is not None else 0}

    def resend_latched(self, served: Server, client: Client, topic: str) -> None:
        """Log the latched message of ``topic`` to ``client`` (it has subscribed to it)."""
        with self._latched_lock:
            if topic == self.latched_topic and self._latched is not None:
                served.log(topic, self._latched, client)
            elif topic == self.frames_topic and self._frame is not None:
                served.log_frame(self._frame, client)

    def _stop(self) -> None:
        served, self._served = self._served, None
        if served is not None:
            try:
                served.stop()
            except Exception as exc:  # noqa: B902 - stopping must not stop the node
                self.log.error(f'live view: not stopped cleanly: {reason_of(exc)}')
