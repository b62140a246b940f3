"""
The station table: the loadport-loadlock pairs planned once, kept on disk, answered at once.

Station pairs are a fab's hot path, and the best trajectories take a second or more to
find (``trajectory.shape``), as do the moves through the ports. A table holds the moves of one
limit set (``Planner.load``: loaded or empty). ``build_table`` plans the pairs asked of
``table_pairs`` with a planner (one direction of each; the other is the same motion
backwards): the ``station_pairs`` (retracted pose to retracted pose) and the ``port_pairs``
(inside one port to inside the other, non-stop); ``save_table``/``load_table`` keep the
table in the cache directory, one JSON file per key. The key is the SHA-256 of the cell's
digest, the roadmap's hash, the planner's settings (all but the sample period, which only
changes the returned samples), the limit set and the package version. The file
(``FORMAT`` 2) stores the key, the SHA-256 of its content and each pair's plan, but no
figure of its verification. On load the key, the format and the digest are checked, and
every pair must be one of ``table_pairs``: a stale, foreign or corrupt file is reported
and rebuilt, never trusted. A file may hold some pairs only (a build stopped half-way, or
the port pairs not asked for): ``lacking`` says which of those asked for it lacks, and
``build_table`` given the loaded table plans just those. The digest guards
against damage, not against a deliberate edit, so every curve is then verified in full as
if just planned (``verify``: well formed and at rest exactly on its two stations on the
branches it names, every limit, the proof and the dense collision check over all of
[0, T]; a curve over ``MAX_DURATION`` is rejected before): about 2.5 ms an entry, the
default cell's 12 loaded in a median 31 ms. What an answer reports is that verification
and what it measures on the curve (its method, lengths, counts of points), never a figure
of the file's; the rest an answer takes from the file (the λ-scaled start's cycle time,
the paths behind the curve, the warnings and planning counts) is checked for what it can
be (``_described``). An entry that fails is left out and listed in
``rejected`` with the reason, never answered from; ``build_table`` given the loaded table
plans those pairs again (``load_or_build_table`` does, and stores the table). Files are
written to a temporary name and renamed, so a crash never leaves half a file.

A re-taught station re-plans only its own pairs: a file also stores the SHA-256 of what its
plans depend on besides the stations (the cell without its stations and name, the planner's
settings, the package version: ``basis``) and of each station as written. When no table
matches the key, ``build_and_store_table`` takes from the newest file of the same basis
(``MAX_DONORS`` looked at) the entries of the pairs whose two stations are unchanged
(``inherited_table``), each verified in full as on any load, and plans only the others.
The roadmap may differ (it is built for the whole cell): a verified curve does not depend
on it.
"""

from dataclasses import asdict, dataclass, field, replace
import hashlib
import json
import logging
import os
from pathlib import Path
import tempfile
import time
from typing import Callable, Dict, Optional, Sequence, Tuple

import numpy as np

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.limits import LOADED
from wafer_planner_ros.cell.stations import INSIDE, station_pairs
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import path_lengths, Planner, PlanResult
from wafer_planner_ros.service.adoption import faster
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.methods import WholeCurve
from wafer_planner_ros.trajectory.verify import Verification, verify

logger = logging.getLogger(__name__)

TMP_SUFFIX = '.tmp'
FORMAT = 2
"""The layout of a table file. Format 1 stored each entry's verification figures and
answered with them; format 2 stores none, they are computed on load."""
MAX_DURATION = 60.0
"""s: a stored curve longer than this is rejected before it is checked (the planner's
station moves take seconds; checking a curve costs time and memory in proportion to it)."""
MAX_ITEMS = 10000
"""Most vertices of a stored path, or warnings or counts of an entry."""
MAX_DONORS = 20
"""Most table files (the newest) looked at for entries to inherit."""
MAX_TEXT = 1000
"""Most characters of a stored warning or count's name."""
MEASURED = ('method', 'roadmap_path_vertices', 'path_vertices', 'control_points', 'branches',
            'joint_path_length', 'wafer_path_length')
"""Metrics an answer from the table measures on what it answers with, never read."""


class TableError(Exception):
    """A table file that cannot be used, with the reason."""


@dataclass(frozen=True, eq=False)
class StationTable:
    """The verified plans of station pairs, by (start, goal) name."""

    key: str
    entries: Dict[Tuple[str, str], dict]
    """Each pair's plan as stored (see ``_stored``): only pairs whose curve verified."""
    verified: Dict[Tuple[str, str], Verification]
    """Each entry's full verification, made when it was planned or loaded: what answers
    report."""
    failures: Dict[Tuple[str, str], str] = field(default_factory=dict)
    """Pairs that could not be planned, with the reason."""
    rejected: Dict[Tuple[str, str], str] = field(default_factory=dict)
    """Pairs whose stored entry failed verification on load, with the reason: never answered
    from the file (``build_table`` plans them again; they stay listed here)."""
    seconds: float = 0.0
    """Wall time to build or load (s)."""
    loaded: bool = False
    """Whether it came from the cache as it is (no pair planned)."""
    method: str = WholeCurve.name
    """The curve method of the planner it was planned for (part of its key): what its
    answers report."""
    load: str = LOADED
    """The limit set its moves are planned and verified against (part of its key)."""
    basis: str = ''
    """``table_basis`` of its planner: what its plans depend on besides the stations."""
    stations: Dict[str, str] = field(default_factory=dict)
    """``station_digests`` of its cell."""
    lengths: Dict[Tuple[str, str], dict] = field(default_factory=dict, repr=False)
    """Each pair's path lengths (``planner.path_lengths``), measured on its curve when it is
    first answered: the same every time, and most of an answer's work."""

    def __len__(self) -> int:
        """Return the number of pairs in the table."""
        return len(self.entries)

    def answer(self, planner: Planner, start: str, goal: str) -> Optional[PlanResult]:
        """Return the table's plan from ``start`` to ``goal`` as a result (its load), or None."""
        entry = self.entries.get((start, goal))
        if entry is None:
            return None
        begun = time.perf_counter()
        planner = planner.for_load(self.load)
        lengths = self.lengths.get((start, goal))
        if lengths is None:
            lengths = self.lengths[(start, goal)] = path_lengths(planner.cell, _curve(entry))
        result = _result(planner, (start, goal), entry, self.verified[(start, goal)],
                         self.method, lengths)
        spent = (time.perf_counter() - begun) * 1000.0
        return replace(result, timings_ms={'table': spent, 'total': spent})


def port_pairs(cell) -> list:
    """Return the ``station_pairs`` of two stations with ports, inside one to inside the other."""
    return [(start + INSIDE, goal + INSIDE) for start, goal in station_pairs(cell)
            if cell.stations[start].port is not None and cell.stations[goal].port is not None]


def table_pairs(cell) -> list:
    """Return every pair a table may hold: ``station_pairs``, then ``port_pairs``."""
    return station_pairs(cell) + port_pairs(cell)


def table_key(planner: Planner) -> str:
    """Return the key of a planner's table (hex SHA-256), for the planner's limit set."""
    settings = _plan_settings(planner)
    text = json.dumps({'cell': planner.cell.digest, 'roadmap': planner.roadmap.digest,
                       'settings': settings, 'version': __version__, 'load': planner.load},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def table_basis(planner: Planner) -> str:
    """Return the SHA-256 of what a table's plans depend on besides its stations (hex)."""
    cell = {name: value for name, value in planner.cell.canonical().items()
            if name not in ('stations', 'name')}
    settings = _plan_settings(planner)
    text = json.dumps({'cell': cell, 'settings': settings, 'version': __version__,
                       'load': planner.load}, sort_keys=True, default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()


def _plan_settings(planner: Planner) -> dict:
    """Return the planner's settings its plans depend on, as JSON data (the method by name)."""
    settings = asdict(planner.settings)
    settings.pop('sample_period')
    settings['method'] = planner.settings.method.name
    return settings


def station_digests(cell) -> Dict[str, str]:
    """Return each station's SHA-256 (hex) as written in the cell file."""
    return {name: hashlib.sha256(json.dumps(dict(station.spec), sort_keys=True,
                                            default=_plain).encode()).hexdigest()
            for name, station in cell.stations.items()}


def table_path(cache_dir, key: str) -> Path:
    """Return the file of a table key in a cache directory."""
    return Path(cache_dir) / f'table-{key[:16]}.json'


def build_table(planner: Planner, progress: Optional[Callable[[int, int, str], None]] = None,
                loaded: Optional[StationTable] = None,
                pairs: Optional[Sequence[Tuple[str, str]]] = None,
                donor: Optional[StationTable] = None) -> StationTable:
    """
    Plan the ``pairs`` of ``table_pairs`` (default: every station pair); return the table.

    Against the planner's limit set (``Planner.load``); ``progress(done, total, pair)``
    after each pair.

    A pair whose reverse is already planned gets that trajectory backwards in time
    (``Trajectory.backwards``), verified again: every limit, the clearance and the proof
    are the same for a motion and its reverse, so planning both directions would take
    twice as long for the same cycle time. Given a table ``loaded`` from the cache, only
    the pairs it rejected or lacks are planned; its entries and failures are kept. Given
    the table of another limit set, ``donor`` (the loaded moves' for the empty ones), its
    curve of a pair is taken instead when it is faster than the one planned and passes
    this planner's verification (``adoption.faster``).
    """
    begun = time.perf_counter()
    entries = dict(loaded.entries) if loaded is not None else {}
    verified = dict(loaded.verified) if loaded is not None else {}
    failures = dict(loaded.failures) if loaded is not None else {}
    known = set(table_pairs(planner.cell))
    unknown = [pair for pair in pairs or () if pair not in known]
    if unknown:
        raise ValueError(f'{"->".join(unknown[0])} is not a pair a station table holds')
    pairs = _lacking(entries, failures,
                     station_pairs(planner.cell) if pairs is None else pairs)
    for done, (start, goal) in enumerate(pairs, 1):
        pair = (start, goal)
        try:
            back = entries.get((goal, start))
            if back is None:
                result = planner.plan(start, goal)
                if donor is not None and pair in donor.entries:
                    result = faster(planner, result, donor.answer(planner, start, goal))
                entries[pair], verified[pair] = _entry(result), result.verification
            else:
                entries[pair], verified[pair] = _reversed(planner, pair, back)
        except PlanningError as exc:
            failures[pair] = f'{exc.code.value}: {exc.message}'
        if progress is not None:
            progress(done, len(pairs), f'{start}->{goal}')
    return StationTable(table_key(planner), entries, verified, failures,
                        {} if loaded is None else dict(loaded.rejected),
                        time.perf_counter() - begun + (0.0 if loaded is None else loaded.seconds),
                        method=planner.method.name, load=planner.load,
                        basis=table_basis(planner), stations=station_digests(planner.cell))


def lacking(table: Optional[StationTable], pairs: Sequence[Tuple[str, str]]) -> list:
    """Return the ``pairs`` a table (None: none) neither holds nor records as not plannable."""
    if table is None:
        return list(pairs)
    return _lacking(table.entries, table.failures, pairs)


def _lacking(entries: dict, failures: dict, pairs) -> list:
    return [pair for pair in pairs if pair not in failures and pair not in entries]


def save_table(table: StationTable, cache_dir) -> Path:
    """Write a table atomically; return its path."""
    path = table_path(cache_dir, table.key)
    entries = [dict(entry, pair=list(pair)) for pair, entry in sorted(table.entries.items())]
    failures = [[*pair, reason] for pair, reason in sorted(table.failures.items())]
    document = {'key': table.key, 'version': __version__, 'format': FORMAT, 'load': table.load,
                'digest': _digest([entries, failures]), 'entries': entries,
                'failures': failures, 'basis': table.basis, 'stations': table.stations}
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
    """
    Return the table of ``planner`` from the cache, every entry verified in full.

    An entry whose curve fails verification is left out and listed in ``rejected`` with the
    reason. Raise TableError if the file is unusable: missing, unreadable, for another key
    or format, not matching its digest, or naming pairs that are none of ``table_pairs``.
    A file may lack pairs (a build that stopped half-way, or one that planned some pairs
    only): ``lacking`` says which, ``build_table`` plans them.
    """
    begun = time.perf_counter()
    key = table_key(planner)
    path = table_path(cache_dir, key)
    try:
        document = json.loads(path.read_text())
        stored, entries = document['key'], document['entries']
        digest, failures = document['digest'], document['failures']
        layout = document.get('format', 1)
        failed = {(a, b): str(reason) for a, b, reason in failures}
        pairs = [tuple(str(name) for name in entry['pair']) for entry in entries]
    except FileNotFoundError:
        raise TableError(f'no table file {path}') from None
    except Exception as exc:  # noqa: B902 - any failure to parse means a corrupt file
        raise TableError(f'{path} is unreadable ({type(exc).__name__}: {exc})') from None
    if stored != key:
        raise TableError(f'{path} was built for another cell, roadmap, settings or version')
    if layout != FORMAT:
        raise TableError(f'{path} is in table format {layout}, not {FORMAT}')
    if _digest([entries, failures]) != digest:
        raise TableError(f'{path}: its content does not match its digest')
    known = set(table_pairs(planner.cell))
    strange = [pair for pair in [*pairs, *failed] if pair not in known]
    if strange:
        raise TableError(f'{path} holds {list(strange[0])}, not a station pair')
    table, verified, rejected = {}, {}, {}
    for pair, entry in zip(pairs, entries):
        entry = {name: value for name, value in entry.items() if name != 'pair'}
        try:
            checked = _verified(planner, pair, entry)
        except Exception as exc:  # noqa: B902 - an entry that cannot be read is rejected
            rejected[pair] = f'unreadable ({type(exc).__name__}: {exc})'
            continue
        if checked.ok:
            table[pair], verified[pair] = entry, checked
        else:
            rejected[pair] = '; '.join(checked.problems)
    return StationTable(key, table, verified, failed, rejected, time.perf_counter() - begun,
                        loaded=True, method=planner.method.name, load=planner.load,
                        basis=table_basis(planner), stations=station_digests(planner.cell))


def inherited_table(planner: Planner, cache_dir) -> Optional[StationTable]:
    """
    Return the entries an earlier table leaves for ``planner``, each verified, or None.

    From the newest table file in ``cache_dir`` of the same ``table_basis`` that has any:
    the entries of the pairs whose two stations are written as they are now. Files that
    cannot be read, or whose content does not match its digest, are passed over.
    """
    begun = time.perf_counter()
    basis, stations = table_basis(planner), station_digests(planner.cell)
    known = set(table_pairs(planner.cell))
    try:
        files = sorted(Path(cache_dir).glob('table-*.json'),
                       key=lambda path: path.stat().st_mtime, reverse=True)[:MAX_DONORS]
    except OSError:
        return None
    for path in files:
        try:
            document = json.loads(path.read_text())
            if document.get('basis') != basis or document.get('format') != FORMAT or \
                    _digest([document['entries'], document['failures']]) != document['digest']:
                continue
            before = document['stations']
            kept = {}
            for entry in document['entries']:
                pair = tuple(str(name) for name in entry['pair'])
                if pair in known and all(before.get(_station(name)) == stations[_station(name)]
                                         for name in pair):
                    kept[pair] = {name: value for name, value in entry.items() if name != 'pair'}
        except Exception as exc:  # noqa: B902 - a file that cannot be read is passed over
            logger.debug('station table: %s passed over (%s)', path, exc)
            continue
        entries, verified = {}, {}
        for pair, entry in kept.items():
            try:
                checked = _verified(planner, pair, entry)
            except Exception:  # noqa: B902 - an entry that cannot be read is not inherited
                continue
            if checked.ok:
                entries[pair], verified[pair] = entry, checked
        if entries:
            logger.info('station table: %d of %d pairs inherited from %s (their stations '
                        'unchanged), each verified', len(entries), len(known), path.name)
            return StationTable(table_key(planner), entries, verified,
                                seconds=time.perf_counter() - begun, method=planner.method.name,
                                load=planner.load, basis=basis, stations=stations)
    return None


def load_or_build_table(planner: Planner, cache_dir=None, progress=None,
                        pairs: Optional[Sequence[Tuple[str, str]]] = None) -> StationTable:
    """
    Return the cached table, or build (and, with a cache directory, store) it.

    ``pairs``: what it must hold (default: every station pair). A cached table with rejected
    entries has them planned again, and so has one lacking some of ``pairs``; it is then
    stored again.
    """
    loaded = None
    if cache_dir is not None:
        try:
            loaded = load_table(planner, cache_dir)
        except TableError as exc:
            logger.info('station table: %s; building it', exc)
        else:
            if not loaded.rejected and not lacking(loaded, pairs or station_pairs(planner.cell)):
                return loaded
    return build_and_store_table(planner, cache_dir, progress, loaded=loaded, pairs=pairs)


def build_and_store_table(planner: Planner, cache_dir=None, progress=None,
                          warn: Callable[[str], None] = logger.warning,
                          loaded: Optional[StationTable] = None,
                          pairs: Optional[Sequence[Tuple[str, str]]] = None,
                          donor: Optional[StationTable] = None) -> StationTable:
    """
    Build the table of ``pairs`` and, with a cache directory, store it (``warn`` if not).

    Given a table ``loaded`` from the cache, only its rejected pairs and the ``pairs`` it
    lacks are planned (see ``build_table``); without one, an earlier table's entries for
    unchanged stations are inherited (``inherited_table``) and only the other pairs planned.
    ``donor``: see ``build_table``.
    """
    if loaded is None and cache_dir is not None:
        loaded = inherited_table(planner, cache_dir)
    table = build_table(planner, progress, loaded, pairs, donor)
    if cache_dir is not None:
        try:
            save_table(table, cache_dir)
        except OSError as exc:
            warn(f'station table not stored: {exc}')
    return table


def _entry(result: PlanResult) -> dict:
    """Return what the table keeps of a plan (plain data; an answer's ``source`` is not)."""
    metrics = {name: value for name, value in result.metrics.items() if name != 'source'}
    return _stored(result.branches, result.trajectory, result.initial_cycle_time,
                   result.roadmap_path, result.path, metrics, result.warnings,
                   result.timings_ms['total'])


def _reversed(planner: Planner, pair, entry: dict) -> Tuple[dict, Verification]:
    """Return the entry of ``pair`` from that of its reverse (backwards) and its verification."""
    begun = time.perf_counter()
    trajectory = _curve(entry).backwards()
    branches = entry['branches'][::-1]
    checked = verify(trajectory, planner.cell, *_ends(planner, pair, branches))
    if not checked.ok:  # cannot happen for a verified curve; never trusted all the same
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the reversed trajectory {"->".join(pair)} failed verification: '
                            + '; '.join(checked.problems))
    return _stored(branches, trajectory, entry['initial_cycle_time'],
                   np.asarray(entry['roadmap_path'])[::-1], np.asarray(entry['path'])[::-1],
                   dict(entry['metrics'], reversed=True, branches=branches), entry['warnings'],
                   (time.perf_counter() - begun) * 1000.0), checked


def _stored(branches, trajectory, initial_cycle_time, roadmap_path, path, metrics, warnings,
            planning_ms: float) -> dict:
    """Return a table entry (plain data): the plan, no figure of its verification."""
    return {
        'branches': list(branches), 'trajectory': trajectory.describe(),
        'initial_cycle_time': initial_cycle_time,
        'roadmap_path': np.asarray(roadmap_path).tolist(), 'path': np.asarray(path).tolist(),
        'metrics': dict(metrics), 'warnings': list(warnings), 'planning_ms': planning_ms,
    }


def _verified(planner: Planner, pair, entry: dict) -> Verification:
    """
    Return the full verification of a stored entry's curve, from its stations (``verify``).

    Raise ValueError if the entry cannot be read, its curve is longer than ``MAX_DURATION``,
    or a field an answer takes from it is unfit (``_described``).
    """
    curve = _curve(entry)
    if not curve.duration <= MAX_DURATION:
        raise ValueError(f'its curve lasts {curve.duration:.6g} s, over {MAX_DURATION:g} s')
    checked = verify(curve, planner.cell, *_ends(planner, pair, entry['branches']))
    if checked.ok:
        _described(curve, entry, _ends(planner, pair, entry['branches'], retracted=True))
    return checked


def _described(curve: Trajectory, entry: dict, retracted: list) -> dict:
    """
    Return what an answer takes from a stored entry besides its verified curve, checked.

    Raise ValueError unless: the initial (λ-scaled start's) cycle time is finite and no
    shorter than the curve; the path is a finite (n, 3) array from the curve's start to its
    end, and so is the roadmap path from the ``retracted`` ends (an end inside a port: its
    retracted pose, where the roadmap begins); the warnings are texts; the planning counts
    are numbers or flags. ``MEASURED`` metrics are not read: the caller measures them.
    """
    initial = float(entry['initial_cycle_time'])
    if not curve.duration <= initial < np.inf:
        raise ValueError(f'its initial cycle time {initial!r} is not a finite time at least '
                         f"the curve's {curve.duration:.6g} s")
    paths = {}
    for name, ends, what in (
            ('roadmap_path', np.asarray(retracted), "from its stations' retracted poses"),
            ('path', curve.evaluate([0.0, curve.duration]), "from the curve's start")):
        path = np.asarray(entry[name], float)
        if path.ndim != 2 or path.shape[1] != 3 or not 2 <= len(path) <= MAX_ITEMS \
                or not np.all(np.isfinite(path)) \
                or not np.allclose(path[[0, -1]], ends, rtol=0.0, atol=1e-9):
            raise ValueError(f'its {name} is not a path {what} to its end')
        paths[name] = path
    warnings = entry['warnings']
    if not isinstance(warnings, list) or len(warnings) > MAX_ITEMS or not all(
            isinstance(text, str) and len(text) <= MAX_TEXT for text in warnings):
        raise ValueError('its warnings are not a list of texts')
    counts = {name: value for name, value in entry['metrics'].items() if name not in MEASURED}
    if len(counts) > MAX_ITEMS or not all(
            isinstance(name, str) and len(name) <= MAX_TEXT and (
                isinstance(value, bool) or isinstance(value, int)
                or isinstance(value, float) and np.isfinite(value))
            for name, value in counts.items()):
        raise ValueError('its planning counts are not all finite numbers or flags')
    return {'initial_cycle_time': initial, 'warnings': tuple(warnings), 'counts': counts,
            **paths}


def _ends(planner: Planner, pair, branches, retracted: bool = False) -> list:
    """
    Return the configurations of a pair's ends (stations, or inside ports) on the branches.

    ``retracted``: an end inside a port as its port's mouth (the end of its way out).
    """
    ends = []
    for name, branch, role in zip(pair, branches, ('start', 'goal')):
        end = planner.endpoint(name, role)
        k = next(k for k, (elbow, _) in enumerate(end.configs)
                 if elbow is None or elbow == branch)
        channel = end.channel(k) if retracted else None
        ends.append(end.configs[k][1] if channel is None else channel.mouth)
    return ends


def _station(name: str) -> str:
    """Return the station of a pair's end: ``loadport1`` of ``loadport1:inside``."""
    return name[:-len(INSIDE)] if name.endswith(INSIDE) else name


def _curve(entry: dict) -> Trajectory:
    """Return an entry's curve, of the kind its description names."""
    return Trajectory.from_description(entry['trajectory'])


def _result(planner: Planner, pair, entry: dict, verification: Verification,
            method: str, lengths: dict) -> PlanResult:
    """Return the PlanResult of a stored entry, sampled at the planner's period."""
    trajectory = _curve(entry)
    described = _described(trajectory, entry,
                           _ends(planner, pair, entry['branches'], retracted=True))
    start, goal = (planner.endpoint(name, role) for name, role in zip(pair, ('start', 'goal')))
    times, positions, velocities, accelerations = trajectory.samples(
        planner.settings.sample_period)
    # A station given by joint angles has no elbow branch (None).
    branches = [None if branch is None else int(branch) for branch in entry['branches']]
    # Measured on the curve: its description's control points, or its transfer's (a kind
    # without any has 0).
    description = trajectory.describe()
    points = description.get('control_points') or (
        description.get('transfer') or {}).get('control_points', ())
    metrics = dict(
        described['counts'], method=method,
        roadmap_path_vertices=len(described['roadmap_path']),
        path_vertices=len(described['path']),
        control_points=len(points),
        branches=branches, **lengths, source='table')
    start_q, goal_q = trajectory.evaluate([0.0, trajectory.duration])
    return PlanResult(
        start=start, goal=goal, start_q=start_q, goal_q=goal_q, branches=tuple(branches),
        load=planner.load, trajectory=trajectory,
        initial_cycle_time=described['initial_cycle_time'], verification=verification,
        times=times, positions=positions, velocities=velocities,
        accelerations=accelerations, roadmap_path=described['roadmap_path'],
        path=described['path'], metrics=metrics, warnings=described['warnings'])


def _digest(entries: list) -> str:
    text = json.dumps(entries, sort_keys=True, default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()


def _plain(value):
    """Return a numpy scalar or array as JSON data (``json.dumps``'s ``default``)."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON data')
