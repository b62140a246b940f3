"""
The cell model: enclosure, robot, limits and stations, loaded and validated from YAML.

``Cell.from_yaml`` is the one entry point; a cell that loads is complete and consistent
(every station resolved to collision-free joint configurations), and a bad file raises
:class:`CellError` naming the key path and the reason, never a half-built cell.
"""

from dataclasses import dataclass, replace
import functools
import hashlib
import json
from pathlib import Path
import sys
from typing import Mapping, Optional, Tuple

import numpy as np

from wafer_planner_ros.cell import schema
from wafer_planner_ros.cell.document import read_cell_file, read_cell_yaml
from wafer_planner_ros.cell.limits import EMPTY, LOADED
from wafer_planner_ros.cell.robot import check_motion_times, read_robot, Robot
from wafer_planner_ros.cell.stations import read_stations, Station
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.clearance import ClearanceModel
from wafer_planner_ros.geometry.polygons import PolygonError, simple_polygon, touches_or_overlaps
from wafer_planner_ros.geometry.ports import PortedModel, PortModel

_PACKAGE = Path(__file__).resolve().parents[1]  # wafer_planner_ros/

NOTES_LISTED = 5
"""The notes (dropped vertices) listed per polygon; then how many more there are."""


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
        robot = read_robot(top['robot'], boundary, obstacles)
        check_motion_times(robot, boundary)
        model = _clearance_model(robot, boundary, obstacles)
        stations = read_stations(top['stations'], robot, model)
        built = cls(name=schema.text(cell['name'], 'cell.name'), boundary=boundary,
                    obstacles=obstacles, robot=robot, stations=stations, source=source,
                    notes=tuple(notes))
        built.__dict__['clearance_model'] = model  # the validated model is the one used
        return built

    def with_load(self, load: str) -> 'Cell':
        """
        Return the cell whose motions are planned against the limit set ``load``.

        The geometry is this cell's, and so are its models (built here if not yet) unless the
        end effector's envelope without a wafer (``Robot.empty_envelope_radius``) is not the
        wafer disc: the clearance and motion models are then built for it.
        """
        cells = self._by_load  # one cell per limit set, shared by all of them
        if load not in cells:
            robot = self.robot.with_load(load)
            other = replace(self, robot=robot)
            shared = {'port_model': self.port_model, '_by_load': cells}
            if np.array_equal(robot.body_radii, self.robot.body_radii):
                shared.update(clearance_model=self.clearance_model,
                              motion_model=self.motion_model)
            other.__dict__.update(shared)
            cells[load] = other
        return cells[load]

    @functools.cached_property
    def _by_load(self) -> dict:
        """Return the cells of this one's geometry by limit set (``with_load``)."""
        return {self.robot.load: self}

    @functools.cached_property
    def clearance_model(self) -> ClearanceModel:
        """Return the vectorised collision/clearance model of this cell."""
        return _clearance_model(self.robot, self.boundary, self.obstacles)

    @functools.cached_property
    def port_model(self) -> PortModel:
        """Return the port margins of every station with a port (``geometry.ports``)."""
        return PortModel(self.robot.arm, [s.port for _, s in sorted(self.stations.items())
                                          if s.port is not None])

    @functools.cached_property
    def motion_model(self) -> PortedModel:
        """Return the clearance model with the port margins: what a motion must keep > 0."""
        return PortedModel(self.clearance_model, self.port_model, self.robot.lipschitz)

    def fcl_model(self):
        """Return a new reference collision model on python-fcl (margin included)."""
        from wafer_planner_ros.geometry.fcl_model import FclModel
        return FclModel(self.robot.arm, self.robot.collision_radii, self.boundary,
                        self.obstacles)

    def canonical(self) -> dict:
        """Return the cell as plain data, independent of file layout, comments and order."""
        r = self.robot
        loaded, empty = (r.limit_sets[name] for name in (LOADED, EMPTY))
        raised = {key: getattr(empty.joints, key).tolist()
                  for key in ('velocity', 'acceleration', 'jerk')
                  if getattr(empty.joints, key) is not getattr(loaded.joints, key)}
        return {
            'name': self.name,
            'boundary': self.boundary.tolist(),
            'obstacles': [o.tolist() for o in self.obstacles],
            'robot': {
                'base': r.base.tolist(), 'joint_names': list(r.joint_names),
                'link_lengths': r.link_lengths.tolist(), 'link_radii': r.link_radii.tolist(),
                'wafer_radius': r.wafer_radius,
                'position': loaded.joints.position.tolist(),
                'velocity': loaded.joints.velocity.tolist(),
                'acceleration': loaded.joints.acceleration.tolist(),
                'jerk': None if loaded.joints.jerk is None else loaded.joints.jerk.tolist(),
                'wafer_acceleration_limit': loaded.wafer.xy.tolist(),
                'wafer_acceleration_norm_limit': loaded.wafer.norm,
                # Only when set: cells without them keep their digest (and roadmaps).
                **({'clearance_margin': r.clearance_margin} if r.clearance_margin else {}),
                **({'empty_joint_limits': raised} if raised else {}),
                **({'empty_envelope_radius': r.empty_envelope_radius}
                   if r.empty_envelope_radius is not None else {}),
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


def _polygon(value, path: str, notes: list) -> np.ndarray:
    """Return a valid polygon, counter-clockwise; add what was dropped from it to notes."""
    points = schema.points(value, path, minimum=3)
    schema.coordinates(points, path)
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
