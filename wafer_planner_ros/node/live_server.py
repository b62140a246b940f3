"""
The live view's server: the Foxglove WebSocket protocol, its clients, their bounded outboxes.

The server is the node's own, on ``websockets``, in a thread of its own with its own event loop
(``live.LiveView`` starts and stops it, and hands it what the node publishes); the SDK's server
bounds a client's outbox by messages only (1024 of them: 2 GB of roadmap markers), cannot refuse
a client and, stopping, waits for its clients. Here:

- Only what some client has subscribed to is serialised; logging it puts a reference to the
  bytes into each subscribed client's outbox and never waits on a socket, so the executor is
  not held up. An outbox holds at most ``OUTBOX_BYTES``: a client that reads too slowly
  loses its oldest messages (logged once per client); the newest is always kept, even alone
  larger than that. A client that has not taken a message for ``STALL`` seconds is
  disconnected (logged); one that has gone without closing is noticed by the next ping
  (``PING``).
- The latched messages go to the client that subscribes, at most once per
  ``LATCHED_PERIOD`` per channel and client (one subscribing again sooner gets them when the
  period is up); unsubscribing drops what its outbox still holds for that subscription.
- At most ``live.max_clients`` clients at once: one more is refused (HTTP 503, logged at
  most every ``REFUSED_LOG_PERIOD``), and connections still in their opening handshake are
  limited to ``HANDSHAKES`` more (closed at once beyond).
- A client's messages are taken at ``INCOMING_RATE`` a second at most: beyond, its socket
  is not read until their time comes, so that a flood of them cannot keep the server's
  thread (and the GIL) busy; its socket's receive buffer is ``RECEIVE_BUFFER``, so that one
  read (parsed whole) stays small.
- Stopping shuts every client's socket down at once, from the stopping thread, however busy
  the server's thread is (unsent data is dropped); then the server's thread closes the
  listening socket, waited for at most ``STOP_WAIT`` (the thread is a daemon).
"""

import asyncio
import base64
from collections import deque
import http
import json
import logging
import socket
import struct
import threading
import time
from typing import Dict, Optional

from wafer_planner_ros.node.faults import reason_of
from wafer_planner_ros.recording.msgdefs import definition

SUBPROTOCOL = 'foxglove.websocket.v1'
MIB = 1 << 20
OUTBOX_BYTES = 16 * MIB
"""Bytes of messages a client's outbox holds at most (the newest is always kept)."""
LATCHED_PERIOD = 1.0
"""s: a client is sent a channel's latched message at most once in this."""
STALL = 30.0
"""s a client may take to accept one message before it is disconnected."""
HANDSHAKES = 8
"""Connections in their opening handshake allowed beyond ``live.max_clients``."""
INCOMING = (1 << 16, 16)
"""Largest message a client may send (bytes), and how many are buffered from it at most."""
RECEIVE_BUFFER = 8192
"""Bytes of a client's socket's receive buffer (the kernel may double it)."""
INCOMING_RATE = 100
"""Messages a second taken from a client; beyond, it waits (its socket is not read)."""
OPEN_TIMEOUT = 5.0
"""s a connection may take for its opening handshake."""
PING = (5.0, 20.0)
"""s between pings to each client (noticing one gone), and how long its answer may take."""
REFUSED_LOG_PERIOD = 10.0
"""s between log lines about refused clients (the first is logged at once)."""
START_WAIT = 10.0
"""s the view waits for its server to listen."""
STOP_WAIT = 1.0
"""s a stopping view waits for its server's thread."""
MESSAGE_DATA = 0x01
"""The opcode of a binary message-data frame (server to client)."""


class Client:
    """A connected client: its subscriptions and its outbox."""

    def __init__(self, number: int, connection):
        self.number = number
        self.connection = connection
        peer = connection.remote_address
        self.address = f'{peer[0]}:{peer[1]}' if peer else '?'
        self.subscriptions: Dict[int, int] = {}
        """subscription id -> channel id."""
        self.by_channel: Dict[int, int] = {}
        """channel id -> subscription id (one per channel)."""
        self.outbox = deque()
        """(subscription id, log time ns, bytes) waiting to be sent."""
        self.queued = 0
        """Bytes in the outbox."""
        self.dropped = 0
        self.wake = asyncio.Event()
        self.latched_at: Dict[int, float] = {}
        """channel id -> when its latched message was last sent (loop time)."""
        self.pending: Dict[int, asyncio.TimerHandle] = {}
        """channel id -> the latched message's sending, deferred to the end of its period."""

    def __str__(self) -> str:
        return f'client {self.number} ({self.address})'


class Server:
    """A running server: its thread and event loop, its channels, its clients."""

    def __init__(self, view, host: str, port: int, max_clients: int):
        """Serve ``view`` (a ``live.LiveView``) on ``host:port`` in a thread; raise if not."""
        import foxglove.messages  # here: a node without the live view needs neither
        from websockets.asyncio.server import serve, ServerConnection
        from websockets.exceptions import ConnectionClosed
        from websockets.protocol import State
        served = self

        class Connection(ServerConnection):
            """A connection that the server knows of from its first moment to its last."""

            def connection_made(self, transport) -> None:
                super().connection_made(transport)
                sock = transport.get_extra_info('socket')
                try:  # what one read takes from a client (parsed whole) stays small
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
                except OSError:  # gone already: the next read says so
                    pass
                with served._lock:
                    served._open[self] = sock
                    over = len(served._open) > served.max_clients + HANDSHAKES
                if over:
                    served._refused(self, 'connections')
                    transport.abort()

            def connection_lost(self, exc) -> None:
                with served._lock:
                    served._open.pop(self, None)
                super().connection_lost(exc)

        self.view = view
        self.max_clients = max_clients
        self._messages = foxglove.messages
        self._closed = ConnectionClosed
        self._open_state = State.OPEN
        self._lock = threading.Lock()
        """Guards the clients, their subscriptions and outboxes (the executor logs)."""
        self._clients = []
        self._open = {}
        """Every connection, from its opening handshake on, and its socket."""
        self._halted = threading.Event()
        """Set once the clients' connections and the listening socket are closed."""
        self._numbers = 0
        self._refusals, self._refused_logged = 0, -REFUSED_LOG_PERIOD
        self._stopped = False
        topics = list(view.topics.items()) + [(view.frames_topic, None)]
        self._ids = {topic: k + 1 for k, (topic, _) in enumerate(topics)}
        self._topics = {k: topic for topic, k in self._ids.items()}
        self._subscribers = dict.fromkeys(self._topics, 0)
        """channel id -> how many clients have subscribed to it."""
        self._latched = {self._ids[view.latched_topic], self._ids[view.frames_topic]}
        frame_schema = self._messages.FrameTransform.get_schema()
        channels = [{'id': self._ids[topic], 'topic': topic, 'encoding': 'cdr',
                     'schemaName': kind, 'schema': definition(kind),
                     'schemaEncoding': 'ros2msg'} for topic, kind in view.topics.items()]
        channels.append({'id': self._ids[view.frames_topic], 'topic': view.frames_topic,
                         'encoding': 'protobuf', 'schemaName': frame_schema.name,
                         'schema': base64.b64encode(frame_schema.data).decode(),
                         'schemaEncoding': 'protobuf'})
        self._greeting = [
            json.dumps({'op': 'serverInfo', 'name': view.name, 'capabilities': [],
                        'supportedEncodings': [], 'metadata': {},
                        'sessionId': str(time.time_ns())}),
            json.dumps({'op': 'advertise', 'channels': channels})]
        quiet = logging.getLogger(f'{__name__}.websockets')  # a client's faults: not the node's
        quiet.propagate = False
        if not quiet.handlers:
            quiet.addHandler(logging.NullHandler())

        async def listen():
            return await serve(
                self._serve_client, host, port, create_connection=Connection,
                process_request=self._admit, subprotocols=[SUBPROTOCOL], compression=None,
                open_timeout=OPEN_TIMEOUT, ping_interval=PING[0], ping_timeout=PING[1],
                close_timeout=1.0, max_size=INCOMING[0],
                max_queue=INCOMING[1], logger=quiet)

        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run, name='live view', daemon=True)
        self._thread.start()
        try:
            self._server = asyncio.run_coroutine_threadsafe(listen(), self._loop).result(
                START_WAIT)
        except BaseException:
            self._server = None
            self.stop()
            raise
        bound = self._server.sockets[0].getsockname()[1]
        self.url = f"ws://{f'[{host}]' if ':' in host else host}:{bound}"

    def subscribed(self, topic: str) -> bool:
        """Return whether some client has subscribed to ``topic``."""
        return self._subscribers[self._ids[topic]] > 0

    def clients(self) -> int:
        """Return how many clients are connected."""
        return len(self._clients)

    def log_frame(self, frame, client: Optional[Client] = None) -> None:
        """Log ``frame`` (parent, child, translation) as a ``foxglove.FrameTransform``."""
        parent, child, (x, y, z) = frame
        messages = self._messages
        self.log(self.view.frames_topic, messages.FrameTransform(
            parent_frame_id=parent, child_frame_id=child,
            translation=messages.Vector3(x=x, y=y, z=z),
            rotation=messages.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)).encode(), client)

    def log(self, topic: str, data: bytes, client: Optional[Client] = None) -> None:
        """Put ``data`` into the outbox of every client subscribed to ``topic`` (or one)."""
        channel, now, dropping = self._ids[topic], time.time_ns(), []
        with self._lock:
            if self._stopped:
                return
            targets = [c for c in ([client] if client is not None else self._clients)
                       if channel in c.by_channel]
            for target in targets:
                if self._put(target, channel, now, data):
                    dropping.append(target)
        for target in dropping:
            self.view.log.warning(f'live view: {target} reads too slowly: its oldest messages '
                                  f'are dropped (its outbox holds {OUTBOX_BYTES // MIB} MiB; '
                                  'logged once per client)')
        for target in targets:
            try:
                self._loop.call_soon_threadsafe(target.wake.set)
            except RuntimeError:  # the loop has just been closed: the view is stopping
                return

    def stop(self) -> None:
        """Close every client's socket, then the listening one; never wait long."""
        with self._lock:
            self._stopped = True
            self._clients = []
            sockets = list(self._open.values())
        # At once, from this thread: however busy the server's thread is, no client is
        # sent or read anything more, and each sees its connection end.
        for sock in sockets:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:  # not connected (any more)
                pass
        try:
            self._loop.call_soon_threadsafe(self._halt)
        except RuntimeError:  # closed already
            pass
        self._halted.wait(STOP_WAIT)  # the rest ends with the (daemon) thread

    # ------------------------------------------------- on the server's thread from here on

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_forever()
            tasks = asyncio.all_tasks(self._loop)
            for task in tasks:
                task.cancel()
            if tasks:
                self._loop.run_until_complete(asyncio.wait(tasks, timeout=STOP_WAIT / 2))
        finally:
            self._loop.close()

    def _halt(self) -> None:
        with self._lock:
            connections = list(self._open)
        for connection in connections:
            connection.transport.abort()
        server = getattr(self, '_server', None)
        if server is not None:
            server.server.close()  # the listening socket, closed now
        self._halted.set()
        self._loop.stop()

    def _put(self, client: Client, channel: int, now: int, data: bytes) -> bool:
        """Queue ``data`` for ``client`` (under the lock); return whether it first drops."""
        first = False
        while client.outbox and client.queued + len(data) > OUTBOX_BYTES:
            client.queued -= len(client.outbox.popleft()[2])
            first = first or client.dropped == 0
            client.dropped += 1
        client.outbox.append((client.by_channel[channel], now, data))
        client.queued += len(data)
        return first

    def _admit(self, connection, request):
        if len(self._clients) < self.max_clients:
            return None
        self._refused(connection, 'clients')
        return connection.respond(http.HTTPStatus.SERVICE_UNAVAILABLE,
                                  f'the live view serves at most {self.max_clients} clients '
                                  'at once (live.max_clients)\n')

    def _refused(self, connection, what: str) -> None:
        self._refusals += 1
        now = time.monotonic()
        if now - self._refused_logged < REFUSED_LOG_PERIOD:
            return
        peer = connection.transport.get_extra_info('peername') or ('?', '?')
        more = self._refusals - 1
        since = f'; {more} more refused since the last such line' if more else ''
        limit = f'{self.max_clients} clients' if what == 'clients' else \
            f'{self.max_clients} clients and {HANDSHAKES} opening connections'
        self.view.log.warning(f'live view: a client from {peer[0]}:{peer[1]} refused: '
                              f'{limit} at most (live.max_clients {self.max_clients}){since}')
        self._refusals, self._refused_logged = 0, now

    async def _serve_client(self, connection) -> None:
        with self._lock:
            full = len(self._clients) >= self.max_clients
            if not full:
                self._numbers += 1
                client = Client(self._numbers, connection)
                self._clients.append(client)
        if full:  # admitted in the same moment as another one
            self._refused(connection, 'clients')
            await connection.close(1013, 'too many clients (live.max_clients)')
            return
        writer = None
        try:
            for text in self._greeting:
                if not await self._send(client, text):
                    return
            writer = asyncio.create_task(self._write(client))
            began, taken = self._loop.time(), 0
            async for message in connection:
                taken += 1
                if taken > INCOMING_RATE:  # a flood: taken at the rate, the rest waits
                    await asyncio.sleep(max(0.0, began + 1.0 - self._loop.time()))
                    began, taken = self._loop.time(), 1
                if connection.state is not self._open_state:
                    break  # gone: what it sent before is not waited for
                if isinstance(message, str):
                    self._on_message(client, message)
        except self._closed:
            pass
        finally:
            if writer is not None:
                writer.cancel()
            self._forget(client)

    async def _write(self, client: Client) -> None:
        while True:
            await client.wake.wait()
            client.wake.clear()
            while True:
                with self._lock:
                    if not client.outbox:
                        break
                    subscription, stamp, data = client.outbox.popleft()
                    client.queued -= len(data)
                header = struct.pack('<BIQ', MESSAGE_DATA, subscription, stamp)
                if not await self._send(client, [header, data]):  # data is not copied
                    return

    async def _send(self, client: Client, message) -> bool:
        """Send ``message``; return False if it stalled (the client is disconnected)."""
        try:
            async with asyncio.timeout(STALL):
                await client.connection.send(message)
            return True
        except TimeoutError:
            self.view.log.warning(f'live view: {client} disconnected: it has not taken a '
                                  f'message for {STALL:g} s')
            client.connection.transport.abort()
            return False
        except self._closed:  # gone: its handler forgets it
            return False

    def _on_message(self, client: Client, text: str) -> None:
        try:
            message = json.loads(text)
            if message.get('op') == 'subscribe':
                for subscription in message['subscriptions']:
                    self._subscribe(client, subscription['id'], subscription['channelId'])
            elif message.get('op') == 'unsubscribe':
                for subscription in message['subscriptionIds']:
                    self._unsubscribe(client, subscription)
        except (ValueError, TypeError, KeyError, AttributeError):
            return  # not the protocol: ignored (nothing else is offered)

    def _subscribe(self, client: Client, subscription, channel) -> None:
        if not (_id(subscription) and channel in self._topics) or \
                subscription in client.subscriptions or channel in client.by_channel:
            return
        with self._lock:
            client.subscriptions[subscription] = channel
            client.by_channel[channel] = subscription
            self._subscribers[channel] += 1
        if channel in self._latched:
            wait = client.latched_at.get(channel, -LATCHED_PERIOD) + LATCHED_PERIOD - \
                self._loop.time()
            if wait <= 0:
                self._send_latched(client, channel)
            elif channel not in client.pending:
                client.pending[channel] = self._loop.call_later(wait, self._send_latched,
                                                                client, channel)

    def _send_latched(self, client: Client, channel: int) -> None:
        client.pending.pop(channel, None)
        if channel not in client.by_channel:
            return
        client.latched_at[channel] = self._loop.time()
        try:
            self.view.resend_latched(self, client, self._topics[channel])
        except Exception as exc:  # noqa: B902 - on the server's thread: never raise
            self.view.log.error(f'live view: {self._topics[channel]} not sent to {client}: '
                                f'{reason_of(exc)}')

    def _unsubscribe(self, client: Client, subscription) -> None:
        if not _id(subscription) or subscription not in client.subscriptions:
            return
        with self._lock:
            channel = client.subscriptions.pop(subscription)
            del client.by_channel[channel]
            self._subscribers[channel] -= 1
            kept = deque(item for item in client.outbox if item[0] != subscription)
            client.queued -= sum(len(item[2]) for item in client.outbox) - \
                sum(len(item[2]) for item in kept)
            client.outbox = kept
        pending = client.pending.pop(channel, None)
        if pending is not None:
            pending.cancel()

    def _forget(self, client: Client) -> None:
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)
            for channel in client.by_channel:
                self._subscribers[channel] -= 1
            client.subscriptions, client.by_channel = {}, {}
            client.outbox, client.queued = deque(), 0
        for pending in client.pending.values():
            pending.cancel()
        if client.dropped:
            self.view.log.info(f'live view: {client} gone; {client.dropped} messages were '
                               'dropped for it (read too slowly)')


def _id(value) -> bool:
    """Return whether ``value`` is a subscription id (an unsigned 32-bit integer)."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 1 << 32
