"""The stations of a cell: named wafer places resolved to collision-free joint angles."""

from dataclasses import dataclass, field
from typing import Mapping, Tuple

import numpy as np

from wafer_planner_ros.cell import schema
from wafer_planner_ros.cell.robot import Robot
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.clearance import ClearanceModel
from wafer_planner_ros.geometry.kinematics import IkSolution


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


def read_stations(value, robot: Robot, model: ClearanceModel) -> dict:
    """Return the ``stations`` section by name; raise CellError naming the bad key."""
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
        centre = schema.coordinates(schema.vector(s['wafer_center'], f'{path}.wafer_center',
                                                  2), f'{path}.wafer_center')
        heading = schema.number(s['heading'], f'{path}.heading')
        if abs(heading) > schema.MAX_JOINT_ANGLE:
            raise CellError(f'{path}.heading',
                            f'{heading:.6g} rad is beyond +-{schema.MAX_JOINT_ANGLE:g} rad: '
                            'not a plausible heading')
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
