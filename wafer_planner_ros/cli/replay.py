"""
wafer-replay: re-plan the queries of a recording, or send them to a running node.

``--compare`` (the default) re-plans every recorded request offline (a stop request: the
controlled stop of the replayed move it names, braking from the moment the recorded answer
braked from: a stop the node made ahead follows the move a few ms first), with the recorded cell,
roadmap size and seed, and the parameters in force when it arrived, and prints the recorded
and replayed answer and cycle time of each query. Exit 1 when any differs (code, or cycle
time by more than ``--tolerance``). Answers that depended on the node's load at the time
(BUSY, TIMEOUT, ROADMAP_NOT_READY) or on a time budget (``planning.optimise_budget``) are
listed but not replayed; an answer from the station table is re-planned with the
whole-curve optimisation that made the table (``service.planning``: the answer without a
table or a budget, by the curve method the answer names). ``--publish`` sends the
recorded requests to a running node at their recorded pace and compares its answers. A
split recording is read whole (every file left in its directory, each holding the context
of its queries), or one file of it alone.
"""

import argparse
import sys
from typing import Optional, Tuple

from wafer_planner_ros.cli.common import (EXIT_FAILURE, EXIT_OK, Progress, recorded_queries,
                                          run, UsageError, write_json)
from wafer_planner_ros.errors import CellError, ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.planner.stop import DIVERT as DIVERT_METHOD, METHOD as STOP_METHOD
from wafer_planner_ros.recording.compare import (DEFAULT_TOLERANCE, judge, OK, row_for,
                                                 summary, table)
from wafer_planner_ros.recording.queries import NODE_ONLY_CODES, Query
from wafer_planner_ros.roadmap.cache import DEFAULT_CACHE_DIR, load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service.planning import PlanningService, within_budget
from wafer_planner_ros.service.requests import Moving, request_of, RequestError, stop_request


class Replayer:
    """Re-plan queries as the node did, with one planner per recorded roadmap load."""

    def __init__(self, cache_dir, quiet: bool = False):
        """Use the roadmap cache in ``cache_dir`` (None: build every roadmap)."""
        self.cache_dir, self.quiet = cache_dir, quiet
        self._planners = {}
        self._answers = {}
        """request id -> (planner, result) of the answers replayed so far: what a stop
        request names, as the node kept what it published."""
        self._unreplayed = set()
        """The request ids of queries not replayed: a stop of one is not replayed either."""

    def planner(self, query: Query) -> Planner:
        """
        Return the planner of the roadmap the query was answered on (it has one).

        It uses the curve method the answer names (from the station table or the budgeted
        optimisation: ``whole-curve``; else the corridor curve).
        """
        load = query.load
        period = float(query.parameters.get('trajectory.sample_period', 0.01))
        values = query.result.values if query.result is not None else {}
        named = values.get('method')
        if named in (STOP_METHOD, DIVERT_METHOD):  # a stop's or a divert's: not a curve's
            named = None
        method = PlannerSettings(method=named or PlannerSettings.method).method
        key = (load.cell_text, load.values.get('roadmap_nodes'),
               load.values.get('roadmap_seed'))
        if key not in self._planners:
            self._planners[key] = self._load(load)
        planner = self._planners[key]
        if planner.settings.sample_period != period or planner.settings.method is not method:
            planner = Planner(planner.cell, planner.roadmap,
                              PlannerSettings(sample_period=period, method=method))
        return planner

    def _load(self, load) -> Planner:
        try:
            cell = load.cell
            nodes, seed = int(load.values['roadmap_nodes']), int(load.values['roadmap_seed'])
        except (CellError, KeyError, ValueError) as exc:
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

    def answer(self, query: Query) -> Tuple[str, Optional[float]]:
        """
        Return (code, cycle time or None) of answering ``query`` again as the node did.

        The code is '' when it cannot be (the node's load decided it, or no roadmap had
        been loaded when it arrived, or it stops a move that was not replayed).
        """
        code, cycle_time = self._answer(query)
        if not code:
            self._unreplayed.add(query.request_id)
        return code, cycle_time

    def _answer(self, query: Query) -> Tuple[str, Optional[float]]:
        """Return what ``answer`` does, without noting what was not replayed."""
        if query.code in NODE_ONLY_CODES:
            return '', None
        values = query.result.values if query.result is not None else {}
        if within_budget(query.kind == 'station', values,
                         query.parameters.get('planning.optimise_budget', 0.0)):
            return '', None  # the optimisation stopped when its time was up
        if query.kind == 'stop':
            return self._stop(query)
        try:
            if query.load is None:  # only a station request can be read without the cell
                if query.kind != 'station':
                    return '', None
                request_of(query.kind, query.request, ())
                return '', None
            planner = self.planner(query)
            request = request_of(query.kind, query.request, planner.cell.robot.joint_names)
            if isinstance(request.start, Moving):  # a move left in motion: as a stop is
                kept = self._answers.get(request.start.trajectory)
                if kept is None:
                    return self._unknown(request.start.trajectory)
                result = PlanningService(planner).divert(
                    kept[1].trajectory, request.start.at, request.goal,
                    request.start.trajectory, load=request.load)
            else:
                result = PlanningService(planner).answer(request.start, request.goal,
                                                         load=request.load)
        except (RequestError, PlanningError) as exc:
            return exc.code.value, None
        self._answers[request.request_id] = (planner, result)
        return OK, result.cycle_time

    def _unknown(self, trajectory: str) -> Tuple[str, Optional[float]]:
        """Return the replay of a query naming a trajectory not replayed: as the node did."""
        if trajectory in self._unreplayed:
            return '', None
        return ErrorCode.UNKNOWN_TRAJECTORY.value, None

    def _stop(self, query: Query) -> Tuple[str, Optional[float]]:
        """
        Return (code, cycle time) of a stop request replayed on the move it names.

        The move is the replayed answer of the request it names, so a stop of a move that
        was not replayed (a budgeted or a node-only answer) is not replayed either ('').
        """
        try:
            request = stop_request(query.request.data)
        except RequestError as exc:
            return exc.code.value, None
        kept = self._answers.get(request.trajectory)
        if kept is None:
            return self._unknown(request.trajectory)
        planner, move = kept
        try:
            stopped = planner.stop(move.trajectory, request.at, request.trajectory,
                                   move.load, move.verification,
                                   _ahead(planner, move, request.at, query))
        except PlanningError as exc:
            return exc.code.value, None
        self._answers[request.request_id] = (planner, stopped)
        return OK, stopped.cycle_time


def _ahead(planner, move, at: float, query: Query):
    """
    Return the stop the node made ahead for a recorded stop (None: it was found for ``at``).

    The recorded answer's ``braking_from``: the moment of the move the node's answer braked
    from (later than ``at`` when it was made ahead), found again here on the replayed move.
    """
    braking = query.result.values.get('braking_from') if query.result is not None else None
    try:
        moment = float(braking)
    except (TypeError, ValueError):
        return None
    if not (at < moment < move.trajectory.duration and move.verification.proven):
        return None
    return planner.prepare_stop(move.trajectory, moment, move.verification, move.load)


def main(argv=None) -> int:
    """Run wafer-replay."""
    parser = argparse.ArgumentParser(prog='wafer-replay', description=__doc__.split('\n')[1])
    parser.add_argument('bag', metavar='BAG',
                        help='recording directory (or one of its .mcap files)')
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
