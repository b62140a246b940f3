"""
wafer-review: draw every query of a recording as a figure, with an index page.

For each query, ``DIR/query_NNNN.png`` (by query number) like the paper's Figs. 10-13: the
enclosure with the robot's outline along the motion and the wafer trace, the joint position,
velocity and acceleration against their limits, and the wafer acceleration along x and y
against its limit. A refused query shows the robot at its start and goal when they are
known, and the code and message. ``DIR/index.html`` lists every query (number, id, from,
to, status and code, cycle time, planning time, limit ratios) linking to its figure. The
cell drawn is the one recorded with the query's roadmap load.
"""

import argparse
from collections import Counter
import html
import json
from pathlib import Path
import sys
from typing import Dict, List, Optional, Tuple

import numpy as np
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, recorded_queries, run
from wafer_planner_ros.cli.common import UsageError
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.plotting import plot_ends, plot_motion
from wafer_planner_ros.recording.queries import label_configuration, Query, short_label
from wafer_planner_ros.service.requests import end_label, request_of, RequestError

INDEX = 'index.html'
DEFAULT_DPI = 80
LEVELS = {0: 'ok', 1: 'warn', 2: 'error', 3: 'stale'}
_ID_WIDTH = 60
"""Characters of a request id shown in a figure's title."""


def figure_name(query: Query) -> str:
    """Return the file name of a query's figure."""
    return f'query_{query.number:04d}.png'


def status(query: Query) -> str:
    """Return 'ok', 'warn', 'error' or 'no answer' (none recorded)."""
    if query.result is None:
        return 'no answer'
    return LEVELS.get(query.result.level, str(query.result.level))


def render(query: Query, cell: Cell, path: Path, dpi: int = DEFAULT_DPI) -> None:
    """Write the figure of ``query``: its motion, or the robot at its ends when it has none."""
    trajectory = query.trajectory
    if trajectory is not None and len(trajectory.times):
        q, qd, qdd = _robot_order(trajectory, cell.robot.joint_names)
        plot_motion(cell, trajectory.times, q, qd, qdd, title(query, cell), path, dpi=dpi)
    else:
        start, goal = (_configuration(end, cell) for end in asked(query, cell)[1:])
        plot_ends(cell, start, goal, title(query, cell), path, dpi=dpi)


def asked(query: Query, cell: Cell) -> Tuple[str, str, str]:
    """
    Return the (id, from, to) of a query: as answered, else as read from the request.

    From and to are labels (station names or JSON joint lists); '' where unknown.
    """
    request_id, (start, goal) = query.request_id, query.ends()
    if start or goal:
        return request_id, start, goal
    try:  # no answer recorded, or one that could not name the ends
        request = request_of(query.kind, query.request, cell.robot.joint_names)
    except (RequestError, AttributeError, TypeError, ValueError):
        return request_id, '', ''
    return (request_id or request.request_id, end_label(request.start),
            end_label(request.goal))


def title(query: Query, cell: Cell) -> str:
    """Return a figure's title: the query, then its answer (cycle time or message)."""
    request_id, start, goal = asked(query, cell)
    start, goal = short_label(start), short_label(goal)
    request_id = _printable(request_id) or '(no id)'
    if len(request_id) > _ID_WIDTH:
        request_id = request_id[:_ID_WIDTH - 1] + '…'
    lines = [f'#{query.number} {request_id}: {start or "?"} -> {goal or "?"}']
    result = query.result
    if result is None:
        lines.append('no answer recorded')
        return '\n'.join(lines)
    values = result.values
    if query.cycle_time is not None:
        lines.append(f'{query.code}: cycle time {query.cycle_time:.3f} s (λ-scaled '
                     f'{_number(values.get("initial_cycle_time"), "{:.3f}")} s), planning '
                     f'{_number(values.get("planning_time_ms"), "{:.0f}")} ms'
                     + _branches(values.get('branches', '')))
    if result.level != 0 or query.cycle_time is None:
        message = _printable(result.message)
        code = query.code
        lines.append(message if not code or message.startswith(code) else
                     f'{code}: {message}')
    return '\n'.join(lines)


def index_html(recording, found: List[Query], cells: Dict[int, Cell],
               failed: Dict[int, str]) -> str:
    """Return the index page: the recording, the counts by code, a row per query."""
    esc = html.escape
    ratios = []
    for query in found:
        for key in query.result.values if query.result is not None else ():
            if key.startswith('ratio_') and key not in ratios:
                ratios.append(key)
    loads = []
    for query in found:
        load = query.load
        if load is not None and (load.values.get('cell', ''), load.roadmap_hash) not in loads:
            loads.append((load.values.get('cell', ''), load.roadmap_hash))
    state = 'complete' if recording.complete else f'cut off ({recording.cut})'
    codes = Counter(query.code or '(no answer)' for query in found)
    head = ['#', 'id', 'kind', 'from', 'to', 'status', 'code', 'cycle time (s)',
            'planning (ms)'] + [key.replace('_', ' ') for key in ratios] + [
            'min clearance (mm)', 'message']
    rows = []
    for query in found:
        values = query.result.values if query.result is not None else {}
        request_id, start, goal = asked(query, cells[query.number])
        link = f'<a href="{esc(figure_name(query))}">{query.number}</a>'
        columns = [link, esc(request_id), esc(query.kind), esc(short_label(start)),
                   esc(short_label(goal)),
                   esc(status(query)), esc(query.code),
                   _number(values.get('cycle_time'), '{:.3f}'),
                   _number(values.get('planning_time_ms'), '{:.1f}')]
        columns += [_ratio(values.get(key)) for key in ratios]
        columns.append(_number(values.get('min_clearance'), '{:.1f}', 1000.0))
        message = query.result.message if query.result is not None else ''
        if query.number in failed:
            message = f'{message} [no figure: {failed[query.number]}]'.strip()
        columns.append(esc(message))
        rows.append(f'<tr class="{esc(status(query).replace(" ", "-"))}">'
                    + ''.join(f'<td>{column}</td>' for column in columns) + '</tr>')
    cell_names = sorted({cell.name for cell in cells.values()})
    return '\n'.join([
        '<!DOCTYPE html>',
        '<html lang="en"><head><meta charset="utf-8">',
        f'<title>wafer-review: {esc(str(recording.path))}</title>',
        '<style>body{font-family:sans-serif;margin:1.5em}'
        'table{border-collapse:collapse;font-size:13px}'
        'th,td{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}'
        'th{background:#eee}tr.error td{background:#fdecea}tr.warn td{background:#fff8e1}'
        'tr.no-answer td{background:#eee}.over{color:#b00;font-weight:bold}</style>',
        '</head><body>',
        '<h1>wafer-review</h1>',
        f'<p>recording: {esc(str(recording.path))} ({esc(state)})<br>',
        f'cell: {esc(", ".join(cell_names))}<br>',
        'roadmap: ' + (esc('; '.join(f'{name} {digest}' for name, digest in loads))
                       or 'no roadmap load recorded') + '</p>',
        f'<p>{len(found)} queries: '
        + esc(', '.join(f'{code} {n}' for code, n in sorted(codes.items()))) + '</p>',
        '<table><thead><tr>' + ''.join(f'<th>{esc(h)}</th>' for h in head)
        + '</tr></thead><tbody>',
        *rows,
        '</tbody></table>',
        '<p>Ratios are the peak value over the limit (above 1: the limit is exceeded). '
        'Click a query number for its figure.</p>',
        '</body></html>', ''])


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


def _branches(text: str) -> str:
    """Return ', elbow branches [..]' for station ends ('' for joint ends: none chosen)."""
    try:
        branches = json.loads(text)
    except ValueError:
        return ''
    if not isinstance(branches, list) or all(b is None for b in branches):
        return ''
    return ', elbow branches [' + ', '.join('-' if b is None else str(b) for b in branches) + ']'


def _number(text, form: str, scale: float = 1.0) -> str:
    try:
        return form.format(float(text) * scale)
    except (TypeError, ValueError):
        return ''


def _ratio(text) -> str:
    shown = _number(text, '{:.3f}')
    if shown and float(text) > 1.0:
        return f'<span class="over">{shown}</span>'
    return shown


def _printable(text: str) -> str:
    return ''.join(c if c.isprintable() else ' ' for c in str(text))


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
    args = parser.parse_args(argv)
    if not 20 <= args.dpi <= 600:
        raise UsageError(f'--dpi must be between 20 and 600, got {args.dpi}')
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
        except Exception as exc:  # noqa: B902 - one bad query must not hide the others
            failed[query.number] = f'{type(exc).__name__}: {exc}'
            print(f'warning: query {query.number}: no figure: {failed[query.number]}',
                  file=sys.stderr)
        _progress(done, len(found))
    index = out / INDEX
    index.write_text(index_html(recording, found, cells, failed), encoding='utf-8')
    print(index)
    return EXIT_FAILURE if failed else EXIT_OK


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
