"""The CDR bytes of trajectories and results, read back by rclpy's deserialiser."""

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from rosbags.typesys import get_typestore, Stores
from trajectory_msgs.msg import JointTrajectory

from wafer_planner_ros.service.cdr import diagnostic_status, joint_trajectory


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
    # The independent reader of the recordings takes the bytes as they are.
    back = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(
        data, 'trajectory_msgs/msg/JointTrajectory')
    assert back.header.frame_id == frame_id and len(back.points) == count
    if count:
        assert np.array_equal(back.points[-1].accelerations, rows[2][-1])


@pytest.mark.parametrize('count', [0, 1, 7])
@pytest.mark.parametrize('name', ['', 'r', 'station-7', 'ünï'])
def test_status_bytes_read_back_and_match_an_independent_encoder(name, count):
    values = [(f'key_{k}' * (k % 3 + 1), repr(0.1 * k) * k) for k in range(count)]
    data = diagnostic_status(2, name, 'NO_PATH: no path', 'wafer_planner', values)
    back = deserialize_message(data, DiagnosticStatus)
    assert (back.level, back.name, back.message, back.hardware_id) == \
        (b'\x02', name, 'NO_PATH: no path', 'wafer_planner')
    assert [(kv.key, kv.value) for kv in back.values] == values
    # rosbags zero-fills the alignment padding as we do (rclpy leaves it uninitialised).
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    independent = store.serialize_cdr(types['diagnostic_msgs/msg/DiagnosticStatus'](
        level=2, name=name, message='NO_PATH: no path', hardware_id='wafer_planner',
        values=[types['diagnostic_msgs/msg/KeyValue'](key=k, value=v) for k, v in values]),
        'diagnostic_msgs/msg/DiagnosticStatus')
    assert data == bytes(independent)
