"""
The CDR bytes of the messages the node sends most: trajectories (from arrays) and results.

The recorder writes the very bytes that were published, and independent readers accept
them. rclpy's own serialiser leaves alignment padding uninitialised and, after empty
float64 sequences (a trajectory point's effort), can append bytes that ``rosbags`` rejects.
The markers are encoded with the same ``Writer`` (``marker_cdr``).

Building hundreds of ``JointTrajectoryPoint`` objects and letting rclpy convert them costs
milliseconds per plan; the bytes, which ``Publisher.publish`` takes as they are, come from
one numpy structured array. Encoding: XCDR1 little endian (header ``00 01 00 00``), each
primitive aligned to its size from the start of the payload. After the first point every
point starts 4 bytes past an 8-byte boundary, so all but the first share one layout.
"""

import struct
from typing import Sequence, Tuple

import numpy as np


def joint_trajectory(stamp_sec: int, stamp_nanosec: int, frame_id: str,
                     joint_names: Sequence[str], times: np.ndarray, positions: np.ndarray,
                     velocities: np.ndarray, accelerations: np.ndarray) -> bytes:
    """Return the serialised message: points at ``times`` (s) with the given (N, J) rows."""
    writer = Writer()
    writer.header(stamp_sec, stamp_nanosec, frame_id)
    writer.uint32(len(joint_names))
    for name in joint_names:
        writer.string(name)
    count, joints = positions.shape
    writer.uint32(count)
    nanoseconds = np.round(np.asarray(times, float) * 1e9).astype(np.int64)
    seconds, nanos = np.divmod(nanoseconds, 1_000_000_000)
    if count == 0:
        return writer.serialised()
    for rows in (positions, velocities, accelerations):  # the first point, field by field
        writer.doubles(rows[0])
    writer.uint32(0)  # effort
    writer.int32(int(seconds[0]))
    writer.uint32(int(nanos[0]))
    assert len(writer.payload) % 8 == 4
    rest = np.zeros(count - 1, dtype=_point_layout(joints))
    for name, rows in (('positions', positions), ('velocities', velocities),
                       ('accelerations', accelerations)):
        rest[name + '_count'] = joints
        rest[name] = rows[1:]
    rest['sec'], rest['nanosec'] = seconds[1:], nanos[1:]
    return writer.serialised() + rest.tobytes()


def diagnostic_status(level: int, name: str, message: str, hardware_id: str,
                      values: Sequence[Tuple[str, str]]) -> bytes:
    """Return a serialised ``diagnostic_msgs/DiagnosticStatus`` (``level``: 0-3)."""
    writer = Writer()
    writer.payload.append(level)
    for text in (name, message, hardware_id):
        writer.string(text)
    writer.uint32(len(values))
    for key, value in values:
        writer.string(key)
        writer.string(value)
    return writer.serialised()


def _point_layout(joints: int) -> np.dtype:
    """Return the layout of a point that starts 4 bytes past an 8-byte boundary."""
    names, formats, offsets, offset = [], [], [], 0
    for field in ('positions', 'velocities', 'accelerations'):
        names.append(field + '_count')
        formats.append('<u4')
        offsets.append(offset)
        offset += 4
        offset += (-(offset + 4)) % 8  # align the doubles (the point starts at 4 mod 8)
        names.append(field)
        formats.append(('<f8', (joints,)))
        offsets.append(offset)
        offset += 8 * joints
    names += ['effort_count', 'sec', 'nanosec']
    formats += ['<u4', '<i4', '<u4']
    offsets += [offset, offset + 4, offset + 8]
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                     'itemsize': offset + 12})


class Writer:
    """Append CDR primitives to a payload, aligning each to its size."""

    def __init__(self):
        self.payload = bytearray()

    def _align(self, size: int) -> None:
        self.payload += b'\0' * (-len(self.payload) % size)

    def uint32(self, value: int) -> None:
        self._align(4)
        self.payload += struct.pack('<I', value)

    def int32(self, value: int) -> None:
        self._align(4)
        self.payload += struct.pack('<i', value)

    def string(self, text: str) -> None:
        data = text.encode('utf-8') + b'\0'
        self.uint32(len(data))
        self.payload += data

    def header(self, sec: int, nanosec: int, frame_id: str) -> None:
        """Append a ``std_msgs/Header``: the stamp, then the frame."""
        self.int32(sec)
        self.uint32(nanosec)
        self.string(frame_id)

    def boolean(self, value: bool) -> None:
        self.payload.append(1 if value else 0)

    def fixed(self, values, dtype: str) -> None:
        """Append numbers of one primitive type, each aligned to its size, with no count."""
        values = np.ascontiguousarray(values, dtype)
        if values.size:
            self._align(values.dtype.itemsize)
            self.payload += values.tobytes()

    def sequence(self, rows, dtype: str) -> None:
        """Append a sequence: its length, then its rows (structs of one primitive type)."""
        rows = np.asarray(rows, dtype)
        self.uint32(len(rows))
        self.fixed(rows, dtype)

    def doubles(self, values) -> None:
        self.sequence(np.asarray(values, '<f8').reshape(-1), '<f8')

    def serialised(self) -> bytes:
        return b'\x00\x01\x00\x00' + bytes(self.payload)
