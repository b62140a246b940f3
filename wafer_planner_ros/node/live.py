"""
The live view: an optional Foxglove WebSocket server streaming what the node publishes.

With ``live.port`` set, the node serves the Foxglove WebSocket protocol (the SDK's
subprotocol ``foxglove.sdk.v1``) so that Foxglove shows it live on a machine without ROS.
Each published topic is a channel with the ``ros2msg`` schema the recording writes (the full
concatenated definition, ``recording.msgdefs``) and ``cdr`` messages: the very bytes that go
out on DDS. The roadmap markers are latched as on DDS: whoever subscribes is sent the last
ones. (The SDK's Python API cannot address one client, so the clients already subscribed get
them once more: the same markers, no change in what they show.) So is where the joint-space
frame stands beside the cell (``markers.joint_space_offset``), on ``<node>/frames`` as a
``foxglove.FrameTransform``: without ROS there is no ``/tf_static``, and Foxglove needs it
to show joint space beside the cell.

Only what some client has subscribed to is serialised and logged; logging copies it into
each subscribed client's bounded outbox (the SDK drops a slow client's oldest messages) and
never waits on a socket, so the executor is not held up (measured: about 1.6 ms per client
for the 2 MB roadmap markers, under 1 ms for a plan's path markers, microseconds for an
answer).
``foxglove-sdk`` is imported only when the view starts: without it, or when the port cannot
be bound, the error is logged naming the port, shown in the status, and the node serves on.
"""

import threading
from typing import Dict, Optional, Sequence

from rclpy.serialization import serialize_message

from wafer_planner_ros.node.faults import reason_of
from wafer_planner_ros.recording.msgdefs import definition

SDK = 'foxglove-sdk==0.30.3'
"""The SDK version the live view is made for (requirements.txt)."""


def type_name(msg_type) -> str:
    """Return ``pkg/msg/Type`` of a generated message class."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


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
        self.latched_topic = latched.topic_name
        self.log = log
        self._lock = threading.Lock()
        self._served: Optional[_Served] = None
        self._latched = None
        """The last latched message's bytes."""
        self._latched_lock = threading.Lock()
        self._failed = set()
        """Topics whose logging failed (logged once per start)."""
        self.frames_topic = f'{name.rstrip("/")}/frames'
        self._frame = None
        """(parent, child, translation) of the joint-space frame, latched like the markers."""
        self.error = ''

    def start(self, host: str, port: int) -> bool:
        """(Re)start serving on ``host:port`` (0: stop); return whether it serves."""
        with self._lock:
            self._stop()
            self.error, self._failed = '', set()
            if port == 0:
                return False
            try:
                self._served = _Served(self, host, port)
            except Exception as exc:  # noqa: B902 - the node serves on without it
                reason = (f'foxglove-sdk is not installed (pip install {SDK})'
                          if isinstance(exc, ImportError) else reason_of(exc, False))
                self.error = (f'live view not served on ws://{host}:{port} (live.port {port}): '
                              f'{reason}')
                self.log.error(f'{self.error}; the node serves on without it')
                return False
            url = self._served.url
        local = f', ws://localhost:{port} from this machine' if host == '0.0.0.0' else ''
        self.log.info(f'live view: Foxglove WebSocket on {url}{local} (Foxglove: Open '
                      'connection, Foxglove WebSocket)')
        return True

    def stop(self) -> None:
        """Stop serving (the clients are disconnected)."""
        with self._lock:
            self._stop()

    def publish(self, publisher, data) -> None:
        """Hand what ``publisher`` has just published (bytes or a message) on; never raise."""
        topic = ''
        try:
            topic = publisher.topic_name
            if topic == self.latched_topic:
                with self._latched_lock:  # never sent to anyone after a newer one
                    self._latched = data
                    self._resend(self._served)
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
                self._resend_frame(self._served)
        except Exception as exc:  # noqa: B902 - the live view must not stop the node
            if self.frames_topic not in self._failed:
                self._failed.add(self.frames_topic)
                self.log.error(f'live view: {self.frames_topic} not served: {reason_of(exc)} '
                               '(logged once)')

    def status(self) -> Dict[str, str]:
        """Return the live view's URL ('' when off) and why it does not serve ('' if none)."""
        served = self._served
        return {'live': served.url if served is not None else '', 'live_error': self.error}

    def resend_latched(self, served: '_Served', topic: str) -> None:
        """Log the latched message of ``topic`` again (a client has just subscribed to it)."""
        with self._latched_lock:
            if topic == self.latched_topic:
                self._resend(served)
            elif topic == self.frames_topic:
                self._resend_frame(served)

    def _resend_frame(self, served: Optional['_Served']) -> None:
        if served is not None and self._frame is not None and served.frames_subscribed():
            served.log_frame(*self._frame)

    def _resend(self, served: Optional['_Served']) -> None:
        if served is None or self._latched is None or not served.subscribed(self.latched_topic):
            return
        served.log(self.latched_topic, self._latched)

    def _stop(self) -> None:
        served, self._served = self._served, None
        if served is not None:
            try:
                served.stop()
            except Exception as exc:  # noqa: B902 - stopping must not stop the node
                self.log.error(f'live view: not stopped cleanly: {reason_of(exc)}')


class _Served:
    """A running server: a private SDK context, its channels and the WebSocket server."""

    def __init__(self, view: LiveView, host: str, port: int):
        import foxglove  # here: a node without the live view does not need the SDK
        import foxglove.channels
        import foxglove.messages
        from foxglove.websocket import ServerListener
        served = self

        class Listener(ServerListener):
            """Send the latched message to whoever subscribes to it."""

            def on_subscribe(self, client, channel) -> None:
                try:
                    if channel.topic in (view.latched_topic, view.frames_topic):
                        view.resend_latched(served, channel.topic)
                except Exception as exc:  # noqa: B902 - on the SDK's thread: never raise
                    view.log.error(f'live view: {channel.topic} not sent to client '
                                   f'{client.id}: {reason_of(exc)}')

        self._context = foxglove.Context()  # this node's channels only, not the process's
        self._messages = foxglove.messages
        self._frames = foxglove.channels.FrameTransformChannel(view.frames_topic,
                                                               context=self._context)
        self._channels = {
            topic: foxglove.Channel(
                topic, message_encoding='cdr', context=self._context,
                schema=foxglove.Schema(name=kind, encoding='ros2msg',
                                       data=definition(kind).encode()))
            for topic, kind in view.topics.items()}
        try:
            self._server = foxglove.start_server(name=view.name, host=host, port=port,
                                                 context=self._context,
                                                 server_listener=Listener())
        except Exception:
            self._close_channels()
            raise
        self.url = f"ws://{f'[{host}]' if ':' in host else host}:{self._server.port}"

    def subscribed(self, topic: str) -> bool:
        return self._channels[topic].has_sinks()

    def frames_subscribed(self) -> bool:
        return self._frames.has_sinks()

    def log_frame(self, parent: str, child: str, translation) -> None:
        x, y, z = translation
        self._frames.log(self._messages.FrameTransform(
            parent_frame_id=parent, child_frame_id=child,
            translation=self._messages.Vector3(x=x, y=y, z=z),
            rotation=self._messages.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))

    def log(self, topic: str, data: bytes) -> None:
        self._channels[topic].log(data)

    def stop(self) -> None:
        self._server.stop()
        self._close_channels()

    def _close_channels(self) -> None:
        for channel in (*self._channels.values(), self._frames):
            channel.close()
