"""
wafer-review: draw every query of a recording as a figure, with an index page.

For each query, ``DIR/query_NNNN.png`` (by query number) like the paper's Figs. 10-13: the
enclosure with its stations, the robot's outline along the motion coloured by time (with a
colour bar), the wafer trace and the closest approach to a wall with its distance; the joint
position, velocity, acceleration and jerk against their limits, and the wafer acceleration
along x and y against its limit. A refused query shows the robot at its start and goal when
they are known, the bodies in collision filled red with what they collide with, and the
code and message. Beside each figure, ``DIR/thumb_NNNN.png``, a small copy.
``DIR/index.html`` lists every query (number, receive time, id, kind, from, to, status and code,
cycle time, planning time, limit ratios, clearance, flags) with its thumbnail linking to its
figure, after a summary of the flagged queries: a clearance below ``--flag-clearance`` or a
planning time above ``--flag-planning``. The cell drawn is the one recorded with the query's
roadmap load.
"""

import argparse
import math
from pathlib import Path
import sys
from typing import Dict, List, Optional

import numpy as np
from PIL import Image
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cli import summary
from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, recorded_queries, run
from wafer_planner_ros.cli.common import UsageError
from wafer_planner_ros.cli.review_index import (asked, DEFAULT_FLAG_CLEARANCE,
                                                DEFAULT_FLAG_PLANNING, figure_name, ID_WIDTH,
                                                index_html, number_text, printable, received,
                                                Thresholds, thumbnail_name, THUMBNAIL_WIDTH)
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.plotting import motion_label, plot_ends, plot_motion
from wafer_planner_ros.recording.queries import label_configuration, Query, short_label

INDEX = 'index.html'
DEFAULT_DPI = 80


def write_thumbnail(figure: Path, thumbnail: Path, width: int = THUMBNAIL_WIDTH) -> None:
    """Write a copy of the PNG ``figure`` at most ``width`` pixels wide, its proportions kept."""
    with Image.open(figure) as image:
        width = min(width, image.width)
        height = max(1, round(image.height * width / image.width))
        image.convert('RGB').resize((width, height), Image.Resampling.LANCZOS).save(
            thumbnail, format='PNG', optimize=True)


def render(query: Query, cell: Cell, path: Path, dpi: int = DEFAULT_DPI):
    """
    Write the figure of ``query``: its motion, or the robot at its ends when it has none.

    Return the matplotlib figure.
    """
    trajectory = query.trajectory
    if trajectory is not None and len(trajectory.times):
        q, qd, qdd = _robot_order(trajectory, cell.robot.joint_names)
        return plot_motion(cell, trajectory.times, q, qd, qdd, title(query, cell), path,
                           dpi=dpi)
    start, goal = (_configuration(end, cell) for end in asked(query, cell)[1:])
    return plot_ends(cell, start, goal, title(query, cell), path, dpi=dpi)


def title(query: Query, cell: Cell) -> str:
    """Return a figure's title: the query, then its answer (cycle time or message)."""
    request_id, start, goal = asked(query, cell)
    start, goal = short_label(start), short_label(goal)
    request_id = printable(request_id) or '(no id)'
    if len(request_id) > ID_WIDTH:
        request_id = request_id[:ID_WIDTH - 1] + '…'
    result = query.result
    values = result.values if result is not None else {}
    lines = [f'#{query.number} {request_id}: '
             + motion_label(start or '?', goal or '?',
                            summary.branches(values.get('branches', '')))
             + f', received {received(query)[0]}']
    if result is None:
        lines.append('no answer recorded')
        return '\n'.join(lines)
    if query.cycle_time is not None:
        lines.append(f'{query.code}: '
                     + summary.cycle_text(query.cycle_time,
                                          summary.number(values.get('initial_cycle_time')))
                     + f', planning {number_text(values.get("planning_time_ms"), "{:.0f}")} ms')
    if result.level != 0 or query.cycle_time is None:
        message = printable(result.message)
        code = query.code
        lines.append(message if not code or message.startswith(code) else
                     f'{code}: {message}')
    return '\n'.join(lines)


def cells_of(found: List[Query], fallback: Optional[Cell] = None) -> Dict[int, Cell]:
    """
    Return the cell of each query (by number): the one of its roadmap load.

    A query answered before the first load (the roadmap not ready) is drawn in the first
    loaded cell; ``fallback`` is used when the recording holds no cell at all.
    """
    first = next((query.load for query in found if query.load is not None), None)
    cells = {}
    for query in found:
        load = query.load or first
        if load is None or not load.cell_text:
            if fallback is None:
                raise UsageError(f'query {query.number} has no recorded cell file: pass --cell')
            cells[query.number] = fallback
            continue
        try:
            cells[query.number] = load.cell
        except CellError as exc:
            raise UsageError(f'the recorded cell cannot be used: {exc}') from None
    return cells


def _robot_order(trajectory, joint_names) -> tuple:
    """Return positions, velocities, accelerations with columns in the robot's joint order."""
    arrays = (trajectory.positions, trajectory.velocities, trajectory.accelerations)
    names = list(trajectory.joint_names)
    if names == list(joint_names) or sorted(names) != sorted(joint_names):
        return arrays
    order = [names.index(name) for name in joint_names]
    return tuple(values[:, order] for values in arrays)


def _configuration(label: str, cell: Cell) -> Optional[np.ndarray]:
    """Return the finite configuration a label names, None if it names none."""
    q = label_configuration(label, cell)
    return q if q is not None and bool(np.all(np.isfinite(q))) else None


def _progress(done: int, total: int, stream=None) -> None:
    """Show ``review: done/total`` on stderr; off a terminal, at every tenth of the way."""
    stream = stream or sys.stderr
    if stream.isatty():
        stream.write(f'\rreview: {done}/{total}' + ('\n' if done == total else ''))
    elif done == total or 10 * done // total != 10 * (done - 1) // total:
        stream.write(f'review: {done}/{total}\n')
    stream.flush()


def main(argv=None) -> int:
    """Run wafer-review."""
    parser = argparse.ArgumentParser(prog='wafer-review', description=__doc__.split('\n')[1])
    parser.add_argument('bag', metavar='BAG', help='recording directory (or its .mcap file)')
    parser.add_argument('--out', required=True, metavar='DIR',
                        help='directory for the figures and index.html (created if missing)')
    parser.add_argument('--dpi', type=int, default=DEFAULT_DPI,
                        help='resolution of the figures (default: %(default)s)')
    parser.add_argument('--cell', help='cell YAML file to draw when the recording holds none')
    parser.add_argument('--flag-clearance', type=float, default=DEFAULT_FLAG_CLEARANCE,
                        metavar='MM', help='flag a motion passing closer than MM millimetres '
                        'to a wall or obstacle (default: %(default)s; 0: off)')
    parser.add_argument('--flag-planning', type=float, default=DEFAULT_FLAG_PLANNING,
                        metavar='MS', help='flag a query planned for longer than MS '
                        'milliseconds (default: %(default)s; 0: off)')
    args = parser.parse_args(argv)
    if not 20 <= args.dpi <= 600:
        raise UsageError(f'--dpi must be between 20 and 600, got {args.dpi}')
    for option, value in (('--flag-clearance', args.flag_clearance),
                          ('--flag-planning', args.flag_planning)):
        if not (math.isfinite(value) and value >= 0.0):
            raise UsageError(f'{option} must be a number >= 0 (0: off), got {value}')
    thresholds = Thresholds(args.flag_clearance, args.flag_planning)
    recording, found = recorded_queries(args.bag, 'reviewing')
    fallback = None
    if args.cell:
        try:
            fallback = Cell.from_yaml(args.cell)
        except CellError as exc:
            raise UsageError(f'bad cell file: {exc}') from None
    cells = cells_of(found, fallback)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f'--out {out}: {exc.strerror or exc}') from None
    failed = {}
    for done, query in enumerate(found, 1):
        try:
            render(query, cells[query.number], out / figure_name(query), args.dpi)
            write_thumbnail(out / figure_name(query), out / thumbnail_name(query))
        except Exception as exc:  # noqa: B902 - one bad query must not hide the others
            failed[query.number] = f'{type(exc).__name__}: {exc}'
            print(f'warning: query {query.number}: no figure: {failed[query.number]}',
                  file=sys.stderr)
        _progress(done, len(found))
    index = out / INDEX
    index.write_text(index_html(recording, found, cells, failed, thresholds),
                     encoding='utf-8')
    print(index)
    return EXIT_FAILURE if failed else EXIT_OK


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
