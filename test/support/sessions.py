"""
A session of requests like a cell controller's (stations, joint requests and bad ones).

And a recorded session read back by the independent ``rosbags``.
"""

from collections import defaultdict
import json

import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def mixed_requests(cell, count: int = 50, seed: int = 7) -> list:
    """
    Return ``count`` requests to publish, each (kind, message, request id).

    Half are station pairs, a quarter joint requests (with permuted joint names), a quarter
    bad requests.
    """
    rng = np.random.default_rng(seed)
    names = sorted(cell.stations)
    joints = list(cell.robot.joint_names)
    bad = [
        ('station', String(data=json.dumps({'id': 'x-unknown', 'from': 'loadport1',
                                            'to': 'nowhere'})), 'x-unknown'),
        ('station', String(data='{"id": "x-broken", "from": '), ''),
        ('station', String(data=json.dumps({'from': 'loadport1', 'to': 'loadlock1'})), ''),
        ('station', String(data=json.dumps({'id': 'x-limits', 'from': [0.0, 3.5, 0.0],
                                            'to': 'loadlock1'})), 'x-limits'),
        ('station', String(data=json.dumps({'id': 'x-collide',
                                            'from': [-1.5707963, 0.0, 0.0],
                                            'to': 'loadlock1'})), 'x-collide'),
        ('joint', _joints('x-nan', [0.1, float('nan'), 0.0], [0.1, 0.2, 0.3]), 'x-nan'),
        ('joint', _joints('x-short', [0.1, 0.2], [0.1, 0.2, 0.3]), 'x-short'),
        ('joint', _joints('x-names', [0.0, 0.0, 0.0], [0.1, 0.2, 0.3],
                          ['joint_1', 'joint_2', 'elbow_x']), 'x-names'),
    ]
    requests = []
    for k in range(count):
        kind = k % 4
        if kind == 3:
            requests.append(bad[(k // 4) % len(bad)])
            continue
        a, b = rng.choice(len(names), 2, replace=False)
        request_id = f'q{k:02d}'
        if kind == 2:
            start = cell.stations[names[a]].configs[0].q
            goal = cell.stations[names[b]].configs[-1].q
            order = rng.permutation(len(joints))
            requests.append(('joint', _joints(request_id, start[order], goal[order],
                                              [joints[i] for i in order]), request_id))
        else:
            requests.append(('station', String(data=json.dumps(
                {'id': request_id, 'from': names[a], 'to': names[b]})), request_id))
    return requests


def _joints(request_id, start, goal, joint_names=()) -> JointTrajectory:
    msg = JointTrajectory(joint_names=list(joint_names))
    msg.header.frame_id = request_id
    msg.points = [JointTrajectoryPoint(positions=[float(v) for v in start]),
                  JointTrajectoryPoint(positions=[float(v) for v in goal])]
    return msg


def read_with_rosbags(bag) -> dict:
    """Return every message of the bag, deserialised by rosbags, by topic."""
    store = get_typestore(Stores.ROS2_JAZZY)
    messages = defaultdict(list)
    with Reader(bag) as reader:
        for connection, _, raw in reader.messages():
            messages[connection.topic].append(store.deserialize_cdr(raw, connection.msgtype))
    return messages
