"""The node as its own process, asked over DDS on loopback by wafer-plan-client."""

import os
import signal
import subprocess
import sys

import pytest

pytest.importorskip('rclpy')


@pytest.fixture()
def dds_env(tmp_path):
    """Return an environment confined to loopback and a domain of this test run."""
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))  # a run may pick its own
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_LOG_DIR=str(tmp_path / 'log'))
    return env


# A peer sending the request, found by a fuzzer, that once ended the node: an integer no
# float holds (the client's own JSON writes it in full).
OVERFLOWING = """
import rclpy
from wafer_planner_ros.node.client import _Client
rclpy.init()
answer = _Client('/wafer_planner').ask(
    {'id': 'overflow', 'from': [10 ** 400, 0, 0], 'to': 'loadlock1'}, 120)
print(answer[0].message if answer else 'no answer')
rclpy.try_shutdown()
"""


def _client(env, *args):
    return subprocess.run([sys.executable, '-m', 'wafer_planner_ros.node.client', *args,
                           '--timeout', '120'], env=env, capture_output=True, text=True,
                          timeout=300)


def test_node_process_answers_the_client_and_stops_on_sigint(
        dds_env, roadmap_cache, tmp_path, default_roadmap):
    node = subprocess.Popen(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
         '-p', 'planning.station_table:=false', '-p', 'planning.optimise_budget:=0.0',
         '-p', f'roadmap.cache_dir:={roadmap_cache}', '-p', 'planning.timeout:=60.0',
         '-p', f'recording.directory:={tmp_path / "recordings"}'],
        env=dds_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ok = _client(dds_env, 'loadport1', 'loadlock2', '--id', 'p1')
        assert ok.returncode == 0, ok.stdout + ok.stderr
        assert 'p1: ok: loadport1 -> loadlock2' in ok.stdout
        assert 'cycle_time:' in ok.stdout and 'trajectory:' in ok.stdout
        bad = _client(dds_env, 'loadport1', 'nowhere', '--id', 'p2')
        assert bad.returncode == 1
        assert 'UNKNOWN_STATION' in bad.stdout
        fuzzed = subprocess.run([sys.executable, '-c', OVERFLOWING], env=dds_env,
                                capture_output=True, text=True, timeout=300)
        assert fuzzed.stdout.strip() == \
            'NOT_FINITE: "from"[0] is not a finite number (401 digits)', fuzzed.stderr
        assert node.poll() is None  # still running, still ready and answering
        again = _client(dds_env, 'loadport2', 'loadlock1', '--id', 'p3')
        assert again.returncode == 0, again.stdout + again.stderr
        # Joint angles that start with '-' are an end, not an unknown option.
        negative = _client(dds_env, '-2.4303,-1.5807,-0.7014', 'loadlock1', '--id', 'p4')
        assert negative.returncode == 0, negative.stdout + negative.stderr
        assert 'p4: ok:' in negative.stdout
    finally:
        node.send_signal(signal.SIGINT)
        output, _ = node.communicate(timeout=60)
    assert node.returncode == 0, output
    # The roadmap the tests built for the same cell and settings (not a size written here).
    assert (f'ready: roadmap {default_roadmap.node_count} nodes, {default_roadmap.edge_count} '
            f'edges, hash {default_roadmap.digest[:12]}') in output


def test_node_process_rejects_a_bad_parameter(dds_env):
    node = subprocess.run(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
         '-p', 'planning.station_table:=false', '-p', 'planning.optimise_budget:=0.0',
         '-p', 'planning.max_queue:=0'], env=dds_env, capture_output=True, text=True,
        timeout=120)
    assert node.returncode != 0
    assert 'planning.max_queue' in node.stdout + node.stderr


def test_launch_file_describes_the_node():
    pytest.importorskip('launch')
    pytest.importorskip('launch_ros')
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / 'launch' / 'wafer_planner.launch.py'
    spec = importlib.util.spec_from_file_location('wafer_planner_launch', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert any(type(e).__name__ == 'Node' for e in description.entities)
