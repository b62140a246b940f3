"""
The index page of ``wafer-review``: a row per query under a summary of the flagged ones.

Each row says when the request was received (its recorded log time, in UTC and in the local
time of the machine reviewing), shows the query's thumbnail linked to its figure, what was
asked and answered (id, kind, from, to, status, code, cycle time, planning time, limit
ratios, minimum clearance) and the query's flags: a clearance below ``Thresholds.clearance_mm``
or a planning time above ``Thresholds.planning_ms``.
"""

from collections import Counter
from dataclasses import dataclass
from datetime import datetime, timezone
import html
from typing import Dict, List, Tuple

from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cli import summary
from wafer_planner_ros.recording.queries import Query, short_label
from wafer_planner_ros.service.requests import end_label, request_of, RequestError

THUMBNAIL_WIDTH = 320
"""Most pixels across a thumbnail (its height keeps the figure's proportions)."""
DEFAULT_FLAG_CLEARANCE = 1.0
"""mm: a motion passing closer to a wall or obstacle is flagged."""
DEFAULT_FLAG_PLANNING = 400.0
"""ms: a query planned for longer is flagged (the node's aim for its slowest requests)."""
LEVELS = {0: 'ok', 1: 'warn', 2: 'error', 3: 'stale'}
ID_WIDTH = 60
"""Characters of a request id shown in a figure's title."""


@dataclass(frozen=True)
class Thresholds:
    """What flags a query; 0 turns a flag off."""

    clearance_mm: float = DEFAULT_FLAG_CLEARANCE
    """Flag a motion whose minimum clearance is below this (mm)."""
    planning_ms: float = DEFAULT_FLAG_PLANNING
    """Flag a query whose planning took longer than this (ms)."""


def figure_name(query: Query) -> str:
    """Return the file name of a query's figure."""
    return f'query_{query.number:04d}.png'


def thumbnail_name(query: Query) -> str:
    """Return the file name of a query's thumbnail, written beside its figure."""
    return f'thumb_{query.number:04d}.png'


def received(query: Query) -> Tuple[str, str]:
    """
    Return when the query's request was received: (UTC, local time) as text.

    The recorded log time of the request, e.g. ('2025-03-04 13:05:09.123 UTC',
    '2025-03-04 14:05:09.123 CET (UTC+01:00)'), in the time zone of the machine reviewing.
    """
    seconds, rest = divmod(int(query.received_ns), 10 ** 9)  # integers: no rounding up
    moment = datetime.fromtimestamp(seconds, tz=timezone.utc)
    local = moment.astimezone()
    offset = local.strftime('%z')
    milliseconds = f'{rest // 10 ** 6:03d}'
    return (f'{moment:%Y-%m-%d %H:%M:%S}.{milliseconds} UTC',
            f'{local:%Y-%m-%d %H:%M:%S}.{milliseconds} {local.tzname()} '
            f'(UTC{offset[:3]}:{offset[3:]})')


def flags(query: Query, thresholds: Thresholds) -> List[str]:
    """Return why the query is flagged, e.g. 'clearance 0.3 mm < 1.0 mm' (none: [])."""
    values = query.result.values if query.result is not None else {}
    found = []
    clearance = summary.number(values.get('min_clearance'))
    if thresholds.clearance_mm > 0.0 and clearance is not None and (
            clearance * 1000.0 < thresholds.clearance_mm):
        found.append(f'clearance {clearance * 1000.0:.2f} mm < '
                     f'{thresholds.clearance_mm:g} mm')
    planning = summary.number(values.get('planning_time_ms'))
    if thresholds.planning_ms > 0.0 and planning is not None and (
            planning > thresholds.planning_ms):
        found.append(f'planning {planning:.1f} ms > {thresholds.planning_ms:g} ms')
    return found


def status(query: Query) -> str:
    """Return 'ok', 'warn', 'error' or 'no answer' (none recorded)."""
    if query.result is None:
        return 'no answer'
    return LEVELS.get(query.result.level, str(query.result.level))


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


def asked_id(query: Query) -> str:
    """Return the request id of a query for a list, or '(no id)'."""
    return printable(query.request_id)[:ID_WIDTH] or '(no id)'


def index_html(recording, found: List[Query], cells: Dict[int, Cell],
               failed: Dict[int, str], thresholds: Thresholds = Thresholds()) -> str:
    """
    Return the index page: the recording, the flagged queries, the counts, a row per query.

    A query whose figure was drawn (not in ``failed``) shows its thumbnail, linked to the
    figure.
    """
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
    flagged = {query.number: flags(query, thresholds) for query in found}
    head = ['#', 'figure', 'received', 'id', 'kind', 'from', 'to', 'status', 'code',
            'cycle time (s)', 'planning (ms)'] + [key.replace('_', ' ') for key in ratios] + [
            'min clearance (mm)', 'flags', 'message']
    rows = []
    for query in found:
        values = query.result.values if query.result is not None else {}
        request_id, start, goal = asked(query, cells[query.number])
        link = f'<a href="{esc(figure_name(query))}">{query.number}</a>'
        figure = '' if query.number in failed else (
            f'<a href="{esc(figure_name(query))}"><img src="{esc(thumbnail_name(query))}" '
            f'alt="query {query.number}" loading="lazy"></a>')
        utc, local = received(query)
        columns = [link, figure, f'{esc(utc)}<br><small>{esc(local)}</small>',
                   esc(request_id), esc(query.kind), esc(short_label(start)),
                   esc(short_label(goal)),
                   esc(status(query)), esc(query.code),
                   number_text(values.get('cycle_time'), '{:.3f}'),
                   number_text(values.get('planning_time_ms'), '{:.1f}')]
        columns += [_ratio(values.get(key)) for key in ratios]
        columns.append(number_text(values.get('min_clearance'), '{:.2f}', 1000.0))
        columns.append('<br>'.join(f'<span class="flag">{esc(flag)}</span>'
                                   for flag in flagged[query.number]))
        message = query.result.message if query.result is not None else ''
        if query.number in failed:
            message = f'{message} [no figure: {failed[query.number]}]'.strip()
        columns.append(esc(message))
        classes = status(query).replace(' ', '-') + (' flagged' if flagged[query.number]
                                                     else '')
        rows.append(f'<tr class="{esc(classes)}" id="q{query.number}">'
                    + ''.join(f'<td>{column}</td>' for column in columns) + '</tr>')
    cell_names = sorted({cell.name for cell in cells.values()})
    first, last = (received(query)[0] for query in (found[0], found[-1]))
    return '\n'.join([
        '<!DOCTYPE html>',
        '<html lang="en"><head><meta charset="utf-8">',
        f'<title>wafer-review: {esc(str(recording.path))}</title>',
        '<style>body{font-family:sans-serif;margin:1.5em}'
        'table{border-collapse:collapse;font-size:13px}'
        'th,td{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}'
        'th{background:#eee}tr.error td{background:#fdecea}tr.warn td{background:#fff8e1}'
        'tr.no-answer td{background:#eee}.over,.flag{color:#b00;font-weight:bold}'
        'td img{display:block;border:0}</style>',
        '</head><body>',
        '<h1>wafer-review</h1>',
        f'<p>recording: {esc(str(recording.path))} ({esc(state)})<br>',
        f'cell: {esc(", ".join(cell_names))}<br>',
        'roadmap: ' + (esc('; '.join(f'{name} {digest}' for name, digest in loads))
                       or 'no roadmap load recorded') + '<br>',
        f'received: {esc(first)} to {esc(last)}</p>',
        _flag_summary(found, flagged, thresholds),
        f'<p>{len(found)} queries: '
        + esc(', '.join(f'{code} {n}' for code, n in sorted(codes.items()))) + '</p>',
        '<table><thead><tr>' + ''.join(f'<th>{esc(h)}</th>' for h in head)
        + '</tr></thead><tbody>',
        *rows,
        '</tbody></table>',
        '<p>Ratios are the peak value over the limit (above 1: the limit is exceeded). '
        'Receive times are the recorded log times of the requests, in UTC and in the local '
        'time of the machine that made this page. Click a query number or a thumbnail for '
        'its figure.</p>',
        '</body></html>', ''])


def _flag_summary(found: List[Query], flagged: Dict[int, List[str]],
                  thresholds: Thresholds) -> str:
    """Return the paragraph listing the flagged queries, each linked to its row."""
    esc = html.escape
    rules = [f'clearance below {thresholds.clearance_mm:g} mm' if thresholds.clearance_mm
             else 'clearance: off',
             f'planning above {thresholds.planning_ms:g} ms' if thresholds.planning_ms
             else 'planning: off']
    listed = [f'<li><a href="#q{query.number}">#{query.number}</a> '
              f'{esc(asked_id(query))}: {esc("; ".join(flagged[query.number]))}</li>'
              for query in found if flagged[query.number]]
    return (f'<div class="flags"><p><strong>{len(listed)} flagged</strong> '
            f'({esc(", ".join(rules))})'
            + (':</p><ul>' + ''.join(listed) + '</ul>' if listed else '.</p>') + '</div>')


def number_text(text, form: str, scale: float = 1.0) -> str:
    """Return a recorded value times ``scale`` in ``form`` ('' when it is not a number)."""
    try:
        return form.format(float(text) * scale)
    except (TypeError, ValueError):
        return ''


def _ratio(text) -> str:
    shown = number_text(text, '{:.3f}')
    if shown and float(text) > 1.0:
        return f'<span class="over">{shown}</span>'
    return shown


def printable(text: str) -> str:
    """Return ``text`` with every unprintable character a space."""
    return ''.join(c if c.isprintable() else ' ' for c in str(text))
