"""
The cell model: enclosure, robot, limits and stations, loaded and validated from YAML.

``Cell.from_yaml`` is the one entry point; a cell that loads is complete and consistent
(every station resolved to collision-free joint configurations), and a bad file raises
:class:`CellError` naming the key path and the reason, never a half-built cell.
"""

from dataclasses import dataclass, field
import functools
import hashlib
import json
from pathlib import Path
import sys
from typing import Mapping, Optional, Tuple

import numpy as np
from wafer_planner_ros.cell import schema
from wafer_planner_ros.cell.document import read_cell_file, read_cell_yaml
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.clearance import ClearanceModel
from wafer_planner_ros.geometry.kinematics import IkSolution, PlanarArm
from wafer_planner_ros.geometry.lipschitz import body_constants
from wafer_planner_ros.geometry.planar import points_in_polygon
from wafer_planner_ros.geometry.polygons import PolygonError, simple_polygon, touches_or_overlaps

_PACKAGE = Path(__file__).resolve().parents[1]  # wafer_planner_ros/

MAX_MOTION_TIME = 3600.0
"""s: a limit under which one motion across the cell would take longer is refused."""
MAX_COORDINATE = 1000.0
"""m: the largest |x| or |y| of a polygon vertex or the base (an EFEM is a few metres)."""
NOTES_LISTED = 5
"""The notes (dropped vertices) listed per polygon; then how many more there are."""
MAX_JOINT_ANGLE = 100.0
"""rad: the largest |position limit| (about 16 turns)."""


def default_cell_path() -> Path:
    """Return the packaged default cell: from the source tree, or the install's share/."""
    prefixes = list(_PACKAGE.parents)[3:4] + [Path(sys.prefix)]  # <prefix>/lib/pythonX/site-p..
    candidates = [_PACKAGE.parent / 'config']  # source checkout or symlink install
    candidates += [prefix / 'share' / 'wafer_planner_ros' / 'config' for prefix in prefixes]
    for folder in candidates:
        if (folder / 'efem_default.yaml').is_file():
            return folder / 'efem_default.yaml'
    raise FileNotFoundError('config/efem_default.yaml is not installed with wafer_planner_ros')


@dataclass(frozen=True, eq=False)
class JointLimits:
    """Joint limits, one row or entry per joint."""

    position: np.ndarray
    """(3, 2) lower/upper angle (rad)."""
    velocity: np.ndarray
    """(3,) rad/s."""
    acceleration: np.ndarray
    """(3,) rad/s^2."""
    jerk: Optional[np.ndarray] = None
    """(3,) rad/s^3, optional."""


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
    limits: JointLimits
    wafer_acceleration_limit: np.ndarray
    """Wafer-centre acceleration limit on x and y (m/s^2), (2,)."""
    wafer_acceleration_norm_limit: Optional[float] = None
    """Optional limit on the wafer-centre acceleration's magnitude (m/s^2)."""
    clearance_margin: float = 0.0
    """Distance (m) every body keeps from every wall and obstacle; 0: touching is the limit."""

    @functools.cached_property
    def arm(self) -> PlanarArm:
        """Return the kinematic chain."""
        return PlanarArm(self.base, self.link_lengths)

    @property
    def body_radii(self) -> np.ndarray:
        """Return the radii of the bodies: three links then the wafer (m)."""
        return np.append(self.link_radii, self.wafer_radius)

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


@dataclass(frozen=True, eq=False)
class Station:
    """A named place the wafer is picked from or put down at, resolved to joint angles."""

    name: str
    configs: Tuple[IkSolution, ...]
    """Collision-free joint configurations, one per allowed elbow branch."""
    spec: Mapping = field(default_factory=dict)
    """The station as written in the cell file (canonical numbers)."""

    @property
    def role(self) -> str:
        """Return 'loadport', 'loadlock' or 'other', from the station's name."""
        for role in ('loadport', 'loadlock'):
            if self.name.startswith(role):
                return role
        return 'other'


@dataclass(frozen=True, eq=False)
class Cell:
    """A validated work cell."""

    name: str
    boundary: np.ndarray
    """(V, 2) polygon, counter-clockwise."""
    obstacles: Tuple[np.ndarray, ...]
    """(V_j, 2) polygons, counter-clockwise."""
    robot: Robot
    stations: Mapping[str, Station]
    source: Optional[str] = None
    """The file the cell was loaded from."""
    notes: Tuple[str, ...] = ()
    """What was dropped while reading it (a closing point, a repeated vertex), for a warning."""

    @classmethod
    def from_yaml(cls, path) -> 'Cell':
        """Load and validate a cell file; raise CellError naming the bad key."""
        return cls.from_text(read_cell_file(path), source=str(path))

    @classmethod
    def from_text(cls, text, source: str) -> 'Cell':
        """Validate the text (str or bytes) of a cell file read from ``source``."""
        return cls.from_dict(read_cell_yaml(text, source), source=source)

    @classmethod
    def from_dict(cls, data, source=None) -> 'Cell':
        """Validate a parsed cell document."""
        top = schema.mapping(data, '', required=('cell', 'robot', 'stations'))
        cell = schema.mapping(top['cell'], 'cell', required=('name', 'boundary'),
                              optional=('obstacles',))
        notes = []
        boundary = _polygon(cell['boundary'], 'cell.boundary', notes)
        obstacles = cell.get('obstacles') or []
        if not isinstance(obstacles, list):
            raise CellError('cell.obstacles', 'must be a list of polygons')
        obstacles = tuple(_polygon(o, f'cell.obstacles[{j}]', notes)
                          for j, o in enumerate(obstacles))
        for j, obstacle in enumerate(obstacles):
            _check_inside(obstacle, boundary, f'cell.obstacles[{j}]')
        robot = _robot(top['robot'], boundary, obstacles)
        _check_motion_times(robot, boundary)
        model = _clearance_model(robot, boundary, obstacles)
        stations = _stations(top['stations'], robot, model)
        built = cls(name=schema.text(cell['name'], 'cell.name'), boundary=boundary,
                    obstacles=obstacles, robot=robot, stations=stations, source=source,
                    notes=tuple(notes))
        built.__dict__['clearance_model'] = model  # the validated model is the one used
        return built

    @functools.cached_property
    def clearance_model(self) -> ClearanceModel:
        """Return the vectorised collision/clearance model of this cell."""
        return _clearance_model(self.robot, self.boundary, self.obstacles)

    def fcl_model(self):
        """Return a new reference collision model on python-fcl (margin included)."""
        from wafer_planner_ros.geometry.fcl_model import FclModel
        return FclModel(self.robot.arm, self.robot.collision_radii, self.boundary,
                        self.obstacles)

    def canonical(self) -> dict:
        """Return the cell as plain data, independent of file layout, comments and order."""
        r = self.robot
        return {
            'name': self.name,
            'boundary': self.boundary.tolist(),
            'obstacles': [o.tolist() for o in self.obstacles],
            'robot': {
                'base': r.base.tolist(), 'joint_names': list(r.joint_names),
                'link_lengths': r.link_lengths.tolist(), 'link_radii': r.link_radii.tolist(),
                'wafer_radius': r.wafer_radius,
                'position': r.limits.position.tolist(), 'velocity': r.limits.velocity.tolist(),
                'acceleration': r.limits.acceleration.tolist(),
                'jerk': None if r.limits.jerk is None else r.limits.jerk.tolist(),
                'wafer_acceleration_limit': r.wafer_acceleration_limit.tolist(),
                'wafer_acceleration_norm_limit': r.wafer_acceleration_norm_limit,
                # Only when set: cells without a margin keep their digest (and roadmaps).
                **({'clearance_margin': r.clearance_margin} if r.clearance_margin else {}),
            },
            'stations': {name: dict(s.spec) for name, s in sorted(self.stations.items())},
        }

    @functools.cached_property
    def digest(self) -> str:
        """Return the SHA-256 of the canonical cell."""
        text = json.dumps(self.canonical(), sort_keys=True, separators=(',', ':'))
        return hashlib.sha256(text.encode()).hexdigest()


def _clearance_model(robot: Robot, boundary, obstacles) -> ClearanceModel:
    return ClearanceModel(robot.arm, robot.body_radii, robot.body_names, boundary, obstacles,
                          margin=robot.clearance_margin)


def _coordinates(values, path: str, beyond: str = 'farther out than'):
    """
    Return ``values`` (m); refuse one beyond MAX_COORDINATE, too large to be part of a cell.

    Beyond it the geometry's arithmetic would overflow long before it meant anything.
    """
    values = np.asarray(values, float)
    far = np.argwhere(np.abs(values) > MAX_COORDINATE)
    if len(far):
        where = ''.join(f'[{int(k)}]' for k in far[0])  # nothing for a single number
        raise CellError(f'{path}{where}', f'{values[tuple(far[0])]:.6g} m is {beyond} '
                                          f'{MAX_COORDINATE:g} m: not a plausible cell')
    return values


def _polygon(value, path: str, notes: list) -> np.ndarray:
    """Return a valid polygon, counter-clockwise; add what was dropped from it to notes."""
    points = schema.points(value, path, minimum=3)
    _coordinates(points, path)
    try:
        polygon = simple_polygon(points)
    except PolygonError as exc:
        raise CellError(path, exc.reason) from None
    notes.extend(f'{path}: {note}' for note in polygon.notes[:NOTES_LISTED])
    if len(polygon.notes) > NOTES_LISTED:
        notes.append(f'{path}: and {len(polygon.notes) - NOTES_LISTED} more repeated vertices '
                     'were dropped')
    return polygon.points


def _check_inside(polygon: np.ndarray, boundary: np.ndarray, path: str) -> None:
    """Reject an obstacle wholly outside the boundary (one touching a wall is fine)."""
    if not touches_or_overlaps(polygon, boundary):
        raise CellError(path, 'lies outside cell.boundary')


def _robot(value, boundary, obstacles) -> Robot:
    r = schema.mapping(value, 'robot', required=(
        'base', 'joint_names', 'link_lengths', 'link_radii', 'wafer_radius', 'joint_limits',
        'wafer_acceleration_limit'), optional=('wafer_acceleration_norm_limit',
                                               'clearance_margin'))
    base = schema.vector(r['base'], 'robot.base', 2)
    _coordinates(base, 'robot.base')
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
    norm = r.get('wafer_acceleration_norm_limit')
    margin = schema.number(r.get('clearance_margin', 0.0), 'robot.clearance_margin')
    if margin < 0.0:
        raise CellError('robot.clearance_margin', f'must be >= 0, got {margin!r}')
    sizes = {key: _coordinates(schema.vector(r[key], f'robot.{key}', 3, positive=True),
                               f'robot.{key}', 'longer than')
             for key in ('link_lengths', 'link_radii')}
    return Robot(
        base=base, joint_names=names,
        link_lengths=sizes['link_lengths'], link_radii=sizes['link_radii'],
        wafer_radius=float(_coordinates(schema.number(
            r['wafer_radius'], 'robot.wafer_radius', positive=True), 'robot.wafer_radius',
            'larger than')),
        limits=_limits(r['joint_limits']),
        wafer_acceleration_limit=schema.vector(
            r['wafer_acceleration_limit'], 'robot.wafer_acceleration_limit', 2, positive=True),
        wafer_acceleration_norm_limit=None if norm is None else schema.number(
            norm, 'robot.wafer_acceleration_norm_limit', positive=True),
        clearance_margin=float(_coordinates(margin, 'robot.clearance_margin', 'larger than')))


def _check_motion_times(robot: Robot, boundary: np.ndarray) -> None:
    """
    Refuse a limit so small that no motion worth planning fits in MAX_MOTION_TIME.

    Each limit alone bounds the time of a rest-to-rest motion over a distance D from
    below: D / v, 2 sqrt(D / a), (32 D / j)^(1/3). A joint's D is its position range or a
    full turn, whichever is less; the wafer's the diagonal of the enclosure's bounding box
    or the arm's reach across, whichever is less. A denormal or zero-like limit would
    otherwise reach the optimiser and the dense checks as a meaningless million-year motion.
    """
    limits = robot.limits
    ranges = np.minimum(limits.position[:, 1] - limits.position[:, 0], 2.0 * np.pi)
    span = min(float(np.hypot(*np.ptp(boundary, axis=0))), 2.0 * robot.link_lengths.sum())
    checks = [('velocity', 'rad/s', limits.velocity, ranges, lambda d, v: d / v),
              ('acceleration', 'rad/s^2', limits.acceleration, ranges,
               lambda d, a: 2.0 * np.sqrt(d / a))]
    if limits.jerk is not None:
        checks.append(('jerk', 'rad/s^3', limits.jerk, ranges,
                       lambda d, j: np.cbrt(32.0 * d / j)))
    wafer = robot.wafer_acceleration_limit
    if robot.wafer_acceleration_norm_limit is not None:
        wafer = np.append(wafer, robot.wafer_acceleration_norm_limit)
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
                path = f'robot.joint_limits.{kind}[{i}]'
                what = f'moving joint {robot.joint_names[i]} by {distances[i]:.3g} rad'
            raise CellError(path, f'{values[i]:.3g} {unit} is too small: {what} would take '
                                  f'at least {times[i]:.3g} s (more than '
                                  f'{MAX_MOTION_TIME:.0f} s)')


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
            if abs(angle) > MAX_JOINT_ANGLE:
                raise CellError(f'{path}.position[{i}][{k}]',
                                f'{angle:.6g} rad is beyond +-{MAX_JOINT_ANGLE:g} rad: not a '
                                'plausible joint limit')
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


def _stations(value, robot: Robot, model: ClearanceModel) -> dict:
    if not isinstance(value, dict) or not value:
        raise CellError('stations', 'must be a non-empty mapping of station names')
    return {str(name): _station(str(name), spec, robot, model) for name, spec in value.items()}


def _station(name: str, value, robot: Robot, model: ClearanceModel) -> Station:
    path = f'stations.{name}'
    if isinstance(value, dict) and 'joints' in value:
        schema.mapping(value, path, required=('joints',))
        q = schema.vector(value['joints'], f'{path}.joints', 3)
        lower, upper = robot.limits.position.T
        for i in range(3):
            if not lower[i] <= q[i] <= upper[i]:
                raise CellError(f'{path}.joints[{i}]',
                                f'{q[i]} is outside the joint limits [{lower[i]}, {upper[i]}]')
        candidates = [IkSolution(elbow=1 if q[1] >= 0 else -1, q=q)]
        spec = {'joints': q.tolist()}
    else:
        s = schema.mapping(value, path, required=('wafer_center', 'heading'),
                           optional=('elbow',))
        centre = _coordinates(schema.vector(s['wafer_center'], f'{path}.wafer_center', 2),
                              f'{path}.wafer_center')
        heading = schema.number(s['heading'], f'{path}.heading')
        if abs(heading) > MAX_JOINT_ANGLE:
            raise CellError(f'{path}.heading', f'{heading:.6g} rad is beyond '
                                               f'+-{MAX_JOINT_ANGLE:g} rad: not a plausible '
                                               'heading')
        elbow = s.get('elbow')
        if elbow is not None and (isinstance(elbow, bool) or elbow not in (1, -1)):
            raise CellError(f'{path}.elbow', f'must be 1 or -1, got {schema.brief(elbow)}')
        candidates = _reach(robot, centre, heading, elbow, path)
        spec = {'wafer_center': centre.tolist(), 'heading': heading, 'elbow': elbow}
    clearance = model.body_clearance(np.array([c.q for c in candidates])).min(axis=1)
    free = tuple(c for c, d in zip(candidates, clearance) if d > 0.0)
    if not free:
        contact = model.contact(candidates[int(np.argmax(clearance))].q)
        raise CellError(path, f'in collision ({contact.describe()})')
    return Station(name=name, configs=free, spec=spec)


def _reach(robot: Robot, centre, heading, elbow, path) -> list:
    solutions = robot.arm.inverse(centre, heading, robot.limits.position)
    if not solutions:
        l1, l2, l3 = robot.link_lengths
        wrist = centre - l3 * np.array([np.cos(heading), np.sin(heading)])
        reach = float(np.hypot(*(wrist - robot.base)))
        if abs(l1 - l2) <= reach <= l1 + l2:
            raise CellError(path, 'unreachable within robot.joint_limits.position on '
                                  'either elbow branch')
        raise CellError(path, f'unreachable (the wrist would be {reach:.3f} m from the '
                              f'shoulder; the arm reaches {abs(l1 - l2):.3f} to {l1 + l2:.3f} m)')
    if elbow is not None:
        solutions = [s for s in solutions if s.elbow == elbow]
        if not solutions:
            raise CellError(f'{path}.elbow',
                            f'branch {elbow} is outside robot.joint_limits.position')
    return solutions


def station_pairs(cell) -> list:
    """Return every loadport->loadlock and loadlock->loadport pair."""
    ports = sorted(n for n, s in cell.stations.items() if s.role == 'loadport')
    locks = sorted(n for n, s in cell.stations.items() if s.role == 'loadlock')
    return [(p, lk) for p in ports for lk in locks] + [(lk, p) for p in ports for lk in locks]
