"""
Benchmark: the live view (``live.port``) under clients that subscribe and never read.

The node is started as a process (``python -m wafer_planner_ros.node.main``, this checkout's
code) with the live view on loopback, recording and the station table off. Then, for 1 and
for 20 clients with the default ``live.max_clients`` (4), and for 20 with ``live.max_clients``
20 (``--runs CLIENTS:MAX_CLIENTS ...``): each connects (a raw WebSocket, so that nothing reads its
socket after the channels are advertised: no client library buffering for it), then
subscribes to the roadmap markers (2 MB, latched) and unsubscribes again, as fast as it can,
for ``--seconds`` (3); the node's resident memory is sampled every 50 ms (the attack stops
early once it passes ``--limit-mb``, 4000, so that the machine is not exhausted). Then SIGINT
with every client still connected, and how long until the process has ended (killed after
60 s). Clients the node refuses (``live.max_clients``) are counted.

Prints a table; writes ``bench/results/live.json``. Usage:
``python bench/bench_live.py [--runs 1:4 20:4 20:20] [--seconds S] [--limit-mb MB]``.
"""

import argparse
import base64
import json
import os
from pathlib import Path
import platform
import queue
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / 'bench' / 'results' / 'live.json'
ROADMAP_MARKERS = '/wafer_planner/roadmap_markers'
KILL_AFTER = 60.0
"""s after SIGINT before the node is killed."""


def free_port() -> int:
    """Return a TCP port free on loopback now."""
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


class Node:
    """The node as a process with the live view on ``port``, its log read line by line."""

    def __init__(self, port: int, cache: str, max_clients: int):
        env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                   ROS_DOMAIN_ID=str(30 + os.getpid() % 50), ROS_LOG_DIR=tempfile.mkdtemp(),
                   PYTHONUNBUFFERED='1',
                   PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT),
                                                            os.environ.get('PYTHONPATH')])))
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'wafer_planner_ros.node.main', '--ros-args',
             '-p', 'planning.station_table:=false', '-p', 'recording.enabled:=false',
             '-p', f'roadmap.cache_dir:={cache}', '-p', 'live.host:=127.0.0.1',
             '-p', f'live.port:={port}', '-p', f'live.max_clients:={max_clients}'],
            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines = queue.Queue()
        self.log = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.put(line.rstrip())

    def wait_for(self, text: str, timeout: float) -> str:
        """Return the first line holding ``text``."""
        until = time.monotonic() + timeout
        while time.monotonic() < until:
            try:
                line = self.lines.get(timeout=0.05)
            except queue.Empty:
                continue
            self.log.append(line)
            if text in line:
                return line
        raise RuntimeError(f'no {text!r} within {timeout} s:\n' + '\n'.join(self.log[-20:]))

    def rss_mb(self) -> float:
        """Return the process's resident memory (MB; 0 once it has ended)."""
        try:
            status = Path(f'/proc/{self.process.pid}/status').read_text()
        except OSError:
            return 0.0
        for line in status.splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
        return 0.0

    def stop(self) -> float:
        """Send SIGINT; return the seconds until the process has ended (inf: killed)."""
        begun = time.monotonic()
        self.process.send_signal(signal.SIGINT)
        try:
            self.process.wait(timeout=KILL_AFTER)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            return float('inf')
        return time.monotonic() - begun


class Stalled:
    """A WebSocket client that reads the advertisements, then never reads again."""

    def __init__(self, port: int):
        """Connect; ``refused`` tells whether the node refused the connection."""
        self.sock = socket.create_connection(('127.0.0.1', port), timeout=20)
        self.refused, self.sent, self._buffer = False, 0, b''
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n'
             f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n'
             'Sec-WebSocket-Version: 13\r\n'
             'Sec-WebSocket-Protocol: foxglove.sdk.v1, foxglove.websocket.v1\r\n\r\n').encode())
        head = self._until(b'\r\n\r\n')
        if head is None or b' 101 ' not in head.split(b'\r\n', 1)[0]:
            self.refused = True
            return
        self.channel = None
        while self.channel is None:
            frame = self._frame()
            if frame is None:  # closed: refused after the handshake
                self.refused = True
                return
            opcode, payload = frame
            if opcode == 1:
                message = json.loads(payload)
                if message.get('op') == 'advertise':
                    self.channel = next((c['id'] for c in message['channels']
                                         if c['topic'] == ROADMAP_MARKERS), None)

    def _read(self) -> bool:
        try:
            chunk = self.sock.recv(1 << 16)
        except OSError:
            return False
        self._buffer += chunk
        return bool(chunk)

    def _until(self, end: bytes):
        while end not in self._buffer:
            if not self._read():
                return None
        head, self._buffer = self._buffer.split(end, 1)
        return head

    def _exactly(self, count: int):
        while len(self._buffer) < count:
            if not self._read():
                return None
        data, self._buffer = self._buffer[:count], self._buffer[count:]
        return data

    def _frame(self):
        head = self._exactly(2)
        if head is None or head[0] & 0x0F == 8:
            return None
        length = head[1] & 0x7F
        if length >= 126:
            extended = self._exactly(2 if length == 126 else 8)
            length = struct.unpack('>H' if length == 126 else '>Q', extended)[0]
        payload = self._exactly(length)
        return None if payload is None else (head[0] & 0x0F, payload)

    def send(self, message: dict) -> None:
        """Send ``message`` as a masked text frame."""
        data = json.dumps(message).encode()
        mask = os.urandom(4)
        masked = bytes(b ^ mask[k % 4] for k, b in enumerate(data))
        header = bytes([0x81, 0x80 | len(data)]) if len(data) < 126 else \
            bytes([0x81, 0x80 | 126]) + struct.pack('>H', len(data))
        self.sock.sendall(header + mask + masked)
        self.sent += 1

    def churn(self, until: threading.Event) -> None:
        """Subscribe to the roadmap markers and unsubscribe, until ``until`` is set."""
        subscribe = {'op': 'subscribe', 'subscriptions': [{'id': 1, 'channelId': self.channel}]}
        try:
            while not until.is_set():
                self.send(subscribe)
                self.send({'op': 'unsubscribe', 'subscriptionIds': [1]})
        except OSError:
            pass  # the node closed the connection (or stopped reading it for 20 s)

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


def attack(clients: int, max_clients: int, seconds: float, limit_mb: float,
           cache: str) -> dict:
    """Run one attack on a fresh node; return its figures."""
    port = free_port()
    node = Node(port, cache, max_clients)
    try:
        node.wait_for('live view: ', 60.0)
        node.wait_for('ready: ', 300.0)
        time.sleep(1.0)  # the roadmap markers are published just after ready
        before = node.rss_mb()
        stalled = [Stalled(port) for _ in range(clients)]
        admitted = [s for s in stalled if not s.refused]
        stop = threading.Event()
        threads = [threading.Thread(target=s.churn, args=(stop,), daemon=True)
                   for s in admitted]
        begun = time.monotonic()
        for thread in threads:
            thread.start()
        peak, limited = before, None
        while time.monotonic() - begun < seconds:
            peak = max(peak, node.rss_mb())
            if peak > limit_mb:
                limited = time.monotonic() - begun
                break
            time.sleep(0.05)
        stop.set()
        for thread in threads:
            thread.join(timeout=10)
        time.sleep(0.5)
        peak = max(peak, node.rss_mb())
        exit_s = node.stop()  # every client still connected
    finally:
        if node.process.poll() is None:
            node.process.kill()
            node.process.wait()
    for s in stalled:
        s.close()
    return {'clients': clients, 'max_clients': max_clients, 'admitted': len(admitted),
            'refused': clients - len(admitted),
            'messages_sent': sum(s.sent for s in admitted), 'rss_before_mb': round(before, 1),
            'rss_peak_mb': round(peak, 1), 'growth_mb': round(peak - before, 1),
            'attack_s': round(limited if limited is not None else seconds, 2),
            'stopped_at_limit': limited is not None,
            'exit_after_sigint_s': exit_s if exit_s == float('inf') else round(exit_s, 3)}


def main() -> int:
    """Run the benchmark; print and store the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--runs', nargs='+', default=['1:4', '20:4', '20:20'],
                        help='CLIENTS:MAX_CLIENTS (live.max_clients) of each run')
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--limit-mb', type=float, default=4000.0)
    parser.add_argument('--cache-dir', default=str(Path('~/.cache/wafer_planner_ros')
                                                   .expanduser()))
    args = parser.parse_args()
    runs = []
    for spec in args.runs:
        clients, max_clients = (int(v) for v in spec.split(':'))
        run = attack(clients, max_clients, args.seconds, args.limit_mb, args.cache_dir)
        runs.append(run)
        limit = ' (stopped at the limit)' if run['stopped_at_limit'] else ''
        print(f"{clients:3d} clients, live.max_clients {max_clients} ({run['admitted']} "
              f"admitted, {run['refused']} refused), "
              f"{run['messages_sent']} (un)subscribes in {run['attack_s']:.1f} s: RSS "
              f"{run['rss_before_mb']:.0f} -> {run['rss_peak_mb']:.0f} MB "
              f"(+{run['growth_mb']:.0f}){limit}; exit after SIGINT "
              f"{run['exit_after_sigint_s']:.2f} s", flush=True)
    results = {'machine': {'cpus': os.cpu_count(), 'python': platform.python_version()},
               'seconds': args.seconds, 'runs': runs}
    RESULTS.write_text(json.dumps(results, indent=1) + '\n')
    print(f'written {RESULTS}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
