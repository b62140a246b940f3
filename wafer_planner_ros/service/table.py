"""
The station table: every loadport-loadlock pair planned once, kept on disk, answered at once.

Station pairs are a fab's hot path, and the best trajectories take seconds to find
(``trajectory.shape``). ``build_table`` plans every pair of ``station_pairs`` with a
planner (one direction of each; the other is the same motion backwards);
``save_table``/``load_table`` keep the table in the cache directory, one JSON file per key.
The key is the SHA-256 of the cell's digest, the roadmap's hash, the planner's settings
(all but the sample period, which only changes the returned samples) and the package
version; the file stores the key and the SHA-256 of its content. On load both are
checked, every station pair must be there (or recorded as not plannable), and every curve
must be a well-formed clamped cubic that starts and ends exactly at its two stations on
the branches it names and is proven collision-free again (``proof.prove``, about a
millisecond each); the limit checks of its verification are taken from the file, which the
digest protects against damage (not against a deliberate edit). A stale, foreign or corrupt
file is reported and rebuilt, never trusted. Files are written to a temporary name and
renamed, so a crash never leaves half a file.
"""

from dataclasses import asdict, dataclass, field, replace
import hashlib
import json
import logging
import os
from pathlib import Path
import tempfile
import time
from typing import Callable, Dict, Optional, Tuple

import numpy as np

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlanResult
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.proof import CurveProof, prove
from wafer_planner_ros.trajectory.verify import Verification, verify

logger = logging.getLogger(__name__)

TMP_SUFFIX = '.tmp'


class TableError(Exception):
    """A table file that cannot be used, with the reason."""


@dataclass(frozen=True, eq=False)
class StationTable:
    """The verified plans of station pairs, by (start, goal) name."""

    key: str
    entries: Dict[Tuple[str, str], dict]
    """Each pair's plan as stored (see ``_entry``)."""
    failures: Dict[Tuple[str, str], str] = field(default_factory=dict)
    """Pairs that could not be planned, with the reason."""
    seconds: float = 0.0
    """Wall time to build or load (s)."""
    loaded: bool = False
    """Whether it came from the cache."""

    def __len__(self) -> int:
        """Return the number of pairs in the table."""
        return len(self.entries)

    def answer(self, planner: Planner, start: str, goal: str) -> Optional[PlanResult]:
        """Return the table's plan from ``start`` to ``goal`` as a result, or None."""
        entry = self.entries.get((start, goal))
        if entry is None:
            return None
        begun = time.perf_counter()
        result = _result(planner, (start, goal), entry)
        spent = (time.perf_counter() - begun) * 1000.0
        return replace(result, timings_ms={'table': spent, 'total': spent})


def table_key(planner: Planner) -> str:
    """Return the key of a planner's table (hex SHA-256)."""
    settings = asdict(planner.settings)
    settings.pop('sample_period')
    text = json.dumps({'cell': planner.cell.digest, 'roadmap': planner.roadmap.digest,
                       'settings': settings, 'version': __version__}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def table_path(cache_dir, key: str) -> Path:
    """Return the file of a table key in a cache directory."""
    return Path(cache_dir) / f'table-{key[:16]}.json'


def build_table(planner: Planner, progress: Optional[Callable[[int, int, str], None]] = None
                ) -> StationTable:
    """
    Plan every station pair; ``progress(done, total, pair)`` after each.

    A pair whose reverse is already planned gets that trajectory backwards in time
    (``CubicBSpline.backwards``), verified again: every limit, the clearance and the proof
    are the same for a motion and its reverse, so planning both directions would take
    twice as long for the same cycle time.
    """
    begun = time.perf_counter()
    pairs = station_pairs(planner.cell)
    entries, failures = {}, {}
    for done, (start, goal) in enumerate(pairs, 1):
        try:
            back = entries.get((goal, start))
            entries[(start, goal)] = _entry(planner.plan(start, goal)) if back is None \
                else _reversed(planner, (start, goal), back)
        except PlanningError as exc:
            failures[(start, goal)] = f'{exc.code.value}: {exc.message}'
        if progress is not None:
            progress(done, len(pairs), f'{start}->{goal}')
    return StationTable(table_key(planner), entries, failures, time.perf_counter() - begun)


def save_table(table: StationTable, cache_dir) -> Path:
    """Write a table atomically; return its path."""
    path = table_path(cache_dir, table.key)
    entries = [dict(entry, pair=list(pair)) for pair, entry in sorted(table.entries.items())]
    failures = [[*pair, reason] for pair, reason in sorted(table.failures.items())]
    document = {'key': table.key, 'version': __version__,
                'digest': _digest([entries, failures]), 'entries': entries,
                'failures': failures}
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=TMP_SUFFIX, dir=path.parent)
    try:
        with os.fdopen(fd, 'w') as stream:
            json.dump(document, stream, default=_plain)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_table(planner: Planner, cache_dir) -> StationTable:
    """Return the verified table of ``planner`` from the cache; raise TableError if unusable."""
    begun = time.perf_counter()
    key = table_key(planner)
    path = table_path(cache_dir, key)
    try:
        document = json.loads(path.read_text())
        stored, entries = document['key'], document['entries']
        digest, failures = document['digest'], document['failures']
        failed = {(a, b): str(reason) for a, b, reason in failures}
    except FileNotFoundError:
        raise TableError(f'no table file {path}') from None
    except Exception as exc:  # noqa: B902 - any failure to parse means a corrupt file
        raise TableError(f'{path} is unreadable ({type(exc).__name__}: {exc})') from None
    if stored != key:
        raise TableError(f'{path} was built for another cell, roadmap, settings or version')
    if _digest([entries, failures]) != digest:
        raise TableError(f'{path}: its content does not match its digest')
    table = {}
    for entry in entries:
        try:
            pair = tuple(entry.pop('pair'))
            _check(planner, pair, entry)
        except Exception as exc:  # noqa: B902 - a bad entry means a corrupt file
            raise TableError(f'{path}: entry {list(pair)}: {exc}') from None
        table[pair] = entry
    missing = set(station_pairs(planner.cell)) - set(table) - set(failed)
    if missing:
        raise TableError(f'{path} lacks {len(missing)} station pairs, e.g. '
                         f'{"->".join(sorted(missing)[0])}')
    return StationTable(key, table, failed, time.perf_counter() - begun, loaded=True)


def load_or_build_table(planner: Planner, cache_dir=None, progress=None) -> StationTable:
    """Return the cached table, or build (and, with a cache directory, store) it."""
    if cache_dir is not None:
        try:
            return load_table(planner, cache_dir)
        except TableError as exc:
            logger.info('station table: %s; building it', exc)
    return build_and_store_table(planner, cache_dir, progress)


def build_and_store_table(planner: Planner, cache_dir=None, progress=None,
                          warn: Callable[[str], None] = logger.warning) -> StationTable:
    """Build the table and, with a cache directory, store it (``warn`` if that fails)."""
    table = build_table(planner, progress)
    if cache_dir is not None:
        try:
            save_table(table, cache_dir)
        except OSError as exc:
            warn(f'station table not stored: {exc}')
    return table


def _entry(result: PlanResult) -> dict:
    """Return what the table keeps of a plan (plain data)."""
    return _stored(result.branches, result.trajectory, result.initial_cycle_time,
                   result.verification, result.roadmap_path, result.path, result.metrics,
                   result.warnings, result.timings_ms['total'])


def _reversed(planner: Planner, pair, entry: dict) -> dict:
    """Return the entry of ``pair`` from that of its reverse: its trajectory backwards."""
    begun = time.perf_counter()
    trajectory = _curve(entry).backwards()
    branches = entry['branches'][::-1]
    checked = verify(trajectory, planner.cell, *_ends(planner, pair, branches))
    if not checked.ok:  # cannot happen for a verified curve; never trusted all the same
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the reversed trajectory {"->".join(pair)} failed verification: '
                            + '; '.join(checked.problems))
    return _stored(branches, trajectory, entry['initial_cycle_time'], checked,
                   np.asarray(entry['roadmap_path'])[::-1], np.asarray(entry['path'])[::-1],
                   dict(entry['metrics'], reversed=True, branches=branches), entry['warnings'],
                   (time.perf_counter() - begun) * 1000.0)


def _stored(branches, trajectory, initial_cycle_time, checked: Verification, roadmap_path,
            path, metrics, warnings, planning_ms: float) -> dict:
    """Return a table entry (plain data)."""
    proof = checked.proof
    return {
        'branches': list(branches), 'trajectory': trajectory.describe(),
        'initial_cycle_time': initial_cycle_time,
        'verification': {
            'ratios': dict(checked.ratios), 'min_clearance': checked.min_clearance,
            'peak_jerk': list(checked.peak_jerk), 'peak_wafer_jerk': checked.peak_wafer_jerk,
            'limit_samples': checked.limit_samples,
            'collision_samples': checked.collision_samples,
            'proof': {'certified': proof.certified, 'pieces': proof.pieces,
                      'depth': proof.depth, 'evaluations': proof.evaluations}},
        'roadmap_path': np.asarray(roadmap_path).tolist(), 'path': np.asarray(path).tolist(),
        'metrics': dict(metrics), 'warnings': list(warnings), 'planning_ms': planning_ms,
    }


def _check(planner: Planner, pair, entry: dict) -> None:
    """
    Raise ValueError unless the entry's curve is fit to answer with.

    It must be well formed, join the pair's stations on the branches it names, and be
    proven collision-free in the cell now (``prove``).
    """
    curve = _curve(entry)
    points = curve.control_points
    if len(curve.knots) != len(points) + 4 or np.any(np.diff(curve.knots) < 0.0) \
            or not np.all(np.isfinite(curve.knots)) or not np.all(np.isfinite(points)):
        raise ValueError('its curve is not a clamped cubic B-spline')
    ends = _ends(planner, pair, entry['branches'])
    if not (np.array_equal(points[0], ends[0]) and np.array_equal(points[-1], ends[1])):
        raise ValueError('its curve does not join the two stations')
    if not prove(curve, planner.cell.clearance_model, planner.cell.robot.lipschitz).certified:
        raise ValueError('its curve is not proven collision-free')


def _ends(planner: Planner, pair, branches) -> list:
    """Return the configurations of a pair's stations on the given elbow branches."""
    ends = []
    for name, branch in zip(pair, branches):
        station = planner.cell.stations[name]
        ends.append(next(c.q for c in station.configs
                         if 'joints' in station.spec or c.elbow == branch))
    return ends


def _curve(entry: dict) -> CubicBSpline:
    spline = entry['trajectory']
    return CubicBSpline(np.asarray(spline['knots'], float),
                        np.asarray(spline['control_points'], float))


def _result(planner: Planner, pair, entry: dict) -> PlanResult:
    """Return the PlanResult of a stored entry, sampled at the planner's period."""
    trajectory = _curve(entry)
    stored = entry['verification']
    verification = Verification(
        problems=(), ratios=stored['ratios'], min_clearance=stored['min_clearance'],
        peak_jerk=tuple(stored['peak_jerk']), peak_wafer_jerk=stored['peak_wafer_jerk'],
        limit_samples=stored['limit_samples'], collision_samples=stored['collision_samples'],
        proof=CurveProof(**stored['proof']))
    start, goal = (planner.endpoint(name, role) for name, role in zip(pair, ('start', 'goal')))
    times, positions, velocities, accelerations = trajectory.samples(
        planner.settings.sample_period)
    return PlanResult(
        start=start, goal=goal, start_q=trajectory.control_points[0],
        goal_q=trajectory.control_points[-1], branches=tuple(entry['branches']),
        trajectory=trajectory, initial_cycle_time=entry['initial_cycle_time'],
        verification=verification, times=times, positions=positions, velocities=velocities,
        accelerations=accelerations, roadmap_path=np.asarray(entry['roadmap_path'], float),
        path=np.asarray(entry['path'], float), metrics=dict(entry['metrics'], source='table'),
        warnings=tuple(entry['warnings']))


def _digest(entries: list) -> str:
    text = json.dumps(entries, sort_keys=True, default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()


def _plain(value):
    """Return a numpy scalar or array as JSON data (``json.dumps``'s ``default``)."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON data')
