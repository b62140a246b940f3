"""
The simulated arm ``wafer_sim``: a robot to watch, executing what the planner publishes.

It follows the planner's trajectories as a ``joint_trajectory_controller`` would
(``service.execution``: the interpolation, a zero stamp as "now", the replacement of the
rest of the current trajectory, what it refuses) and publishes what a robot driver and its
``joint_state_broadcaster`` would, at ``rate`` Hz on one timer:

- ``/joint_states`` (``sensor_msgs/JointState``): the joints' positions and velocities at
  the header's stamp (no effort);
- ``~/wafer_acceleration`` (``std_msgs/Float64MultiArray``, ``data`` = [x, y, |a|, ratio]):
  the wafer centre's acceleration (m/s^2) and the largest of |x|, |y| (and |a|) over the
  loaded limit set's wafer limit (1: at the limit), as the verification measures it; an
  array rather than a ``DiagnosticStatus`` so that a plot takes ``.data[3]`` as a number;
- ``~/arm_markers`` (``visualization_msgs/MarkerArray``, latched): the links and the wafer
  disc in ``markers.frame_id`` (``markers.arm_scene``), at most every ``MARKER_PERIOD``
  and only when the arm has moved.

A trajectory that cannot be read or that the controller would refuse is logged and
ignored: the arm goes on with what it was doing. One that starts away from where the arm
is makes it jump (logged as a warning), as it would make a real controller lurch. The
parameters (``PARAMETERS``) are read once at start-up: ``cell_file`` and
``markers.frame_id`` are the planner's, so ``config/wafer_planner.yaml`` serves both.
Threads: one executor (the subscription and the timer); the compiled kernel of the wafer
acceleration loads beside the start, as the planner's do.
"""

import sys
from typing import Optional

import numpy as np
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.node import markers, startup
from wafer_planner_ros.node.faults import reason_of, SafeLogger
from wafer_planner_ros.node.process import spin
from wafer_planner_ros.node.qos import LATCHED, RELIABLE
from wafer_planner_ros.service.execution import samples_of, TrajectoryFollower
from wafer_planner_ros.service.execution import TrajectoryRefused

MARKER_PERIOD = 0.05
"""s: the arm's markers go out at most this often (a viewer needs no more)."""
JUMP = 1e-6
"""rad: a trajectory that moves a joint more than this at its handoff is reported."""
WAFER_LAYOUT = 'x,y,norm,ratio'
"""The label of ``~/wafer_acceleration``'s one dimension: what its four numbers are."""
PARAMETERS = (
    ('cell_file', '', "cell YAML file (the planner's); empty: the packaged "
     'config/efem_default.yaml', None),
    ('trajectory_topic', '/wafer_planner/trajectory', 'the trajectories to execute', None),
    ('rate', 100, 'Hz of /joint_states and ~/wafer_acceleration', (1, 1000)),
    ('initial_station', '', 'the station whose first configuration the arm starts at; '
     "empty: the cell file's first station", None),
    ('markers.frame_id', 'efem', "frame of the arm's markers (the planner's)", None),
)
"""(name, default, description, integer range) of each parameter; all read-only."""


class SimulatedArm(Node):
    """The simulated arm; see the module's description."""

    def __init__(self, **kwargs):
        """Read the parameters and the cell, hold the initial configuration, start the timer."""
        super().__init__('wafer_sim', **kwargs)
        self.log = SafeLogger(self.get_logger())
        self.add_on_set_parameters_callback(_check_parameters)
        for name, default, description, bounds in PARAMETERS:
            descriptor = ParameterDescriptor(description=description, read_only=True)
            if bounds is not None:
                descriptor.integer_range = [IntegerRange(from_value=bounds[0],
                                                         to_value=bounds[1], step=0)]
            self.declare_parameter(name, default, descriptor)
        value = {name: self.get_parameter(name).value for name, *_ in PARAMETERS}
        path = value['cell_file'].strip()
        self.cell = Cell.from_yaml(path if path else default_cell_path())
        self.frame_id = value['markers.frame_id']
        self.follower = TrajectoryFollower(self.cell.robot,
                                           initial_configuration(self.cell,
                                                                 value['initial_station']))
        self.followed, self.refused = 0, 0
        """Trajectories taken and refused (the tests wait on them)."""
        self._epoch = self.get_clock().now().nanoseconds
        self._last_markers: Optional[tuple] = None
        self._tick_failures = 0
        self._joint_pub = self.create_publisher(JointState, '/joint_states', 10)
        self._wafer_pub = self.create_publisher(Float64MultiArray, '~/wafer_acceleration', 10)
        self._markers_pub = self.create_publisher(MarkerArray, '~/arm_markers', LATCHED)
        self._trajectory_sub = self.create_subscription(
            JointTrajectory, value['trajectory_topic'], self._on_trajectory, RELIABLE,
            raw=True)
        self.create_timer(1.0 / value['rate'], self._tick)
        self.log.info(f'simulated arm on {self.cell.name}: following '
                      f'{self._trajectory_sub.topic_name}, publishing /joint_states at '
                      f'{value["rate"]} Hz')

    def _seconds(self, nanoseconds: int) -> float:
        """Return a time on the node's clock as the follower's seconds (from the epoch)."""
        return (nanoseconds - self._epoch) * 1e-9

    # ----------------------------------------------------------------- trajectories in

    def _on_trajectory(self, data: bytes) -> None:
        try:
            self._take(data)
        except Exception as exc:  # noqa: B902 - the last resort: the arm goes on
            self.refused += 1
            self.log.error(f'a trajectory was ignored: {reason_of(exc)}')

    def _take(self, data: bytes) -> None:
        now = self._seconds(self.get_clock().now().nanoseconds)
        try:
            msg = deserialize_message(data, JointTrajectory)
        except Exception as exc:  # noqa: B902 - bytes that are no such message
            raise TrajectoryRefused(f'not a JointTrajectory ({reason_of(exc)})') from None
        label = f"trajectory '{msg.header.frame_id}'" if msg.header.frame_id else 'a trajectory'
        try:
            points = msg.points
            samples = samples_of(
                self.cell.robot.joint_names, msg.joint_names,
                [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in points],
                [p.positions for p in points], [p.velocities for p in points],
                [p.accelerations for p in points])
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            start = None if stamp == 0 else self._seconds(stamp)
            jump = self.follower.replace(start, samples, now)
        except TrajectoryRefused as exc:
            self.refused += 1
            self.log.error(f'{label} refused, as a joint_trajectory_controller would: {exc}')
            return
        self.followed += 1
        self.log.info(f'following {label}: {len(samples.times)} points, '
                      f'{samples.duration:.3f} s')
        if jump > JUMP:
            late = '' if start is None or start >= now else (
                f'; its start (header.stamp) was {1e3 * (now - start):.1f} ms before it '
                'arrived, and the points already past are skipped')
            self.log.warning(f'{label} does not start where the arm is: a joint jumps by '
                             f'{jump:.4g} rad (a real controller would lurch){late}')

    # ----------------------------------------------------------------- state out

    def _tick(self) -> None:
        try:
            self._publish()
        except Exception as exc:  # noqa: B902 - the next tick tries again
            self._tick_failures += 1
            if self._tick_failures in (1, 10, 100) or self._tick_failures % 1000 == 0:
                self.log.error(f'state not published ({self._tick_failures} times): '
                               f'{reason_of(exc)}')

    def _publish(self) -> None:
        now = self.get_clock().now()
        t = self._seconds(now.nanoseconds)
        q, qd, _ = self.follower.state(t)
        stamp = now.to_msg()
        joints = JointState(name=list(self.follower.joint_names), position=q.tolist(),
                            velocity=qd.tolist())
        joints.header.stamp = stamp
        self._joint_pub.publish(joints)
        wafer = self.follower.wafer(t)
        self._wafer_pub.publish(wafer_message(wafer))
        last = self._last_markers
        if last is None or (t - last[0] >= MARKER_PERIOD and not np.array_equal(q, last[1])):
            self._markers_pub.publish(markers.arm_markers(self.cell, q, self.frame_id, stamp))
            self._last_markers = (t, q)


def wafer_message(wafer) -> Float64MultiArray:
    """Return ``~/wafer_acceleration``: [x, y, |a|, ratio] (``execution.Wafer``)."""
    msg = Float64MultiArray(data=[float(wafer.acceleration[0]), float(wafer.acceleration[1]),
                                  wafer.norm, wafer.ratio])
    msg.layout.dim = [MultiArrayDimension(label=WAFER_LAYOUT, size=4, stride=4)]
    return msg


def initial_configuration(cell, station: str) -> np.ndarray:
    """Return the first configuration of ``station`` (empty: the cell file's first)."""
    name = station.strip() or next(iter(cell.stations))
    if name not in cell.stations:
        raise ValueError(f'initial_station: no station {name!r} in {cell.name} (one of '
                         f'{", ".join(cell.stations)})')
    return np.asarray(cell.stations[name].configs[0].q, float)


def _check_parameters(parameters) -> SetParametersResult:
    """Refuse an empty frame or topic (types and ranges: the descriptors)."""
    for parameter in parameters:
        if parameter.name in ('trajectory_topic', 'markers.frame_id') and \
                not str(parameter.value).strip():
            return SetParametersResult(successful=False,
                                       reason=f'{parameter.name} must not be empty')
    return SetParametersResult(successful=True)


def main(args=None) -> int:
    """Run the simulated arm until interrupted (Ctrl-C or SIGTERM)."""
    startup.load_kernels()  # the wafer acceleration's, beside ROS's start
    return spin(SimulatedArm, 'wafer_sim', args)


def entry_point() -> None:
    """Console script ``wafer-sim`` (and ``python -m wafer_planner_ros.node.sim``)."""
    sys.exit(main())


if __name__ == '__main__':
    entry_point()
