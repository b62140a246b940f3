"""
wafer-replay: re-plan the queries of a recording, or send them to a running node.

``--compare`` (the default) re-plans every recorded request offline, with the recorded cell,
roadmap size and seed, and the parameters in force when it arrived, and prints the recorded
and replayed answer and cycle time of each query. Exit 1 when any differs (code, or cycle
time by more than ``--tolerance``). Answers that depended on the node's load at the time
(BUSY, TIMEOUT, ROADMAP_NOT_READY) are listed but not replayed. ``--publish`` sends the
recorded requests to a running node at their recorded pace and compares its answers.
"""

import argparse
from dataclasses import dataclass
import sys
from typing import List, Optional

from wafer_planner_ros.cache import DEFAULT_CACHE_DIR, load_or_build
from wafer_planner_ros.cell import Cell
from wafer_planner_ros.cli.common import (EXIT_FAILURE, EXIT_OK, Progress, recorded_queries,
                                          run, UsageError, write_json)
from wafer_planner_ros.errors import CellError, PlanningError
from wafer_planner_ros.node.requests import request_of, RequestError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.recording.queries import NODE_ONLY_CODES, Query, short_label
from wafer_planner_ros.roadmap import RoadmapSettings
import yaml  # after the package: ament_flake8 takes wafer_planner_ros for a third party

OK = 'OK'
"""The code of a planned query (``node.messages.plan_values``)."""
DEFAULT_TOLERANCE = 1e-3
"""Seconds of cycle time by which a replayed answer may differ from the recorded one."""


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
    else:
        same = code == row.recorded and (
            cycle is None or row.recorded_cycle is None
            or abs(cycle - row.recorded_cycle) <= tolerance)
        row.verdict = 'same' if same else 'DIFFERENT'
    return row


class Replayer:
    """Re-plan queries as the node did, with one planner per recorded roadmap load."""

    def __init__(self, cache_dir, quiet: bool = False):
        """Use the roadmap cache in ``cache_dir`` (None: build every roadmap)."""
        self.cache_dir, self.quiet = cache_dir, quiet
        self._planners = {}

    def planner(self, query: Query) -> Planner:
        """Return the planner of the roadmap the query was answered on."""
        load = query.load
        if load is None:
            raise UsageError(f'query {query.number} has no recorded roadmap load: '
                             'the recording holds no cell file for it')
        period = float(query.parameters.get('trajectory.sample_period', 0.01))
        key = (load.cell_text, load.values.get('roadmap_nodes'),
               load.values.get('roadmap_seed'))
        if key not in self._planners:
            self._planners[key] = self._load(load)
        planner = self._planners[key]
        if planner.settings.sample_period != period:
            planner = Planner(planner.cell, planner.roadmap, PlannerSettings(sample_period=period))
        return planner

    def _load(self, load) -> Planner:
        try:
            cell = Cell.from_dict(yaml.safe_load(load.cell_text),
                                  source=load.values.get('cell_file', 'recorded cell.yaml'))
            nodes, seed = int(load.values['roadmap_nodes']), int(load.values['roadmap_seed'])
        except (CellError, KeyError, ValueError, yaml.YAMLError) as exc:
            raise UsageError(f'the recorded roadmap load cannot be used: {exc}') from None
        progress = None if self.quiet else Progress('building roadmap')
        cached = load_or_build(cell, RoadmapSettings(nodes=nodes), seed, self.cache_dir,
                               progress)
        if progress is not None:
            progress.done()
        if cached.roadmap.digest != load.roadmap_hash:
            raise UsageError(
                f'the roadmap rebuilt from the recording ({cached.roadmap.digest[:12]}) is '
                f'not the recorded one ({load.roadmap_hash[:12]}): the results cannot be '
                'compared')
        return Planner(cell, cached.roadmap)

    def answer(self, query: Query):
        """Return (code, cycle time or None) of re-planning ``query``."""
        if query.code in NODE_ONLY_CODES:
            return '', None
        planner = self.planner(query)
        try:
            request = request_of(query.kind, query.request, planner.cell.robot.joint_names)
            result = planner.plan(request.start, request.goal)
        except RequestError as exc:
            return exc.code.value, None
        except PlanningError as exc:
            return exc.code.value, None
        return OK, result.cycle_time


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


def main(argv=None) -> int:
    """Run wafer-replay."""
    parser = argparse.ArgumentParser(prog='wafer-replay', description=__doc__.split('\n')[1])
    parser.add_argument('bag', metavar='BAG', help='recording directory (or its .mcap file)')
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument('--compare', action='store_true',
                      help='re-plan every request offline and compare (the default)')
    mode.add_argument('--publish', action='store_true',
                      help='send the requests to a running node at their recorded pace')
    parser.add_argument('--tolerance', type=float, default=DEFAULT_TOLERANCE,
                        help='cycle-time difference (s) still counted the same '
                             '(default: %(default)s)')
    parser.add_argument('--cache-dir', default=str(DEFAULT_CACHE_DIR),
                        help='roadmap cache directory (default: %(default)s)')
    parser.add_argument('--no-cache', action='store_true', help='always build, never store')
    parser.add_argument('--node', default='',
                        help='--publish: name of the node to ask (default: the recorded one)')
    parser.add_argument('--timeout', type=float, default=60.0,
                        help='--publish: seconds to wait for the last answer '
                             '(default: %(default)s)')
    parser.add_argument('--json', metavar='PATH|-', help='also write the rows as JSON')
    args = parser.parse_args(argv)
    if not args.tolerance >= 0:
        raise UsageError(f'--tolerance must be >= 0, got {args.tolerance}')
    _, found = recorded_queries(args.bag, 'replaying')
    if args.publish:
        from wafer_planner_ros.node.replay_publish import publish
        rows = publish(found, args.node, args.timeout, args.tolerance)
        what = 'answered the same by the node'
    else:
        replayer = Replayer(None if args.no_cache else args.cache_dir,
                            quiet=args.json == '-')
        rows = [judge(row_for(q), *replayer.answer(q), args.tolerance) for q in found]
        what = 'reproduced'
    if args.json:
        write_json([vars(r) for r in rows], args.json)
    if args.json != '-':
        print(table(rows))
        print(summary(rows, what))
    return EXIT_FAILURE if any(r.mismatch for r in rows) else EXIT_OK


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
