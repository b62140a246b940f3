"""
Station table files edited on purpose, their digest recomputed so that it still matches.

Damage breaks a table file's digest; a deliberate edit need not: whoever edits the curves
can compute the SHA-256 of the new content as well. ``tamper`` does that to the file of
the code under test, whatever its format, so the load can tell a bad entry only from its
curve. The edits, each to one entry's curve:

- ``halved``: every knot times 0.5, the same path in half the time, beyond the limits;
- ``shifted``: every knot plus 0.3 s, a curve that no longer begins at t = 0 (evaluated
  from 0 it first runs its first polynomial backwards, through the wall);
- ``nudged``: the second control point moved by 0.02 rad, a motion that does not start at
  rest;
- ``nan``: a NaN in a control point and, in a file that stores figures, in one of them;
- ``slowed``: every knot times 1000, a curve within every limit that lasts about an hour
  (checking it would take seconds and hundreds of megabytes);
- ``askew``: the wrist's fourth control point (the first that is free of the start at rest)
  turned by 0.05 rad: a motion that starts and ends as stored but, out of a port, turns the
  blade beyond the port's heading tolerance; of a move through ports (``through-ports``)
  the wrist turned by 0.05 rad at the end of its way out of the port and the start of its
  transfer: its parts still join, but the way out is no longer the straight line;

and, the curve left as it is, to what an answer reports besides it:

- ``initial``: a NaN initial (λ-scaled start's) cycle time;
- ``counted``: a NaN planning count and a false method;
- ``path``: a roadmap path that leaves the curve's ends.
"""

import hashlib
import json
from pathlib import Path
from typing import Dict, Mapping, Tuple


def _halved(entry: dict) -> None:
    spline = entry['trajectory']
    spline['knots'] = [0.5 * t for t in spline['knots']]


def _shifted(entry: dict) -> None:
    spline = entry['trajectory']
    spline['knots'] = [t + 0.3 for t in spline['knots']]


def _nudged(entry: dict) -> None:
    entry['trajectory']['control_points'][1][0] += 0.02


def _nan(entry: dict) -> None:
    points = entry['trajectory']['control_points']
    points[len(points) // 2][1] = float('nan')
    if 'verification' in entry:
        entry['verification']['ratios']['velocity'] = float('nan')


def _slowed(entry: dict) -> None:
    spline = entry['trajectory']
    spline['knots'] = [1000.0 * t for t in spline['knots']]


def _askew(entry: dict) -> None:
    curve = entry['trajectory']
    if curve.get('kind') != 'through-ports':
        curve['control_points'][3][2] += 0.05
        return
    # The blade turned by 0.05 rad at the port's mouth, where the transfer starts: the way
    # out still starts at the stored pose and meets the transfer, but no longer straight.
    for q in (curve['out']['channel']['mouth'], *curve['transfer']['control_points'][:3]):
        q[2] += 0.05


def _initial(entry: dict) -> None:
    entry['initial_cycle_time'] = float('nan')


def _counted(entry: dict) -> None:
    entry['metrics'].update(budget=float('nan'), method='forged')


def _path(entry: dict) -> None:
    entry['roadmap_path'] = [[9.0, 9.0, 9.0]] + entry['roadmap_path'][1:]


EDITS = {'halved': _halved, 'shifted': _shifted, 'nudged': _nudged, 'nan': _nan,
         'slowed': _slowed, 'askew': _askew, 'initial': _initial, 'counted': _counted,
         'path': _path}
"""Kind of edit -> what it does to a stored entry."""


def digest(entries: list, failures: list) -> str:
    """Return the digest a table file keeps of its entries and failures."""
    text = json.dumps([entries, failures], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def tamper(path: Path, edits: Mapping[Tuple[str, str], str]) -> Dict[Tuple[str, str], dict]:
    """Edit the named pairs' entries of the table file ``path`` (pair -> kind of ``EDITS``)."""
    document = json.loads(Path(path).read_text())
    edited = {}
    for entry in document['entries']:
        pair = tuple(entry['pair'])
        if pair in edits:
            EDITS[edits[pair]](entry)
            edited[pair] = entry
    assert set(edited) == set(edits), f'no entries for {set(edits) - set(edited)}'
    document['digest'] = digest(document['entries'], document['failures'])
    Path(path).write_text(json.dumps(document))
    return edited
