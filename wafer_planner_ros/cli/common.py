"""What the command-line tools share: cell and roadmap options, progress, recordings, JSON."""

import argparse
import json
import logging
import os
import sys

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import CellError, WaferPlannerError
from wafer_planner_ros.recording.queries import queries
from wafer_planner_ros.recording.reading import read
from wafer_planner_ros.roadmap.cache import DEFAULT_CACHE_DIR, load_or_build
from wafer_planner_ros.roadmap.graph import check_seed, RoadmapSettings

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2


def add_roadmap_options(parser: argparse.ArgumentParser) -> None:
    """Add --cell, --nodes, --seed, --cache-dir and --no-cache."""
    parser.add_argument('--cell', help='cell YAML file (default: the packaged default cell)')
    parser.add_argument('--nodes', type=int, default=RoadmapSettings.nodes,
                        help='roadmap nodes (default: %(default)s)')
    parser.add_argument('--seed', type=int, default=0, help='roadmap seed (default: 0)')
    parser.add_argument('--cache-dir', default=str(DEFAULT_CACHE_DIR),
                        help='roadmap cache directory (default: %(default)s)')
    parser.add_argument('--no-cache', action='store_true', help='always build, never store')


def load_cell(args):
    """Return the cell named by --cell; raise UsageError with the validation message."""
    try:
        cell = Cell.from_yaml(args.cell or default_cell_path())
    except CellError as exc:
        raise UsageError(f'bad cell file: {exc}') from None
    for note in cell.notes:
        print(f'warning: {cell.source}: {note}', file=sys.stderr)
    return cell


def roadmap_for(args, cell, quiet=False):
    """Return the CachedRoadmap for the options, showing build progress on stderr."""
    try:
        settings = RoadmapSettings(nodes=args.nodes)
    except ValueError as exc:
        raise UsageError(f'--nodes: {exc}') from None
    try:
        check_seed(args.seed)
    except ValueError as exc:
        raise UsageError(f'--seed: {exc}') from None
    progress = None if quiet else Progress('building roadmap')
    result = load_or_build(cell, settings, args.seed, None if args.no_cache else args.cache_dir,
                           progress)
    if progress is not None:
        progress.done()
    return result


class UsageError(Exception):
    """A bad command line or input file (exit code 2)."""


def run(main, argv=None) -> int:
    """Run a tool's ``main(argv)``: exit 2 on a UsageError, 1 on another planner error."""
    configure_logging()
    try:
        return main(argv)
    except UsageError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    except WaferPlannerError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return EXIT_FAILURE
    except BrokenPipeError:
        # The reader went away (`| head`): no traceback, and none at exit when Python
        # flushes stdout again (the Python documentation's recipe).
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILURE


class Progress:
    """Show ``label: done/total nodes, edges`` on stderr while a roadmap (or table) builds."""

    def __init__(self, label: str, stream=None,
                 text: str = '{done}/{total} nodes, {extra} edges'):
        """Print to ``stream`` (stderr); on a terminal one line is rewritten in place."""
        self.label, self.stream, self.text = label, stream or sys.stderr, text
        self.tty = self.stream.isatty()
        self.shown = False
        self.last_decile = -1

    def __call__(self, done: int, total: int, extra) -> None:
        """Report progress; off a terminal, print at every tenth of the way."""
        line = f'{self.label}: ' + self.text.format(done=done, total=total, extra=extra)
        if self.tty:
            self.stream.write('\r' + line)
        else:
            decile = 10 * done // max(total, 1)
            if decile == self.last_decile:
                return
            self.last_decile = decile
            self.stream.write(line + '\n')
        self.stream.flush()
        self.shown = True

    def done(self) -> None:
        """End the progress line."""
        if self.shown and self.tty:
            self.stream.write('\n')
            self.stream.flush()


def recorded_queries(bag: str, doing: str) -> tuple:
    """
    Return (recording, its queries) of a bag for a tool that is ``doing`` something with it.

    A recording cut off by a crash is read up to the cut, with a warning on stderr; one
    without requests is a UsageError.
    """
    recording = read(bag)
    if not recording.complete:
        print(f'warning: {recording.path} was cut off ({recording.cut}); {doing} what was '
              'written before (wafer-recover makes it complete)', file=sys.stderr)
    found = queries(recording)
    if not found:
        raise UsageError(f'{bag}: the recording holds no requests')
    return recording, found


def write_json(data, destination: str) -> None:
    """Write JSON to a file, or to stdout for '-'."""
    text = json.dumps(data, indent=2)
    if destination == '-':
        print(text)
    else:
        with open(destination, 'w') as stream:
            stream.write(text + '\n')


def configure_logging() -> None:
    """Send the package's warnings to stderr."""
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s: %(message)s')
