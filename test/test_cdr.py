"""The trajectory's CDR bytes, encoded from arrays, read back by rclpy's deserialiser."""

import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from trajectory_msgs.msg import JointTrajectory

from wafer_planner_ros.node.cdr import joint_trajectory


@pytest.mark.parametrize('frame_id', ['', 'r', 'r17', 'request-0123456', 'ünïcode'])
@pytest.mark.parametrize('count', [0, 1, 2, 501])
def test_bytes_deserialise_to_the_arrays(frame_id, count):
    rng = np.random.default_rng(count)
    times = np.sort(rng.uniform(0, 30, count))
    rows = [rng.normal(size=(count, 3)) for _ in range(3)]
    names = ['joint_1', 'elbow', 'w']
    data = joint_trajectory(1795333932, 669000000, frame_id, names, times, *rows)
    msg = deserialize_message(data, JointTrajectory)
    assert msg.header.frame_id == frame_id
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1795333932, 669000000)
    assert list(msg.joint_names) == names
    assert len(msg.points) == count
    for field, expected in zip(('positions', 'velocities', 'accelerations'), rows):
        got = np.array([getattr(p, field) for p in msg.points]).reshape(count, 3)
        assert np.array_equal(got, expected)
    assert all(len(p.effort) == 0 for p in msg.points)
    stamps = np.array([p.time_from_start.sec * 1_000_000_000 + p.time_from_start.nanosec
                       for p in msg.points], dtype=np.int64)
    assert np.array_equal(stamps, np.round(times * 1e9).astype(np.int64))
