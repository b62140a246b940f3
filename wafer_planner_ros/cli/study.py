"""``wafer-study``: layout studies, many variants of a cell planned on local cores or Ray."""

import argparse
import sys

from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, run, UsageError
from wafer_planner_ros.study.evaluate import PLANNED
from wafer_planner_ros.study.report import best_table, write_figures
from wafer_planner_ros.study.results import read_about, read_rows, Results, ResultsError
from wafer_planner_ros.study.spec import Study, StudyError

EXIT_INTERRUPTED = 130

EPILOG = """\
examples:
  wafer-study config/example_study.yaml --out study/       # on every core of this machine
  wafer-study config/example_study.yaml --out study/ --ray auto   # on a Ray cluster
  wafer-study config/example_study.yaml --out study/ --search 200 # an Optuna search
  wafer-study --report study/                               # the best variants, figures
A study stopped at any moment is started again with the same command: only the variants
not yet in study/results.jsonl are planned."""


def main(argv=None) -> int:
    """Run wafer-study."""
    parser = argparse.ArgumentParser(
        prog='wafer-study', description=__doc__.split('\n')[0],
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('study', nargs='?', metavar='STUDY.yaml',
                        help='the study file: a base cell and what varies')
    parser.add_argument('--out', metavar='DIR', help='where the results are written (and '
                        'found again when the study is resumed)')
    parser.add_argument('--ray', metavar='ADDRESS', help='run on the Ray cluster at ADDRESS '
                        '(host:port, or auto: the cluster this machine is part of)')
    parser.add_argument('--workers', type=int, metavar='N', help='local worker processes '
                        '(default: one per core)')
    parser.add_argument('--search', type=int, metavar='N', help='instead of the sweep, an '
                        'Optuna (TPE) search of N trials over study.ranges, minimising the '
                        'swap cycle per wafer')
    parser.add_argument('--report', metavar='DIR', help="print a study's best variants and "
                        'write its figures into DIR/figures')
    parser.add_argument('--axes', nargs=2, metavar=('P1', 'P2'), help='the two parameters '
                        "of the report's heat map (default: the first two that vary)")
    parser.add_argument('--best', type=int, default=10, metavar='K',
                        help='variants listed by the report (default: %(default)s)')
    args = parser.parse_args(argv)
    if args.report:
        if args.study or args.out or args.ray or args.search:
            raise UsageError('--report DIR reads a study directory: give it alone')
        return _report(args)
    if not args.study or not args.out:
        raise UsageError('give STUDY.yaml and --out DIR (or --report DIR)')
    if args.workers is not None and (args.workers < 1 or args.ray):
        raise UsageError('--workers: a number >= 1, for the local machine (not with --ray)')
    if args.search is not None and args.search < 1:
        raise UsageError(f'--search: a number of trials >= 1, got {args.search}')
    try:
        study = Study.from_file(args.study)
    except StudyError as exc:
        raise UsageError(f'{args.study}: {exc}') from None
    if args.search and not study.ranges:
        raise UsageError(f'{args.study}: --search needs study.ranges, the [low, high] of '
                         'each parameter searched')
    from wafer_planner_ros.study import sweep
    try:
        with Results(args.out, sweep.about(study), say) as results:
            executor = _executor(args)
            try:
                if args.search:
                    from wafer_planner_ros.study.search import search
                    outcome = search(study, args.search, executor, results, say)
                else:
                    outcome = sweep.sweep(study, executor, results, say)
            finally:
                executor.close()
    except ResultsError as exc:
        raise UsageError(str(exc)) from None
    except KeyboardInterrupt:
        say(f'stopped; the variants done are in {args.out}: the same command goes on '
            'from there')
        return EXIT_INTERRUPTED
    print(outcome.text)
    return EXIT_OK if outcome.ok else EXIT_FAILURE


def _executor(args):
    if args.ray:
        from wafer_planner_ros.study.executors import RayExecutor
        try:
            executor = RayExecutor(args.ray)
        except (RuntimeError, ConnectionError) as exc:
            raise UsageError(f'--ray {args.ray}: {exc}') from None
    else:
        from wafer_planner_ros.study.executors import LocalExecutor
        executor = LocalExecutor(args.workers)
    say(f'running on {executor.where}')
    return executor


def _report(args) -> int:
    try:
        about, rows = read_about(args.report), read_rows(args.report)
    except ResultsError as exc:
        raise UsageError(str(exc)) from None
    if not rows:
        raise UsageError(f'{args.report}: no variant has been planned yet')
    print(best_table(about, rows, args.best))
    try:
        for path in write_figures(about, rows, args.report, args.axes, say):
            say(f'figure: {path}')
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return EXIT_OK if any(row.get('status') == PLANNED for row in rows) else EXIT_FAILURE


def say(text: str) -> None:
    """Print a line of progress on stderr."""
    print(f'wafer-study: {text}', file=sys.stderr, flush=True)


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
