"""``wafer-plan``: plan a verified, time-optimised trajectory between stations or angles."""

import argparse
from dataclasses import replace
from pathlib import Path
import sys

from wafer_planner_ros.cell.limits import LOADED, LOADS
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.cli import summary
from wafer_planner_ros.cli.common import add_roadmap_options, EXIT_FAILURE, EXIT_OK
from wafer_planner_ros.cli.common import load_cell, Progress, roadmap_for, run, UsageError
from wafer_planner_ros.cli.common import write_json
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.report import error_json, plan_json, roadmap_json
from wafer_planner_ros.service.cycle import loadport_loadlock_pairs, swap_cycle
from wafer_planner_ros.service.planning import PlanningService
from wafer_planner_ros.service.requests import end_of_text, with_negative_ends
from wafer_planner_ros.service.table import load_or_build_table, load_table, TableError
from wafer_planner_ros.trajectory.methods import KnotTiming, METHODS, WholeCurve
from wafer_planner_ros.trajectory.stopping import hold_demand


def parse_end(text: str):
    """Return a station name, or a list of floats for 'q1,q2,q3'; UsageError otherwise."""
    try:
        return end_of_text(text)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def plan_one(planner, start, goal, info, joint_names, stations=None,
             load: str = LOADED) -> tuple:
    """
    Return (result or None, JSON object) for one request; from ``stations`` if it has it.

    ``load``: the limit set (``Planner.plan``); ``stations``: the station table of its moves.

    A pair whose stored entry the table rejected on load is never answered from the file:
    it is planned, with a warning on stderr naming it and why.
    """
    if stations is not None and isinstance(start, str) and isinstance(goal, str):
        rejected = stations.rejected.get((start, goal))
        if rejected is not None:
            print(f'warning: station table: {start} -> {goal} rejected ({rejected}); '
                  'planned again', file=sys.stderr)
    try:
        tables = {} if stations is None else {load: stations}
        result = PlanningService(planner, tables=tables).answer(start, goal, load=load)
    except PlanningError as exc:
        return None, error_json(exc.code.value, exc.message, start, goal, info, load)
    return result, plan_json(result, info, joint_names)


def stop_one(planner, result, at: float, info, joint_names) -> tuple:
    """
    Return (stop or None, JSON object): ``result``'s move stopped ``at`` s after its start.

    The JSON adds what an abrupt hold there would demand of the wafer (``hold_demand``).
    """
    label = f'{result.start.label} -> {result.goal.label}'
    try:
        stopped = planner.stop(result.trajectory, at, label, verified=result.verification)
    except PlanningError as exc:
        return None, error_json(exc.code.value, exc.message, f'{label} at {at} s', 'rest',
                                info, planner.load)
    row = plan_json(stopped, info, joint_names)
    row['metrics']['hold_wafer_acceleration'] = hold_demand(result.trajectory, at,
                                                            planner.cell.robot)
    return stopped, row


def station_table(args, planner, quiet: bool):
    """
    Return the station table of the planner's limit set (whole-curve plans only).

    Cached, or built for --all-pairs.

    A single pair is answered from a cached table when there is one and planned on its own
    otherwise (building the whole table for one pair would take the time of all of them).
    Every cached entry is verified in full on load; one that fails is rejected and planned
    (for --all-pairs into the table, which is stored again).
    """
    if planner.settings.method is not WholeCurve:
        return None
    cache_dir = None if args.no_cache else args.cache_dir
    if not args.all_pairs:
        try:
            return None if cache_dir is None else load_table(planner, cache_dir)
        except TableError:
            return None
    progress = None if quiet else Progress('planning the station table',
                                           text='{done}/{total} pairs ({extra})')
    stations = load_or_build_table(planner, cache_dir, progress)
    if progress is not None:
        progress.done()
    return stations


def table(rows: list) -> str:
    """Return the --all-pairs table."""
    lines = [f"{'pair':<24}{'status':<8}{'cycle s':>8}{'λ-scaled s':>11}{'gain':>7}"
             f"{'path rad':>9}{'clear mm':>9}{'vel':>6}{'acc':>6}{'wafer':>7}"
             f"{'jerk rad/s³':>12}{'ms':>9}"]
    for row in rows:
        pair = f"{row['from']}->{row['to']}"
        if row['status'] != 'ok':
            lines.append(f"{pair:<24}{row['code']}: {row['message']}")
            continue
        m, r = row['metrics'], row['metrics']['limit_ratios']
        wafer = max((v for k, v in r.items() if k.startswith('wafer')), default=None)
        lines.append(
            f"{pair:<24}{'ok':<8}{row['cycle_time']:>8.3f}{row['initial_cycle_time']:>11.3f}"
            f"{1 - row['cycle_time'] / row['initial_cycle_time']:>7.0%}"
            f"{m['joint_path_length']:>9.2f}{m['min_clearance'] * 1000:>9.1f}"
            f"{r['velocity']:>6.2f}{r['acceleration']:>6.2f}"
            f"{'-' if wafer is None else f'{wafer:.3f}':>7}"
            f"{max(m['peak_jerk']):>12.0f}{row['timings_ms']['total']:>9.1f}")
    return '\n'.join(lines)


def main(argv=None) -> int:
    """Run wafer-plan."""
    parser = argparse.ArgumentParser(prog='wafer-plan', description=__doc__.split('\n')[0])
    parser.add_argument('start', nargs='?', metavar='FROM', help='station name or q1,q2,q3')
    parser.add_argument('goal', nargs='?', metavar='TO', help='station name or q1,q2,q3')
    parser.add_argument('--all-pairs', action='store_true',
                        help='plan every loadport->loadlock and loadlock->loadport pair')
    parser.add_argument('--cycle', action='store_true',
                        help='the single-blade swap cycle of every loadport/loadlock pair '
                        '(loaded out, empty back, port to port, non-stop) against the same '
                        'cycle as stop-and-go moves at the loaded limits')
    add_roadmap_options(parser)
    parser.add_argument('--sample-period', type=float, default=0.01,
                        help='seconds between returned samples (default: %(default)s)')
    parser.add_argument('--paper', action='store_true',
                        help="the paper's exact pipeline (no shortcuts, Eq. 3 boxes)")
    parser.add_argument('--method', choices=sorted(METHODS), default=None,
                        help='how the curve is shaped and timed: the whole curve optimised '
                        'and proven (default; seconds per station pair, answered from the '
                        'station table once it is stored), or the corridor curve with '
                        'optimised knot times (milliseconds; the default with --paper)')
    parser.add_argument('--load', choices=LOADS, default=LOADED,
                        help='the limit set: loaded (a wafer on the blade, the wafer limit '
                        'holds; the default) or empty (joint limits only: an empty move '
                        'with a wafer on the blade can slide it)')
    parser.add_argument('--stop-at', type=float, metavar='T',
                        help='then stop the move T seconds after its start: the controlled '
                        'stop on its own path, under every limit (the wafer limit and the '
                        'jerk limit included), as the node answers ~/stop_request')
    parser.add_argument('--json', metavar='PATH|-', help='write the result(s) as JSON')
    parser.add_argument('--plot', metavar='PNG', help='draw the motion and its limits (with '
                        '--stop-at, the stop against an abrupt hold too, at <stem>_stop.png)')
    args = parser.parse_args(with_negative_ends(sys.argv[1:] if argv is None else argv))
    if args.all_pairs and args.cycle:
        raise UsageError('give --all-pairs or --cycle, not both')
    several = args.all_pairs or args.cycle
    if several == (args.start is not None):
        raise UsageError('give FROM and TO, --all-pairs or --cycle')
    if not several and args.goal is None:
        raise UsageError('give both FROM and TO')
    if several and args.stop_at is not None:
        raise UsageError('--stop-at stops one move: give FROM and TO')
    if args.cycle and args.load != LOADED:
        raise UsageError('--cycle plans its own loads (loaded out, empty back): no --load')
    try:
        settings = replace((PlannerSettings.paper if args.paper else PlannerSettings)(
            sample_period=args.sample_period), method=args.method or (
                KnotTiming if args.paper else WholeCurve))
    except ValueError as exc:
        raise UsageError(f'--sample-period: {exc}') from None
    requests = None if several else [(parse_end(args.start), parse_end(args.goal))]
    cell = load_cell(args)
    cached = roadmap_for(args, cell, quiet=args.json == '-')
    planner = Planner(cell, cached.roadmap, settings)
    if args.cycle:
        return _cycles(args, cell, planner)
    info = roadmap_json(cached)
    results, rows = [], []
    stations = station_table(args, planner.for_load(args.load), quiet=args.json == '-')
    for start, goal in requests or station_pairs(cell):
        result, row = plan_one(planner, start, goal, info, cell.robot.joint_names, stations,
                               args.load)
        results.append(result)
        rows.append(row)
    if args.stop_at is not None and results[0] is not None:
        result, row = stop_one(planner.for_load(args.load), results[0], args.stop_at, info,
                               cell.robot.joint_names)
        results.append(result)
        rows.append(row)
    if args.json:
        write_json(rows if args.all_pairs or len(rows) > 1 else rows[0], args.json)
    if args.json != '-':
        print(table(rows) if args.all_pairs else '\n'.join(_summary(row) for row in rows))
    if args.plot:
        _plot(cell, results, rows, Path(args.plot), args.stop_at)
    return EXIT_OK if all(r['status'] == 'ok' for r in rows) else EXIT_FAILURE


def _cycles(args, cell, planner) -> int:
    """Plan, print and write the swap cycle of every loadport/loadlock pair with ports."""
    pairs = loadport_loadlock_pairs(cell)
    if not pairs:
        raise UsageError(f'--cycle: cell {cell.name} has no loadport and loadlock with a port')
    quiet = args.json == '-'
    progress = None if quiet else Progress('planning the swap cycles',
                                           text='{done}/{total} pairs ({extra})')
    cycles = []
    for done, (loadport, loadlock) in enumerate(pairs):

        def plan(start, goal, branches, load, done=done):  # each move shown as it starts
            if progress is not None:
                progress(done, len(pairs), f'{start} -> {goal}, {load}')
            return planner.plan(start, goal, branches=branches, load=load)

        cycles.append(swap_cycle(planner, loadport, loadlock, plan))
    if progress is not None:
        progress.done()
    rows = [c.row() for c in cycles]
    if args.json:
        write_json(rows, args.json)
    if not quiet:
        print(cycle_table(cycles))
    if args.plot:
        from wafer_planner_ros.plotting import plot_cycle
        shown = next((c for c in cycles if c.cycle is not None), None)
        if shown is not None:
            plot_cycle(cell, shown, Path(args.plot))
            print(f'plot: {args.plot} ({shown.loadport} <-> {shown.loadlock})',
                  file=sys.stderr)
    return EXIT_OK if all(c.cycle is not None and c.stop_and_go is not None
                          for c in cycles) else EXIT_FAILURE


def cycle_table(cycles) -> str:
    """Return the --cycle table: seconds of motion and wafers per hour, each way of moving."""
    lines = [f"{'pair':<24}{'non-stop s/wafer':>17}{'wafers/h':>9}{'stop-and-go s/wafer':>20}"
             f"{'wafers/h':>9}{'gain':>7}"]

    def figure(value, width, form):
        return f"{'-' if value is None else format(value, form):>{width}}"

    for c in cycles:
        row = c.row()
        lines.append(f'{c.loadport + " <-> " + c.loadlock:<24}'
                     f"{figure(row['cycle'], 17, '.3f')}{figure(row['wafers_per_hour'], 9, '.0f')}"
                     f"{figure(row['stop_and_go'], 20, '.3f')}"
                     f"{figure(row['stop_and_go_wafers_per_hour'], 9, '.0f')}"
                     f"{figure(row['gain'], 7, '.2f')}")
        lines += [f'  {m.start} -> {m.goal} ({m.load}): {m.error}' for m in c.moves
                  if m.error]
        if c.stop_and_go is None:
            lines += [f'  stop-and-go: {e}' for e in c.stop_and_go_errors]
    return '\n'.join(lines)


def _summary(row: dict) -> str:
    if row['status'] != 'ok':
        return f"{row['from']} -> {row['to']}: {row['code']}: {row['message']}"
    m = row['metrics']
    if 'stopped_at' in m:
        return (f"stop of {row['from']}: ok, at rest after {row['cycle_time']:.3f} s, wafer "
                f"travel {m['wafer_path_length'] * 1000:.1f} mm on the move's path\n"
                f"  {summary.ratios_text(m['limit_ratios'])}\n"
                '  an abrupt hold there (each joint braked alone at its limit) would '
                f"demand {m['hold_wafer_acceleration']:.2f} m/s^2 of the wafer\n"
                f"  {summary.proof_text(m['certified'])}; stop "
                + ', '.join(f'{k} {v:.1f}' for k, v in row['timings_ms'].items()) + ' ms')
    load = '' if row['load'] == LOADED else f", {row['load']}"
    return (f"{row['from']} -> {row['to']}{load}: ok, "
            f"{summary.cycle_text(row['cycle_time'], row['initial_cycle_time'])}, "
            f"{summary.branches_text(m['branches'])}"
            + (f", stopping {m['stops']} times on its way (faster than the non-stop curve)"
               if m.get('stops') else '') + '\n'
            f"  path {m['path_vertices']} vertices ({m['roadmap_path_vertices']} in the "
            f"roadmap), joint length {m['joint_path_length']:.2f} rad, wafer travel "
            f"{m['wafer_path_length']:.3f} m, {summary.clearance_text(m['min_clearance'])}\n"
            f"  {summary.ratios_text(m['limit_ratios'])}\n"
            f"  {summary.jerk_text(m['peak_jerk'], m['peak_wafer_jerk'])}; "
            f"{summary.proof_text(m['certified'])} ({m['proof_pieces']} pieces, depth "
            f"{m['proof_depth']})\n"
            f"  planning {row['timings_ms']['total']:.1f} ms: "
            + ', '.join(f'{k} {v:.1f}' for k, v in row['timings_ms'].items() if k != 'total'))


def _plot(cell, results, rows, path: Path, stop_at=None) -> None:
    """
    Draw each move's figure (one PNG per pair beside ``path`` when there are several).

    With ``stop_at``: the move's at ``path`` and, when it was stopped, the stop against the
    abrupt hold at ``<stem>_stop<suffix>`` (``plotting_stop.plot_stop``).
    """
    from wafer_planner_ros.plotting import plot_trajectory
    if stop_at is not None:
        move, stop = (results + [None])[:2]
        if move is not None:
            plot_trajectory(cell, move, path)
            print(f'plot: {path}', file=sys.stderr)
        if stop is not None:
            from wafer_planner_ros.plotting_stop import plot_stop
            target = path.with_name(f'{path.stem}_stop{path.suffix}')
            plot_stop(cell, move, stop, stop_at, target)
            print(f'plot: {target} (the stop at {stop_at:g} s against an abrupt hold)',
                  file=sys.stderr)
        return
    done = [(r, row) for r, row in zip(results, rows) if r is not None]
    for result, row in done:
        target = path if len(rows) == 1 else path.with_name(
            f"{path.stem}_{row['from']}_{row['to']}{path.suffix}")
        plot_trajectory(cell, result, target)
        print(f'plot: {target}', file=sys.stderr)


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
