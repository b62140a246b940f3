"""The node as its own process, asked over DDS on loopback by wafer-plan-client."""

import os
import re
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


CLIENT = [sys.executable, '-m', 'wafer_planner_ros.cli.client']


def _client(env, *args):
    return subprocess.run([*CLIENT, *args, '--timeout', '120'], env=env, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.slow
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
        assert 'p1: ok: loadport1 -> loadlock2, cycle time ' in ok.stdout
        # Worded with units, as wafer-plan words a plan.
        assert re.search(r'^  cycle time \d+\.\d{3} s \(λ-scaled start \d+\.\d{3} s\), elbow '
                         r'(left|right) -> elbow (left|right) \(knot-timing, planned for this '
                         r'request\)$', ok.stdout, re.M), ok.stdout
        assert re.search(r'^  min clearance \d+\.\d mm; limit ratios: ', ok.stdout, re.M)
        assert 'proven collision-free' in ok.stdout and 'trajectory: ' in ok.stdout
        raw = _client(dds_env, 'loadport1', 'loadlock2', '--id', 'p1r', '--raw')
        assert re.search(r'^  min_clearance: 0\.\d+$', raw.stdout, re.M), raw.stdout
        # A reader that goes away (| head) ends the client quietly.
        piped = subprocess.Popen([*CLIENT, 'loadport1', 'loadlock2', '--timeout', '120'],
                                 env=dds_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        piped.stdout.close()
        assert piped.wait(timeout=300) == 1
        assert b'Traceback' not in piped.stderr.read()
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
        # Stopped on its path 0.4 s in; diverted half-way to another station.
        stopped = _client(dds_env, 'loadport1', 'loadlock2', '--id', 'p5', '--stop-after', '0.4')
        assert stopped.returncode == 0, stopped.stdout + stopped.stderr
        assert re.search(r'^p5-stop: ok: .*\n  cycle time \d+\.\d{3} s.*\(controlled-stop, ',
                         stopped.stdout, re.M), stopped.stdout
        diverted = _client(dds_env, 'loadport2', 'loadlock2', '--id', 'p6', '--divert-to',
                           'loadlock1')
        assert diverted.returncode == 0, diverted.stdout + diverted.stderr
        assert re.search(r'^p6-divert: ok: p6 at \d+\.\d+ s -> loadlock1, cycle time .*\n  '
                         r'cycle time \d+\.\d{3} s.*\((stop-then-move|blended-divert), ',
                         diverted.stdout, re.M), diverted.stdout
    finally:
        node.send_signal(signal.SIGINT)
        output, _ = node.communicate(timeout=60)
    assert node.returncode == 0, output
    # The roadmap the tests built for the same cell and settings (not a size written here).
    assert (f'ready: roadmap {default_roadmap.node_count} nodes, {default_roadmap.edge_count} '
            f'edges, hash {default_roadmap.digest[:12]}') in output


@pytest.mark.slow
def test_client_says_no_node_found_without_waiting_for_its_timeout(dds_env):
    # No node in this domain: discovery finds none within seconds, long before --timeout.
    dds_env['ROS_DOMAIN_ID'] = str(200 + os.getpid() % 30)
    alone = subprocess.run([*CLIENT, 'loadport1', 'loadlock2', '--timeout', '600'],
                           env=dds_env, capture_output=True, text=True, timeout=60)
    assert alone.returncode == 1
    assert 'no node /wafer_planner found' in alone.stderr, alone.stderr
    assert alone.stdout == ''


def test_node_process_rejects_a_bad_parameter(dds_env):
    node = subprocess.run(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
         '-p', 'planning.station_table:=false', '-p', 'planning.optimise_budget:=0.0',
         '-p', 'planning.max_queue:=0'], env=dds_env, capture_output=True, text=True,
        timeout=120)
    assert node.returncode != 0
    assert 'planning.max_queue' in node.stdout + node.stderr


def _launch_module():
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[2] / 'launch' / 'wafer_planner.launch.py'
    spec = importlib.util.spec_from_file_location('wafer_planner_launch', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_launch_file_overrides_the_params_file_only_with_arguments_given(tmp_path):
    pytest.importorskip('launch')
    pytest.importorskip('launch_ros')
    from launch import LaunchContext
    from launch.actions import DeclareLaunchArgument
    from launch.utilities import perform_substitutions
    module = _launch_module()
    description = module.generate_launch_description()

    def actions(**given):
        context = LaunchContext()
        for entity in description.entities:
            if isinstance(entity, DeclareLaunchArgument):
                context.launch_configurations[entity.name] = perform_substitutions(
                    context, entity.default_value)
        context.launch_configurations.update(given)
        return module._actions(context)

    plain = actions()
    assert [a.node_package for a in plain] == ['wafer_planner_ros']
    assert len(plain[0]._Node__parameters) == 1  # the params file alone: its values stand
    assert len(actions(cell_file='/tmp/cell.yaml')[0]._Node__parameters) == 2
    placed = actions(parent_frame='world', x='1.5')
    if len(placed) == 2 and hasattr(placed[1], 'node_package'):  # tf2_ros is installed
        assert placed[1].node_package == 'tf2_ros'
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    markers:\n      frame_id: cell7\n')
    assert module._params_frame(str(params)) == 'cell7'
    params.write_text('wafer_planner:\n  ros__parameters:\n    markers.frame_id: cell8\n')
    assert module._params_frame(str(params)) == 'cell8'
    assert module._params_frame(str(tmp_path / 'missing.yaml')) == 'efem'
