"""
``wafer-plan-client FROM TO``: ask a running wafer_planner node for one plan.

FROM/TO are station names or ``q1,q2,q3`` (radians; a first angle may be negative). The
client finds the node (``--node``, default ``/wafer_planner``), waits until it reports
ready (``~/get_status``), sends the request to ``~/plan_station_request`` and prints the
``~/result`` worded as ``wafer-plan`` words a plan (``--raw``: every value as sent), and
the trajectory's size. ``--stop-after T`` then stops the move T seconds after it starts
(``~/stop_request``: the controlled stop on its path) and prints the stop's answer too;
``--divert-to STATION`` instead sends the moving robot from there (T, or half-way without
``--stop-after``) to STATION (a station request from the move) and prints that answer.
Exit 0 when the plan (and the stop or divert) is ok; 1 when the node answered with an error,
did not answer within ``--timeout``, or was not found within ``DISCOVERY`` seconds; 2 on a
bad command line.
"""

import argparse
import json
import os
import sys
import time

from wafer_planner_ros.cell.limits import LOADED, LOADS
from wafer_planner_ros.cli import summary
from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, run
from wafer_planner_ros.node.client import ask_planner
from wafer_planner_ros.service.requests import end_of_text, with_negative_ends


def main(argv=None) -> int:
    """Send the request, wait for its result, print it."""
    parser = argparse.ArgumentParser(prog='wafer-plan-client',
                                     description=__doc__.split('\n')[1])
    parser.add_argument('start', metavar='FROM', help='station name or q1,q2,q3 (rad)')
    parser.add_argument('goal', metavar='TO', help='station name or q1,q2,q3 (rad)')
    parser.add_argument('--id', help='request id (default: client-<pid>-<ms since 1970>)')
    parser.add_argument('--timeout', type=float, default=30.0,
                        help='seconds to wait for the node to be ready (the first start after '
                             'an install compiles for about 20 s) and for its answer '
                             '(default: 30)')
    parser.add_argument('--node', default='/wafer_planner',
                        help='the planner node (default: /wafer_planner)')
    parser.add_argument('--load', choices=LOADS, default=LOADED,
                        help='loaded (the default: the wafer limit holds) or empty (joint '
                        'limits only: an empty move with a wafer on the blade can slide it)')
    parser.add_argument('--stop-after', type=float, metavar='T',
                        help='then stop the move T seconds after it starts (a stop request: '
                        'the controlled stop on its path) and print the stop too')
    parser.add_argument('--divert-to', metavar='STATION',
                        help='then send the moving robot to STATION instead, from the moment '
                        'of --stop-after (default: half-way through the move); prints that '
                        'answer too')
    parser.add_argument('--raw', action='store_true',
                        help="print every value of the node's result as it was sent")
    args = parser.parse_args(with_negative_ends(sys.argv[1:] if argv is None else argv))
    try:
        ends = [end_of_text(args.start), end_of_text(args.goal)]
    except ValueError as exc:
        parser.error(str(exc))
    node = args.node if args.node.startswith('/') else f'/{args.node}'
    request_id = args.id or f'client-{os.getpid()}-{int(time.time() * 1000)}'
    request = {'id': request_id, 'from': ends[0], 'to': ends[1]}
    if args.load != LOADED:
        request['load'] = args.load
    if args.stop_after is not None and not args.stop_after >= 0.0:
        parser.error(f'--stop-after must be a number of seconds >= 0, got {args.stop_after}')
    if args.divert_to is not None and not args.divert_to.strip():
        parser.error('--divert-to needs a station name')
    answer = ask_planner(node, request, args.timeout, lambda text: print(text, file=sys.stderr),
                         args.stop_after, args.divert_to)
    if answer is None:
        print(f'{request_id}: no answer from {node} within {args.timeout:g} s',
              file=sys.stderr)
        return EXIT_FAILURE
    codes = []
    parts = [answer[:2]] + ([answer[2:]] if len(answer) > 2 else [])
    then = f"{request_id}-{'stop' if args.divert_to is None else 'divert'}"
    for (status, trajectory), name in zip(parts, (request_id, then)):
        if status is None:
            print(f'{name}: no answer from {node} within {args.timeout:g} s', file=sys.stderr)
            codes.append('')
            continue
        values = {kv.key: kv.value for kv in status.values}
        codes.append(values.get('code'))
        print(f'{name}: {status.message}')
        lines = [f'{k}: {v}' for k, v in values.items()] if args.raw else described(values)
        for line in lines:
            print(f'  {line}')
        if trajectory is not None:
            print(f'  trajectory: {len(trajectory.points)} points, '
                  f'{len(trajectory.joint_names)} joints')
    return EXIT_OK if all(code == 'OK' for code in codes) else EXIT_FAILURE


def described(values: dict) -> list:
    """Return the lines that word a result's values (those it has), as ``wafer-plan`` does."""
    lines = []
    number = {key: summary.number(text) for key, text in values.items()}
    if number.get('cycle_time') is not None:
        line = summary.cycle_text(number['cycle_time'], number.get('initial_cycle_time'))
        if 'branches' in values:
            line += f", {summary.branches_text(summary.branches(values['branches']))}"
        if values.get('load', LOADED) != LOADED:
            line += f", {values['load']}"
        source = _source(values.get('source', ''))
        if values.get('from_optimum') == 'True':
            source += ', from a kept optimum near it'
        line += f" ({values.get('method') or 'planned'}, {source})"
        lines.append(line)
    if number.get('min_clearance') is not None:
        ratios = {k[len('ratio_'):]: v for k, v in number.items()
                  if k.startswith('ratio_') and v is not None}
        lines.append(f"{summary.clearance_text(number['min_clearance'])}; "
                     f'{summary.ratios_text(ratios)}')
    jerk = _numbers(values.get('peak_jerk'))
    if jerk and number.get('peak_wafer_jerk') is not None:
        lines.append(f"{summary.jerk_text(jerk, number['peak_wafer_jerk'])}; "
                     f"{summary.proof_text(values.get('certified') == 'True')}")
    timing = []
    if number.get('planning_time_ms') is not None:
        timing.append(f"planning {number['planning_time_ms']:.1f} ms")
    if number.get('node_ms') is not None:
        timing.append(f"answered {number['node_ms']:.1f} ms after receipt")
    if values.get('roadmap_hash'):
        timing.append(f"roadmap {values['roadmap_hash'][:12]}, seed {values.get('seed', '?')}")
    if timing:
        lines.append('; '.join(timing))
    if values.get('code', 'OK') != 'OK':
        lines.insert(0, f"code {values['code']}")
    return lines


def _numbers(text) -> list:
    """Return a list of numbers sent as JSON ([] when it is not one)."""
    try:
        found = json.loads(text)
    except (TypeError, ValueError):
        return []
    ok = isinstance(found, list) and all(summary.number(v) is not None for v in found)
    return [float(v) for v in found] if ok else []


def _source(source: str) -> str:
    return {'table': 'from the station table', 'planned': 'planned for this request'}.get(
        source, source or 'planned for this request')


def entry_point() -> int:
    """Console script ``wafer-plan-client``."""
    return run(main)


if __name__ == '__main__':
    raise SystemExit(entry_point())
