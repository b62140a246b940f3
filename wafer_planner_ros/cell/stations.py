"""The stations of a cell: named wafer places resolved to collision-free joint angles."""

from dataclasses import dataclass, field
from typing import Mapping, Optional, Tuple

import numpy as np

from wafer_planner_ros.cell import schema
from wafer_planner_ros.cell.robot import Robot
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.clearance import ClearanceModel
from wafer_planner_ros.geometry.kinematics import elbow_words, IkSolution
from wafer_planner_ros.geometry.ports import CHANNEL_STEP, DEFAULT_HEADING_TOLERANCE
from wafer_planner_ros.geometry.ports import DEFAULT_LATERAL_TOLERANCE, Port

CHANNEL_SPLITS = 8
"""Halvings at most of a stretch of a port's channel not yet shown free (2 cm / 256)."""
INSIDE = ':inside'
"""The suffix naming a station's pick/place pose inside its port, e.g. 'loadport1:inside'."""


def station_name(end: str) -> str:
    """Return the station a request's end names: ``loadport1`` of ``loadport1:inside``."""
    return end[:-len(INSIDE)] if end.endswith(INSIDE) else end


@dataclass(frozen=True, eq=False)
class Station:
    """A named place the wafer is picked from or put down at, resolved to joint angles."""

    name: str
    configs: Tuple[IkSolution, ...]
    """Collision-free joint configurations, one per allowed elbow branch."""
    spec: Mapping = field(default_factory=dict)
    """The station as written in the cell file (canonical numbers)."""
    port: Optional[Port] = None
    """The station's port, if it has one."""
    inside: Tuple[IkSolution, ...] = ()
    """The pick/place configurations inside the port, one per elbow branch of ``configs``
    whose straight channel is free (in the order of ``configs``)."""

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
        schema.mapping(value, path, required=('joints',), optional=('port',))
        q = schema.vector(value['joints'], f'{path}.joints', 3)
        lower, upper = robot.limits.position.T
        for i in robot.limits.outside(q)[:1]:
            raise CellError(f'{path}.joints[{i}]',
                            f'{q[i]} is outside the joint limits [{lower[i]}, {upper[i]}]')
        candidates = [IkSolution(elbow=1 if q[1] >= 0 else -1, q=q)]
        spec = {'joints': q.tolist()}
    else:
        s = schema.mapping(value, path, required=('wafer_center', 'heading'),
                           optional=('elbow', 'port'))
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
    if value.get('port') is None:
        return Station(name=name, configs=free, spec=spec)
    port, port_spec = _port(value['port'], f'{path}.port', name, robot, free[0].q)
    inside = _channels(port, free, robot, model, f'{path}.port')
    return Station(name=name, configs=free, spec=dict(
        spec, port=port_spec), port=port, inside=tuple(i for _, i in inside))


def _port(value, path: str, name: str, robot: Robot, q) -> tuple:
    """Return (Port, its canonical spec) of a station whose retracted pose is ``q``."""
    p = schema.mapping(value, path, required=('depth',),
                       optional=('lateral_tolerance', 'heading_tolerance'))
    depth = float(schema.coordinates(schema.number(p['depth'], f'{path}.depth', positive=True),
                                     f'{path}.depth', 'longer than'))
    lateral = schema.number(p.get('lateral_tolerance', DEFAULT_LATERAL_TOLERANCE),
                            f'{path}.lateral_tolerance', positive=True)
    if not lateral < robot.wafer_radius:
        raise CellError(f'{path}.lateral_tolerance', f'{lateral:.6g} m must be below the wafer '
                                                     f'radius ({robot.wafer_radius:g} m)')
    heading = schema.number(p.get('heading_tolerance', DEFAULT_HEADING_TOLERANCE),
                            f'{path}.heading_tolerance', positive=True)
    if not heading < np.pi / 2:
        raise CellError(f'{path}.heading_tolerance',
                        f'{heading:.6g} rad must be below pi / 2 (a quarter turn)')
    arm = robot.arm
    port = Port(name, arm.wafer_center(q), float(arm.heading(q)), depth, lateral, heading)
    return port, {'depth': depth, 'lateral_tolerance': lateral, 'heading_tolerance': heading}


def _channels(port: Port, free, robot: Robot, model: ClearanceModel, path: str) -> list:
    """
    Return (retracted, inside) configurations of the branches whose channel is usable.

    Usable: reachable within the position limits all the way on the branch, and free of
    collision. Configurations ``CHANNEL_STEP`` apart along it are checked, and between two
    of them every body is clear when their clearances add up to more than the body moves
    (its Lipschitz bound over the joints' change): where they do not, the stretch is halved,
    ``CHANNEL_SPLITS`` times at most. Raise CellError naming what stops each branch when
    none is usable.
    """
    usable, reasons = [], []
    for config in free:
        words = elbow_words(config.elbow) or "the station's configuration"
        reason = _channel_problem(port, config.q, robot, model)
        if reason is None:
            usable.append((config, IkSolution(elbow=config.elbow, q=port.channel(
                robot.arm, config.q, np.array([0.0, port.depth]))[-1])))
        else:
            reasons.append(f'{words}: {reason}')
    if not usable:
        raise CellError(path, 'the straight channel from the retracted pose to '
                              f'{port.depth:g} m inside is not free: ' + '; '.join(reasons))
    return usable


def _channel_problem(port: Port, start_q, robot: Robot, model: ClearanceModel):
    """Return why the channel from ``start_q`` is not usable (see ``_channels``), or None."""
    s = np.linspace(0.0, port.depth, int(np.ceil(port.depth / CHANNEL_STEP)) + 1)
    q = port.channel(robot.arm, start_q, s)
    for k in range(len(s)):
        if not np.all(np.isfinite(q[k])):
            return f'out of reach {s[k]:.3f} m into the port'
        if len(robot.limits.outside(q[k])):
            return (f'beyond robot.joint_limits.position {s[k]:.3f} m into the port '
                    f'({q[k].round(4).tolist()})')
    clearance = model.body_clearance(q)
    a, b, da, db = s[:-1], s[1:], clearance[:-1], clearance[1:]
    qa, qb = q[:-1], q[1:]
    for _ in range(CHANNEL_SPLITS + 1):
        hit = np.nonzero(~np.all(np.concatenate([da, db]) > 0.0, axis=1))[0]
        if len(hit):
            k = hit[0] % len(a)
            at, config = (a[k], qa[k]) if hit[0] < len(a) else (b[k], qb[k])
            return f'in collision {at:.3f} m into the port ({model.contact(config).describe()})'
        reach = np.abs(qb - qa) @ robot.lipschitz.T
        open_ = ~np.all(da + db > reach, axis=1)
        if not open_.any():
            return None
        a, b, da, db, qa, qb = (x[open_] for x in (a, b, da, db, qa, qb))
        middle = 0.5 * (a + b)
        qm = port.configurations(robot.arm, middle, start_q[1], near=qa)
        if len(robot.limits.outside(qm)):  # a value out of reach is not a number
            return f'beyond robot.joint_limits.position near {middle[0]:.3f} m into the port'
        dm = model.body_clearance(qm)
        a, b = np.concatenate([a, middle]), np.concatenate([middle, b])
        qa, qb = np.concatenate([qa, qm]), np.concatenate([qm, qb])
        da, db = np.concatenate([da, dm]), np.concatenate([dm, db])
    return f'not proven free near {a[0]:.3f} m into the port (it grazes a wall)'


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
