"""The robot of a cell: arm geometry, body radii, its limit sets, read from YAML."""

from dataclasses import dataclass, replace
import functools
from typing import Mapping, Optional, Tuple

import numpy as np

from wafer_planner_ros.cell import schema
from wafer_planner_ros.cell.limits import EMPTY, JointLimits, LimitSet, LOADED, LOADS
from wafer_planner_ros.cell.limits import WaferLimit
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.kinematics import PlanarArm
from wafer_planner_ros.geometry.lipschitz import body_constants
from wafer_planner_ros.geometry.planar import points_in_polygon

MAX_MOTION_TIME = 3600.0
"""s: a limit under which one motion across the cell would take longer is refused."""


@dataclass(frozen=True, eq=False)
class Robot:
    """The arm's geometry and limits."""

    base: np.ndarray
    """Shoulder axis position (m), (2,)."""
    joint_names: Tuple[str, str, str]
    link_lengths: np.ndarray
    """Shoulder->elbow, elbow->wrist, wrist->wafer centre (m), (3,)."""
    link_radii: np.ndarray
    """Capsule radius of each link (m), (3,)."""
    wafer_radius: float
    """m."""
    limit_sets: Mapping[str, LimitSet]
    """``LOADED`` and ``EMPTY`` (``cell.limits``)."""
    clearance_margin: float = 0.0
    """Distance (m) every body keeps from every wall and obstacle; 0: touching is the limit."""
    load: str = LOADED
    """The limit set motions of this robot are planned and verified against."""
    empty_envelope_radius: Optional[float] = None
    """m: the disc about the wafer centre that holds the end effector without a wafer, which
    empty moves keep clear of the walls in place of the wafer's; None: the wafer disc."""

    @property
    def end_radius(self) -> float:
        """Return the radius of the last body: the wafer, or empty the envelope (m)."""
        if self.load == EMPTY and self.empty_envelope_radius is not None:
            return self.empty_envelope_radius
        return self.wafer_radius

    @property
    def limit_set(self) -> LimitSet:
        """Return the limit set in use (``load``)."""
        return self.limit_sets[self.load]

    @property
    def limits(self) -> JointLimits:
        """Return the joint limits of the set in use."""
        return self.limit_set.joints

    @property
    def wafer_limit(self) -> Optional[WaferLimit]:
        """Return the wafer limit of the set in use (None: empty, no wafer limit)."""
        return self.limit_set.wafer

    def with_load(self, load: str) -> 'Robot':
        """Return the robot planned against the limit set ``load``."""
        if load not in self.limit_sets:
            raise ValueError(f'unknown load {load!r}: one of {", ".join(LOADS)}')
        return self if load == self.load else replace(self, load=load)

    def with_limit_set(self, limit_set: LimitSet) -> 'Robot':
        """Return the robot with ``limit_set`` in place of the set of its name, in use."""
        return replace(self, limit_sets={**self.limit_sets, limit_set.name: limit_set},
                       load=limit_set.name)

    @functools.cached_property
    def arm(self) -> PlanarArm:
        """Return the kinematic chain."""
        return PlanarArm(self.base, self.link_lengths)

    @property
    def body_radii(self) -> np.ndarray:
        """Return the radii of the bodies: three links then the wafer (``end_radius``, m)."""
        return np.append(self.link_radii, self.end_radius)

    @property
    def body_names(self) -> Tuple[str, ...]:
        """Return body names for messages: '<joint> link' for each link, then 'wafer'."""
        return tuple(f'{name} link' for name in self.joint_names) + ('wafer',)

    @property
    def collision_radii(self) -> np.ndarray:
        """
        Return the body radii that collision and clearance tests use: grown by the margin.

        A body's clearance is its spine's distance minus its radius, so growing every radius
        by the margin makes "clearance > 0" mean "farther than the margin", everywhere at
        once (roadmap, curve, verification); the Lipschitz constants bound the spine's
        motion and do not change.
        """
        return self.body_radii + self.clearance_margin

    @functools.cached_property
    def lipschitz(self) -> np.ndarray:
        """Return the per-body Lipschitz constants C (4, 3) in m/rad."""
        return body_constants(self.link_lengths, self.body_radii)


def read_robot(value, boundary, obstacles) -> Robot:
    """Return the ``robot`` section; raise CellError naming the bad key."""
    r = schema.mapping(value, 'robot', required=(
        'base', 'joint_names', 'link_lengths', 'link_radii', 'wafer_radius', 'joint_limits',
        'wafer_acceleration_limit'), optional=('wafer_acceleration_norm_limit',
                                               'empty_joint_limits', 'empty_envelope_radius',
                                               'clearance_margin'))
    base = schema.vector(r['base'], 'robot.base', 2)
    schema.coordinates(base, 'robot.base')
    if not points_in_polygon(base, boundary) or any(
            points_in_polygon(base, o) for o in obstacles):
        raise CellError('robot.base', f'{base.tolist()} is not inside the free space')
    names = r['joint_names']
    if not isinstance(names, list) or len(names) != 3:
        raise CellError('robot.joint_names',
                        f'must be a list of 3 names, got {schema.brief(names)}')
    names = tuple(schema.text(n, f'robot.joint_names[{i}]') for i, n in enumerate(names))
    if len(set(names)) != 3:
        raise CellError('robot.joint_names', f'must be unique, got {schema.brief(list(names))}')
    margin = schema.number(r.get('clearance_margin', 0.0), 'robot.clearance_margin')
    if margin < 0.0:
        raise CellError('robot.clearance_margin', f'must be >= 0, got {margin!r}')
    sizes = {key: schema.coordinates(schema.vector(r[key], f'robot.{key}', 3, positive=True),
                                     f'robot.{key}', 'longer than')
             for key in ('link_lengths', 'link_radii')}
    radius = float(schema.coordinates(schema.number(
        r['wafer_radius'], 'robot.wafer_radius', positive=True), 'robot.wafer_radius',
        'larger than'))
    envelope = r.get('empty_envelope_radius')
    if envelope is not None:
        envelope = schema.number(envelope, 'robot.empty_envelope_radius', positive=True)
        if not envelope <= radius:
            # The roadmap and the stations are checked with the wafer disc: a smaller disc
            # keeps them valid, a larger one would not.
            raise CellError('robot.empty_envelope_radius',
                            f'{envelope:.6g} m must not exceed the wafer radius ({radius:g} m)')
    return Robot(
        base=base, joint_names=names,
        link_lengths=sizes['link_lengths'], link_radii=sizes['link_radii'],
        wafer_radius=radius, empty_envelope_radius=envelope,
        limit_sets=_limit_sets(r),
        clearance_margin=float(schema.coordinates(margin, 'robot.clearance_margin',
                                                  'larger than')))


def check_motion_times(robot: Robot, boundary: np.ndarray) -> None:
    """
    Refuse a limit so small that no motion worth planning fits in MAX_MOTION_TIME.

    Each limit alone bounds the time of a rest-to-rest motion over a distance D from
    below: D / v, 2 sqrt(D / a), (32 D / j)^(1/3). A joint's D is its position range or a
    full turn, whichever is less; the wafer's the diagonal of the enclosure's bounding box
    or the arm's reach across, whichever is less. A denormal or zero-like limit would
    otherwise reach the optimiser and the dense checks as a meaningless million-year motion.
    Both limit sets are checked.
    """
    for limit_set in robot.limit_sets.values():
        _check_motion_times(robot, limit_set, boundary)


def _check_motion_times(robot: Robot, limit_set: LimitSet, boundary: np.ndarray) -> None:
    limits = limit_set.joints
    key = 'joint_limits' if limit_set.name == LOADED else 'empty_joint_limits'
    ranges = np.minimum(limits.position[:, 1] - limits.position[:, 0], 2.0 * np.pi)
    span = min(float(np.hypot(*np.ptp(boundary, axis=0))), 2.0 * robot.link_lengths.sum())
    checks = [('velocity', 'rad/s', limits.velocity, ranges, lambda d, v: d / v),
              ('acceleration', 'rad/s^2', limits.acceleration, ranges,
               lambda d, a: 2.0 * np.sqrt(d / a))]
    if limits.jerk is not None:
        checks.append(('jerk', 'rad/s^3', limits.jerk, ranges,
                       lambda d, j: np.cbrt(32.0 * d / j)))
    if limit_set.wafer is not None:
        wafer = limit_set.wafer.values
        checks.append(('wafer', 'm/s^2', wafer, np.full(len(wafer), span),
                       lambda d, a: 2.0 * np.sqrt(d / a)))
    for kind, unit, values, distances, bound in checks:
        with np.errstate(over='ignore'):
            times = bound(distances, values)
        for i in np.nonzero(~(times <= MAX_MOTION_TIME))[0]:
            if kind == 'wafer':
                path = ('robot.wafer_acceleration_limit', 'robot.wafer_acceleration_limit',
                        'robot.wafer_acceleration_norm_limit')[i]
                path += f'[{i}]' if i < 2 else ''
                what = f'moving the wafer by {distances[i]:.3g} m'
            else:
                path = f'robot.{key}.{kind}[{i}]'
                what = f'moving joint {robot.joint_names[i]} by {distances[i]:.3g} rad'
            raise CellError(path, f'{values[i]:.3g} {unit} is too small: {what} would take '
                                  f'at least {times[i]:.3g} s (more than '
                                  f'{MAX_MOTION_TIME:.0f} s)')


def _limit_sets(r: dict) -> dict:
    """
    Return the ``LOADED`` and ``EMPTY`` limit sets of the ``robot`` section.

    Loaded: ``joint_limits`` and the wafer limits. Empty: ``empty_joint_limits``'
    velocity, acceleration and jerk, each the loaded one where it is not given (the
    position range is the arm's, loaded or not), and no wafer limit.
    """
    loaded = _limits(r['joint_limits'])
    norm = r.get('wafer_acceleration_norm_limit')
    wafer = WaferLimit(
        xy=schema.vector(r['wafer_acceleration_limit'], 'robot.wafer_acceleration_limit', 2,
                         positive=True),
        norm=None if norm is None else schema.number(
            norm, 'robot.wafer_acceleration_norm_limit', positive=True))
    path = 'robot.empty_joint_limits'
    empty = r.get('empty_joint_limits')  # None: the key with every entry commented out
    empty = schema.mapping({} if empty is None else empty, path,
                           optional=('velocity', 'acceleration', 'jerk'))
    given = {key: schema.vector(value, f'{path}.{key}', 3, positive=True)
             for key, value in empty.items()}
    return {LOADED: LimitSet(LOADED, loaded, wafer),
            EMPTY: LimitSet(EMPTY, replace(loaded, **given), None)}


def _limits(value) -> JointLimits:
    path = 'robot.joint_limits'
    lim = schema.mapping(value, path, required=('position', 'velocity', 'acceleration'),
                         optional=('jerk',))
    position = lim['position']
    if not isinstance(position, list) or len(position) != 3:
        raise CellError(f'{path}.position', 'must be a list of 3 [lower, upper] pairs')
    position = np.array([schema.vector(p, f'{path}.position[{i}]', 2)
                         for i, p in enumerate(position)])
    for i, (lower, upper) in enumerate(position):
        for k, angle in enumerate((lower, upper)):
            if abs(angle) > schema.MAX_JOINT_ANGLE:
                raise CellError(f'{path}.position[{i}][{k}]',
                                f'{angle:.6g} rad is beyond +-{schema.MAX_JOINT_ANGLE:g} '
                                'rad: not a plausible joint limit')
        if not lower < upper:
            raise CellError(f'{path}.position[{i}]',
                            f'lower limit {lower} must be below upper limit {upper}')
    jerk = lim.get('jerk')
    return JointLimits(
        position=position,
        velocity=schema.vector(lim['velocity'], f'{path}.velocity', 3, positive=True),
        acceleration=schema.vector(lim['acceleration'], f'{path}.acceleration', 3,
                                   positive=True),
        jerk=None if jerk is None else schema.vector(jerk, f'{path}.jerk', 3, positive=True))
