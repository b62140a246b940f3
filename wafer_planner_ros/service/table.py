"""
The station table: the loadport-loadlock pairs planned once, kept on disk, answered at once.

Station pairs are a fab's hot path, and the best trajectories take long to find
(``trajectory.shape``), as do the moves through the ports. A table holds the moves of one
limit set (``Planner.load``: loaded or empty). ``build_table`` plans the pairs asked of
``table_pairs`` with a planner (one direction of each; the other is the same motion
backwards: ``service.table_build``): the ``station_pairs`` (retracted pose to retracted
pose) and the ``port_pairs`` (inside one port to inside the other, non-stop);
``save_table``/``load_table`` keep the table in the cache directory, one file per key
(``service.table_store``). The key is the SHA-256 of the cell's digest, the roadmap's hash,
the planner's settings (all but the sample period, which only changes the returned samples),
the limit set and the package version. On load the key, the format and the digest are
checked, and every pair must be one of ``table_pairs``: a stale, foreign or corrupt file is
reported and rebuilt, never trusted. A file may hold some pairs only (a build stopped
half-way, or the port pairs not asked for): ``lacking`` says which of those asked for it
lacks, and ``build_table`` given the loaded table plans just those. Every entry loaded is
verified in full as if just planned, and answers report that verification, never a figure
of the file's (``service.table_entry``). An entry that fails is left out and listed in
``rejected`` with the reason, never answered from; ``build_table`` given the loaded table
plans those pairs again (``load_or_build_table`` does, and stores the table).

A re-taught station re-plans only its own pairs: a file also stores the SHA-256 of what its
plans depend on besides the stations (the cell without its stations and name, the planner's
settings, the package version: ``table_basis``) and of each station as written. When no
table matches the key, ``build_and_store_table`` takes from the newest file of the same
basis the entries of the pairs whose two stations are unchanged (``inherited_table``), each
verified in full as on any load, and plans only the others. The roadmap may differ (it is
built for the whole cell): a verified curve does not depend on it.
"""

from dataclasses import asdict, dataclass, field, replace
import hashlib
import json
import logging
import time
from typing import Callable, Dict, Optional, Sequence, Tuple

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.limits import LOADED
from wafer_planner_ros.cell.stations import INSIDE, station_pairs
from wafer_planner_ros.planner import path_lengths, Planner, PlanResult
from wafer_planner_ros.service.table_build import missing, plan_pairs
from wafer_planner_ros.service.table_entry import entry_curve, entry_result, verified_entry
from wafer_planner_ros.service.table_store import content_digest, donor_files, FORMAT
from wafer_planner_ros.service.table_store import inheritable, plain, read_table, save_table
from wafer_planner_ros.service.table_store import table_path
from wafer_planner_ros.trajectory.methods import WholeCurve
from wafer_planner_ros.trajectory.verify import Verification

logger = logging.getLogger(__name__)


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
            curve = entry_curve(entry)
            lengths = self.lengths[(start, goal)] = path_lengths(planner.cell, curve)
        result = entry_result(planner, (start, goal), entry, self.verified[(start, goal)],
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
                       'load': planner.load}, sort_keys=True, default=plain)
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
                                            default=plain).encode()).hexdigest()
            for name, station in cell.stations.items()}


def build_table(planner: Planner, progress: Optional[Callable[[int, int, str], None]] = None,
                loaded: Optional[StationTable] = None,
                pairs: Optional[Sequence[Tuple[str, str]]] = None,
                donor: Optional[StationTable] = None) -> StationTable:
    """
    Plan the ``pairs`` of ``table_pairs`` (default: every station pair); return the table.

    Against the planner's limit set (``Planner.load``); ``progress(done, total, pair)``
    after each pair. In the build order of ``service.table_build``: a pair whose reverse is
    already planned gets that trajectory backwards in time, verified again. Given a table
    ``loaded`` from the cache, only the pairs it rejected or lacks are planned; its entries
    and failures are kept. Given the table of another limit set, ``donor`` (the loaded
    moves' for the empty ones), its curve of a pair is taken instead when it is faster than
    the one planned and passes this planner's verification (``adoption.faster``).
    """
    begun = time.perf_counter()
    entries = dict(loaded.entries) if loaded is not None else {}
    verified = dict(loaded.verified) if loaded is not None else {}
    failures = dict(loaded.failures) if loaded is not None else {}
    known = set(table_pairs(planner.cell))
    unknown = [pair for pair in pairs or () if pair not in known]
    if unknown:
        raise ValueError(f'{"->".join(unknown[0])} is not a pair a station table holds')
    pairs = missing(entries, failures, station_pairs(planner.cell) if pairs is None else pairs)
    plan_pairs(planner, pairs, entries, verified, failures, progress, donor)
    return StationTable(table_key(planner), entries, verified, failures,
                        {} if loaded is None else dict(loaded.rejected),
                        time.perf_counter() - begun + (0.0 if loaded is None else loaded.seconds),
                        method=planner.method.name, load=planner.load,
                        basis=table_basis(planner), stations=station_digests(planner.cell))


def lacking(table: Optional[StationTable], pairs: Sequence[Tuple[str, str]]) -> list:
    """Return the ``pairs`` a table (None: none) neither holds nor records as not plannable."""
    if table is None:
        return list(pairs)
    return missing(table.entries, table.failures, pairs)


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
        stored = read_table(path)
    except FileNotFoundError:
        raise TableError(f'no table file {path}') from None
    except Exception as exc:  # noqa: B902 - any failure to parse means a corrupt file
        raise TableError(f'{path} is unreadable ({type(exc).__name__}: {exc})') from None
    if stored.key != key:
        raise TableError(f'{path} was built for another cell, roadmap, settings or version')
    if stored.layout != FORMAT:
        raise TableError(f'{path} is in table format {stored.layout}, not {FORMAT}')
    if content_digest([stored.entries, stored.failures]) != stored.digest:
        raise TableError(f'{path}: its content does not match its digest')
    known = set(table_pairs(planner.cell))
    strange = [pair for pair in [*stored.pairs, *stored.failed] if pair not in known]
    if strange:
        raise TableError(f'{path} holds {list(strange[0])}, not a station pair')
    table, verified, rejected = {}, {}, {}
    for pair, entry in zip(stored.pairs, stored.entries):
        entry = {name: value for name, value in entry.items() if name != 'pair'}
        try:
            checked = verified_entry(planner, pair, entry)
        except Exception as exc:  # noqa: B902 - an entry that cannot be read is rejected
            rejected[pair] = f'unreadable ({type(exc).__name__}: {exc})'
            continue
        if checked.ok:
            table[pair], verified[pair] = entry, checked
        else:
            rejected[pair] = '; '.join(checked.problems)
    return StationTable(key, table, verified, stored.failed, rejected,
                        time.perf_counter() - begun, loaded=True, method=planner.method.name,
                        load=planner.load, basis=table_basis(planner),
                        stations=station_digests(planner.cell))


def inherited_table(planner: Planner, cache_dir) -> Optional[StationTable]:
    """
    Return the entries an earlier table leaves for ``planner``, each verified, or None.

    From the newest table file in ``cache_dir`` of the same ``table_basis`` that has any:
    the entries of the pairs whose two stations are written as they are now
    (``table_store.inheritable``). Files that cannot be read, or whose content does not
    match its digest, are passed over.
    """
    begun = time.perf_counter()
    basis, stations = table_basis(planner), station_digests(planner.cell)
    known = set(table_pairs(planner.cell))
    try:
        files = donor_files(cache_dir)
    except OSError:
        return None
    for path in files:
        try:
            kept = inheritable(path, basis, stations, known)
        except Exception as exc:  # noqa: B902 - a file that cannot be read is passed over
            logger.debug('station table: %s passed over (%s)', path, exc)
            continue
        entries, verified = {}, {}
        for pair, entry in kept.items():
            try:
                checked = verified_entry(planner, pair, entry)
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
