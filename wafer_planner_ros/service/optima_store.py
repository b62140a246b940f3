"""
A planner's library of optima on disk, beside its station table (``planner.optima``).

One JSON file per key in the cache directory (``optima_path``), the key the station table's
(``table.table_key``: the cell, the roadmap, the planner's settings, the limit set and the
package version). The file (``FORMAT`` 1) stores the key, each optimum's two ends and curve,
and the SHA-256 of them (``table_store.content_digest``); it is written to a temporary name
and renamed, so a crash never leaves half a file.

Without a file of its own key, the newest file of the same basis is read (the station
table's ``table_basis``: the same robot, enclosure, settings, limit set and version; another
roadmap, or a station re-taught): its optima are drafts as good as any, once verified.

Nothing read back is trusted. A file that cannot be read, is for another key or format,
whose content does not match its digest, or that holds more optima than a planner keeps
is passed over whole (``OptimaError``); every
optimum in one that is read is verified in full from its two ends as if just planned
(``verify``: well formed, at rest exactly on its ends, every limit, the proof and the dense
collision check), and one that fails, or cannot be read, is left out. And a kept optimum
is only ever a draft, optimised, proven and verified for the request it starts: so a
damaged, edited or missing file changes nothing but how fast requests near its optima are
planned.
"""

import json
from pathlib import Path
import time
from typing import NamedTuple, Optional, Tuple

import numpy as np

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.stations import INSIDE
from wafer_planner_ros.planner.optima import OPTIMA_KEPT
from wafer_planner_ros.service.table import table_basis, table_key
from wafer_planner_ros.service.table_entry import entry_curve, MAX_DURATION
from wafer_planner_ros.service.table_store import content_digest, MAX_DONORS, write_json
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.verify import verify

FORMAT = 1
"""The layout of an optima file."""


class OptimaError(Exception):
    """An optima file that cannot be used, with the reason."""


class LoadedOptima(NamedTuple):
    """What ``load_optima`` kept of a file."""

    kept: int
    """Optima that passed verification, kept as drafts (or as fast a curve was already)."""
    rejected: Tuple[str, ...]
    """Why each left out was: its place in the file and the reason."""
    seconds: float
    path: Path
    """The file read: the key's own, or another of the same basis (``load_optima``)."""


def optima_path(cache_dir, key: str) -> Path:
    """Return the optima file of a table key in a cache directory."""
    return Path(cache_dir) / f'optima-{key[:16]}.json'


def save_optima(planner, cache_dir) -> Path:
    """Write ``planner``'s optima (its limit set's) atomically; return the file's path."""
    key = table_key(planner)
    optima = [{'start': optimum.start.tolist(), 'goal': optimum.goal.tolist(),
               'trajectory': optimum.curve.describe()} for optimum in planner.optima.entries()]
    return write_json(optima_path(cache_dir, key), {
        'key': key, 'version': __version__, 'format': FORMAT, 'load': planner.load,
        'basis': table_basis(planner), 'digest': content_digest([optima]), 'optima': optima})


def load_optima(planner, cache_dir) -> LoadedOptima:
    """
    Keep in ``planner.optima`` every optimum of its file that passes verification.

    ``read_optima``, then ``keep_verified`` of all it read. Return how many were kept and
    why the others were not (and from which file). Raise OptimaError as ``read_optima``.
    """
    begun = time.perf_counter()
    path, optima = read_optima(planner, cache_dir)
    kept, rejected = keep_verified(planner, list(enumerate(optima)))
    return LoadedOptima(kept, tuple(rejected), time.perf_counter() - begun, path)


def read_optima(planner, cache_dir) -> Tuple[Path, list]:
    """
    Return (the file read, its optima as stored, none verified yet) for ``planner``.

    Its own key's file; without one, the newest file of the same ``table.table_basis``
    (the cell but its stations, the settings, the limit set, the version: a station
    re-taught, or another roadmap), whose optima are verified against this cell all the
    same, and those near a re-taught station's old pose start its requests near their
    optimum. Raise OptimaError when there is neither, or the file is unreadable, for
    another key or format, or not matching its digest.
    """
    key = table_key(planner)
    path = optima_path(cache_dir, key)
    try:
        document = _read_file(path, key)
    except FileNotFoundError:
        path = _donor(planner, cache_dir)
        try:
            document = _read_file(path, None) if path is not None else None
        except FileNotFoundError:  # removed meanwhile
            document = None
        if document is None:
            raise OptimaError(f'no optima file {optima_path(cache_dir, key)}') from None
    return path, document['optima']


def keep_verified(planner, optima: list) -> Tuple[int, list]:
    """
    Keep in ``planner.optima`` each of ``optima`` ([(place in its file, as stored)]) that passes.

    Each is verified in full from its two ends (``verify``). Return (how many passed, kept
    or as fast a curve already kept for the same ends; why each other did not:
    'optimum K: the reason').
    """
    kept, rejected = 0, []
    joints = len(planner.cell.robot.joint_names)
    for k, stored in optima:
        try:
            start, goal, curve = _read(stored, joints)
            checked = verify(curve, planner.cell, start, goal)
        except Exception as exc:  # noqa: B902 - an optimum that cannot be read is left out
            rejected.append(f'optimum {k}: unreadable ({type(exc).__name__}: {exc})')
            continue
        if not checked.ok:
            rejected.append(f'optimum {k}: ' + '; '.join(checked.problems))
        else:
            planner.optima.add(start, goal, curve)
            kept += 1
    return kept, rejected


def _read_file(path: Path, key) -> dict:
    """
    Return the optima file ``path`` read and checked: its format, digest and ``key``.

    None: any key. Raise FileNotFoundError when there is none, else OptimaError.
    """
    try:
        document = json.loads(path.read_text())
        stored_key, layout = document['key'], document['format']
        optima, digest = document['optima'], document['digest']
    except FileNotFoundError:
        raise
    except Exception as exc:  # noqa: B902 - any failure to parse means a corrupt file
        raise OptimaError(f'{path} is unreadable ({type(exc).__name__}: {exc})') from None
    if key is not None and stored_key != key:
        raise OptimaError(f'{path} was made for another cell, roadmap, settings or version')
    if layout != FORMAT:
        raise OptimaError(f'{path} is in optima format {layout}, not {FORMAT}')
    if not isinstance(optima, list) or content_digest([optima]) != digest:
        raise OptimaError(f'{path}: its content does not match its digest')
    if len(optima) > OPTIMA_KEPT:
        raise OptimaError(f'{path} holds {len(optima)} optima, more than a planner keeps '
                          f'({OPTIMA_KEPT})')
    return document


def _donor(planner, cache_dir) -> Optional[Path]:
    """Return the newest usable optima file of ``planner``'s table basis, or None."""
    basis = table_basis(planner)
    try:
        files = sorted(Path(cache_dir).glob('optima-*.json'),
                       key=lambda path: path.stat().st_mtime, reverse=True)[:MAX_DONORS]
    except OSError:
        return None
    for path in files:
        try:
            if _read_file(path, None).get('basis') == basis:
                return path
        except (OSError, OptimaError):
            continue  # passed over
    return None


def learn_table(planner, table) -> None:
    """
    Keep the curves of a station table's station pairs in ``planner.optima``.

    ``planner``: of the table's limit set. The table's entries are verified (when loaded or
    planned); the moves through the ports are not free moves, and are not kept.
    """
    for (start, goal), entry in table.entries.items():
        if INSIDE in start or INSIDE in goal:
            continue
        curve = entry_curve(entry)
        if isinstance(curve, CubicBSpline):
            planner.optima.add(curve.control_points[0], curve.control_points[-1], curve)


def _read(stored: dict, joints: int) -> tuple:
    """Return (start, goal, curve) of a stored optimum; raise ValueError if unfit."""
    start, goal = (np.asarray(stored[end], float) for end in ('start', 'goal'))
    if start.shape != (joints,) or goal.shape != (joints,) or \
            not np.all(np.isfinite(start)) or not np.all(np.isfinite(goal)):
        raise ValueError(f'its ends are not two sets of {joints} finite joint angles')
    curve = CubicBSpline.described(stored['trajectory'])
    if not curve.duration <= MAX_DURATION:
        raise ValueError(f'its curve lasts {curve.duration:.6g} s, over {MAX_DURATION:g} s')
    return start, goal, curve
