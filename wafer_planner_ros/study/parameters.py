"""
What a study varies, each by name, and how a value is applied to a cell document.

A parameter is a key path into the cell file's document, holding a number there:
``robot.link_lengths[0]``, ``robot.link_radii[2]``, ``robot.joint_limits.velocity[1]``,
``robot.wafer_acceleration_limit[0]``, ``stations.loadport1.heading``,
``stations.loadlock2.port.depth``, ...; or one of three that move several numbers at once:

- ``stations.<name>.x`` / ``stations.<name>.y``: where the station stands (its retracted
  wafer centre, m). Its port's pocket in the boundary slides along the wall with it: the
  boundary vertices ahead of the station (along its heading) and within
  ``wafer_radius + POCKET_MARGIN`` of its axis move by the part of the displacement that
  runs along the wall. The part towards the wall moves the station alone (its port then
  reaches deeper or less deep into the pocket).
- ``boundary.width``: the enclosure's extent in x (m): the vertices on its two side walls
  (at its least and greatest x) move apart (or together) symmetrically.
- ``boundary.depth``: its extent in y (m): everything on either side of the robot's base
  (boundary vertices, obstacles and stations) moves away from (or towards) it by half the
  change, so the two walls facing each other across the base keep their stations and
  pockets.

A value that makes the cell invalid (a station out of reach, a pocket through a wall) is
not refused here: the variant is validated like any cell file and recorded as invalid.
"""

import copy
import math
import re
from typing import List, Tuple

POCKET_MARGIN = 0.05
"""m beyond the wafer radius, either side of a station's axis, within which a boundary
vertex ahead of the station belongs to its pocket."""
EXTREME = 1e-9
"""m: how close to the least or greatest coordinate a side-wall vertex lies."""

_STEP = re.compile(r'\.?([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]')


class ParameterError(ValueError):
    """A parameter that names nothing in the base cell, or a value that is no number."""


def steps(name: str) -> List:
    """Return the key path ``name`` as keys (str) and list indices (int)."""
    found, at = [], 0
    while at < len(name):
        match = _STEP.match(name, at)
        if match is None or (at == 0 and name.startswith('.')):
            raise ParameterError(f'{name!r} is not a key path (like robot.link_lengths[0])')
        found.append(match.group(1) if match.group(1) is not None else int(match.group(2)))
        at = match.end()
    if not found:
        raise ParameterError('a parameter needs a name')
    return found


def check(document: dict, name: str) -> None:
    """Raise ParameterError unless ``name`` can be applied to the base cell ``document``."""
    value(document, name)


def value(document: dict, name: str) -> float:
    """Return the base cell's value of parameter ``name`` (m, rad, or the limit's unit)."""
    path = steps(name)
    derived = _derived(path)
    if derived is not None:
        kind, station = derived
        if kind in ('x', 'y'):
            return float(_station(document, station, name)['wafer_center'][kind == 'y'])
        low, high = _extent(_boundary(document, name), 0 if kind == 'width' else 1)
        return high - low
    holder, key = _holder(document, path, name)
    number = holder[key]
    if isinstance(number, bool) or not isinstance(number, (int, float)):
        raise ParameterError(f'{name}: the base cell holds {number!r} there, not a number')
    return float(number)


def apply(document: dict, values: dict) -> dict:
    """Return a copy of the cell ``document`` with ``values`` (name -> number) applied."""
    cell = copy.deepcopy(document)
    for name, number in values.items():
        if isinstance(number, bool) or not isinstance(number, (int, float)) \
                or not math.isfinite(number):
            raise ParameterError(f'{name}: {number!r} is not a finite number')
        path = steps(name)
        derived = _derived(path)
        if derived is None:
            holder, key = _holder(cell, path, name)
            holder[key] = float(number)
        elif derived[0] in ('x', 'y'):
            _move_station(cell, derived[1], derived[0], float(number), name)
        else:
            _resize(cell, 0 if derived[0] == 'width' else 1, float(number), name)
    return cell


def footprint(document: dict) -> float:
    """Return the floor area of the enclosure's bounding box (m²)."""
    boundary = _boundary(document, 'cell.boundary')
    (x0, x1), (y0, y1) = _extent(boundary, 0), _extent(boundary, 1)
    return (x1 - x0) * (y1 - y0)


def _derived(path) -> Tuple:
    if path in (['boundary', 'width'], ['boundary', 'depth']):
        return path[1], None
    if len(path) == 3 and path[0] == 'stations' and path[2] in ('x', 'y') \
            and isinstance(path[1], str):
        return path[2], path[1]
    return None


def _holder(document: dict, path: list, name: str):
    """Return (the list or mapping holding the last step, that step)."""
    at = document
    for depth, step in enumerate(path):
        where = _shown(path[:depth + 1])
        if isinstance(step, int):
            if not isinstance(at, list) or step >= len(at):
                raise ParameterError(f'{name}: the base cell has no {where}')
        elif not isinstance(at, dict) or step not in at:
            raise ParameterError(f'{name}: the base cell has no {where}')
        if depth == len(path) - 1:
            return at, step
        at = at[step]


def _shown(path) -> str:
    return ''.join(f'[{s}]' if isinstance(s, int) else f'.{s}' for s in path).lstrip('.')


def _station(document: dict, station: str, name: str) -> dict:
    stations = document.get('stations')
    if not isinstance(stations, dict) or not isinstance(stations.get(station), dict) \
            or not isinstance(stations[station].get('wafer_center'), list):
        raise ParameterError(f'{name}: the base cell has no station {station!r} with a '
                             'wafer_center')
    return stations[station]


def _boundary(document: dict, name: str) -> list:
    cell = document.get('cell')
    boundary = cell.get('boundary') if isinstance(cell, dict) else None
    if not isinstance(boundary, list) or not boundary or not all(
            isinstance(p, list) and len(p) == 2 for p in boundary):
        raise ParameterError(f'{name}: the base cell has no boundary polygon')
    return boundary


def _extent(points: list, axis: int) -> Tuple[float, float]:
    coordinates = [float(p[axis]) for p in points]
    return min(coordinates), max(coordinates)


def _move_station(cell: dict, station: str, axis: str, number: float, name: str) -> None:
    spec = _station(cell, station, name)
    centre = [float(v) for v in spec['wafer_center']]
    shift = [0.0, 0.0]
    shift[axis == 'y'] = number - centre[axis == 'y']
    spec['wafer_center'] = [centre[0] + shift[0], centre[1] + shift[1]]
    if not isinstance(spec.get('port'), dict):
        return
    heading = float(spec.get('heading', 0.0))
    ahead = (math.cos(heading), math.sin(heading))
    wall = (-ahead[1], ahead[0])
    along = shift[0] * wall[0] + shift[1] * wall[1]
    radius = float(cell.get('robot', {}).get('wafer_radius', 0.0))
    for point in _boundary(cell, name):
        dx, dy = float(point[0]) - centre[0], float(point[1]) - centre[1]
        if dx * ahead[0] + dy * ahead[1] > 0 \
                and abs(dx * wall[0] + dy * wall[1]) <= radius + POCKET_MARGIN:
            point[0], point[1] = float(point[0]) + along * wall[0], \
                float(point[1]) + along * wall[1]


def _resize(cell: dict, axis: int, number: float, name: str) -> None:
    boundary = _boundary(cell, name)
    low, high = _extent(boundary, axis)
    half = (number - (high - low)) / 2
    if axis == 0:
        for point in boundary:
            if float(point[0]) >= high - EXTREME:
                point[0] = float(point[0]) + half
            elif float(point[0]) <= low + EXTREME:
                point[0] = float(point[0]) - half
        return
    base = cell.get('robot', {}).get('base', [0.0, 0.0])
    middle = float(base[1])

    def moved(point) -> None:
        y = float(point[1])
        if y != middle:
            point[1] = y + math.copysign(half, y - middle)

    for point in boundary:
        moved(point)
    for obstacle in cell['cell'].get('obstacles') or []:
        for point in obstacle:
            moved(point)
    for spec in (cell.get('stations') or {}).values():
        if isinstance(spec, dict) and isinstance(spec.get('wafer_center'), list):
            centre = [float(v) for v in spec['wafer_center']]
            moved(centre)
            spec['wafer_center'] = centre
