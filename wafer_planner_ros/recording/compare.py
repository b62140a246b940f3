"""
Comparing a recorded answer with another one (replayed offline, or from a live node).

Answers are the same when their codes are, and their cycle times are within a tolerance.
``BUSY``, ``TIMEOUT`` and ``ROADMAP_NOT_READY`` depended on the node at the time and are
not compared, nor are queries whose answer was not recorded, nor those the other side
could not answer (an empty code).
"""

from dataclasses import dataclass
from typing import List, Optional

from wafer_planner_ros.recording.queries import NODE_ONLY_CODES, Query, short_label

OK = 'OK'
"""The code of a planned query (``node.messages.plan_values``)."""
DEFAULT_TOLERANCE = 1e-3
"""Seconds of cycle time by which an answer may differ from the recorded one."""


@dataclass
class Row:
    """One query: the recorded answer, the replayed (or live) one and the verdict."""

    number: int
    request_id: str
    ends: str
    recorded: str
    recorded_cycle: Optional[float]
    answered: bool
    """Whether the recording holds the query's answer."""
    replayed: str = ''
    replayed_cycle: Optional[float] = None
    verdict: str = ''
    """'same', 'DIFFERENT', or why the query was not compared."""

    @property
    def mismatch(self) -> bool:
        """Return True when the answers differ."""
        return self.verdict == 'DIFFERENT'


def row_for(query: Query) -> Row:
    """Return a row holding the recorded side of ``query``."""
    start, goal = (short_label(end) for end in query.ends())
    return Row(query.number, query.request_id, f'{start} -> {goal}' if start or goal else '',
               query.code or '(none recorded)', query.cycle_time, query.result is not None)


def judge(row: Row, code: str, cycle: Optional[float], tolerance: float) -> Row:
    """Fill in the other side of ``row`` and its verdict."""
    row.replayed, row.replayed_cycle = code, cycle
    if row.recorded in NODE_ONLY_CODES:
        row.verdict = 'not compared: the answer depended on the node at the time'
    elif not row.answered:
        row.verdict = 'not compared: no answer was recorded'
    elif not code:
        row.verdict = 'not compared: no roadmap had been loaded when it arrived'
    else:
        same = code == row.recorded and (
            cycle is None or row.recorded_cycle is None
            or abs(cycle - row.recorded_cycle) <= tolerance)
        row.verdict = 'same' if same else 'DIFFERENT'
    return row


def table(rows: List[Row]) -> str:
    """Return the rows as a text table."""
    lines = [f"{'#':>4}  {'id':<18}{'from -> to':<34}{'recorded':<20}{'cycle':>8}  "
             f"{'replayed':<20}{'cycle':>8}{'Δ ms':>8}  verdict"]
    for r in rows:
        delta = (f'{(r.replayed_cycle - r.recorded_cycle) * 1000:8.3f}'
                 if r.replayed_cycle is not None and r.recorded_cycle is not None else ' ' * 8)
        lines.append(f'{r.number:>4}  {_cut(r.request_id, 17):<18}{_cut(r.ends, 33):<34}'
                     f'{_cut(r.recorded, 19):<20}{_seconds(r.recorded_cycle)}  '
                     f'{_cut(r.replayed, 19):<20}{_seconds(r.replayed_cycle)}{delta}  '
                     f'{r.verdict}')
    return '\n'.join(lines)


def summary(rows: List[Row], what: str) -> str:
    """Return one line counting the verdicts."""
    same = sum(r.verdict == 'same' for r in rows)
    different = sum(r.mismatch for r in rows)
    return (f'{len(rows)} queries: {same} {what}, {different} different, '
            f'{len(rows) - same - different} not compared')


def _cut(text: str, width: int) -> str:
    return text if len(text) <= width else text[:width - 1] + '…'


def _seconds(value: Optional[float]) -> str:
    return f'{value:8.3f}' if value is not None else ' ' * 8
