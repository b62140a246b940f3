"""
``wafer-replay BAG --publish``: send a recording's requests to a running node.

They go at their recorded pace, and the node's answers are compared with the recorded ones.

The requests go out as their recorded bytes, on their recorded topics (or those of
``--node``). Answers are paired with requests by id, in order (several requests may share
an id, and unreadable ones have none).
"""

import os
import sys
import time
from typing import List

import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.node.client import PlannerPeer
from wafer_planner_ros.node.qos import RELIABLE
from wafer_planner_ros.recording.compare import judge, OK, Row, row_for
from wafer_planner_ros.recording.queries import Query

NO_ANSWER = '(no answer)'


def publish(found: List[Query], node: str, timeout: float, tolerance: float) -> List[Row]:
    """Send the requests of ``found``; return the compared rows."""
    planner = _planner_name(found, node)
    rclpy.init()
    try:
        peer = PlannerPeer(f'wafer_replay_{os.getpid()}', planner)
        publishers = {
            'station': peer.create_publisher(String, f'{planner}/plan_station_request',
                                             RELIABLE),
            'joint': peer.create_publisher(JointTrajectory, f'{planner}/plan_request',
                                           RELIABLE),
            'stop': peer.create_publisher(String, f'{planner}/stop_request', RELIABLE)}
        if not peer.wait_ready(time.monotonic() + timeout, publishers.values()):
            raise WaferPlannerError(f'{planner} was not ready within {timeout:g} s')
        live = peer.planner_status().get('hash', '')
        recorded = {q.load.roadmap_hash for q in found if q.load is not None}
        if recorded and live not in recorded:
            print(f'warning: {planner} plans on roadmap {live[:12] or "?"}, the recording on '
                  f'{", ".join(sorted(h[:12] for h in recorded))}: its answers may differ '
                  '(another cell, roadmap size or seed)', file=sys.stderr)
        executor = SingleThreadedExecutor()
        executor.add_node(peer)
        first, began = found[0].received_ns, time.monotonic()
        for query in found:  # at the recorded pace
            due = began + (query.received_ns - first) * 1e-9
            while time.monotonic() < due:
                executor.spin_once(timeout_sec=min(0.01, max(due - time.monotonic(), 0.0)))
            publishers[query.kind].publish(query.data)
        deadline, counted = time.monotonic() + timeout, -1
        while time.monotonic() < deadline:  # until every request has its answer
            if len(peer.answers) != counted:
                counted = len(peer.answers)
                if None not in _pair(found, peer.answers):
                    break
            executor.spin_once(timeout_sec=0.05)
        answers = list(peer.answers)
        executor.shutdown()
        peer.destroy_node()
    finally:
        rclpy.try_shutdown()
    return [judge(row_for(query), *_live(answer), tolerance)
            for query, answer in zip(found, _pair(found, answers))]


def _planner_name(found: List[Query], node: str) -> str:
    if node:
        return node if node.startswith('/') else f'/{node}'
    return found[0].topic.rsplit('/', 1)[0]


def _pair(found: List[Query], answers: list) -> list:
    """Return, for each query in order, the first unclaimed answer with its id (or None)."""
    waiting = list(answers)
    paired = []
    for query in found:
        match = next((a for a in waiting if a.name == query.request_id), None)
        if match is not None:
            waiting.remove(match)
        paired.append(match)
    return paired


def _live(answer):
    if answer is None:
        return NO_ANSWER, None
    values = {kv.key: kv.value for kv in answer.values}
    code = values.get('code', '')
    return code, float(values['cycle_time']) if code == OK and 'cycle_time' in values else None
