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
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(100 + os.getpid() % 100), ROS_LOG_DIR=str(tmp_path / 'log'))
    return env


def _client(env, *args):
    return subprocess.run([sys.executable, '-m', 'wafer_planner_ros.node.client', *args,
                           '--timeout', '120'], env=env, capture_output=True, text=True,
                          timeout=300)


def test_node_process_answers_the_client_and_stops_on_sigint(
        dds_env, roadmap_cache, tmp_path):
    node = subprocess.Popen(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
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
    finally:
        node.send_signal(signal.SIGINT)
        output, _ = node.communicate(timeout=60)
    assert node.returncode == 0, output
    assert 'ready: roadmap 1510 nodes' in output


def test_node_process_rejects_a_bad_parameter(dds_env):
    node = subprocess.run(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
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
