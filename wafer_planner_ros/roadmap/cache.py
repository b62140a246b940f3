"""
Roadmap cache: one ``.npz`` file per cell, settings, seed, version and bodies.

The cell is canonical; the bodies are the robot's and the port margins
(``Cell.motion_model``), whose clearances the nodes store.

The key is the SHA-256 of those five; the file name holds its first 16 hex digits and the
file stores the whole key, the cell's digest and the roadmap's content digest. On load the
key and the content digest are checked; a file that is stale (other settings, seed or
version), from another cell, truncated or garbage is reported and rebuilt, never trusted.
Files are written to a temporary name and renamed, so a crash never leaves half a file;
a temporary file that a killed writer left behind is removed once it is an hour old (a live
writer changes its file every moment and renames it within seconds), whichever process,
on whichever host, wrote it.
"""

from dataclasses import asdict, dataclass
import enum
import hashlib
import json
import logging
import os
from pathlib import Path
import tempfile
import time
from typing import Optional

import numpy as np

from wafer_planner_ros import __version__
from wafer_planner_ros.roadmap.builder import build_roadmap
from wafer_planner_ros.roadmap.graph import Roadmap, RoadmapSettings

logger = logging.getLogger(__name__)

DEFAULT_CACHE_DIR = Path.home() / '.cache' / 'wafer_planner_ros'
TMP_SUFFIX = '.tmp'
STALE_TMP = 3600.0
"""Seconds since its last change after which a temporary file is a killed writer's."""


class CacheStatus(str, enum.Enum):
    """What the cache lookup found."""

    HIT = 'hit'
    DISABLED = 'disabled'
    MISSING = 'missing'
    STALE = 'stale'
    OTHER_CELL = 'other_cell'
    CORRUPT = 'corrupt'


@dataclass(frozen=True)
class CachedRoadmap:
    """A roadmap with where it came from."""

    roadmap: Roadmap
    status: CacheStatus
    path: Optional[Path]
    seconds: float
    """Wall time to load or build (s)."""
    reason: str = ''
    """Why the cached file was not used, if it was not."""

    @property
    def hit(self) -> bool:
        """Return whether the roadmap came from the cache."""
        return self.status is CacheStatus.HIT


def cache_key(cell, settings: RoadmapSettings, seed: int) -> str:
    """Return the cache key of a roadmap (hex SHA-256)."""
    # The bodies (and port margins) whose clearances its nodes store and its edges keep.
    text = json.dumps({'cell': cell.digest, 'settings': asdict(settings), 'seed': seed,
                       'version': __version__, 'bodies': list(cell.motion_model.body_names)},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def cache_path(cache_dir, key: str) -> Path:
    """Return the file of a key in a cache directory."""
    return Path(cache_dir) / f'roadmap-{key[:16]}.npz'


def save(roadmap: Roadmap, path: Path, key: str, cell_digest: str) -> None:
    """Write a roadmap atomically."""
    meta = {'key': key, 'cell': cell_digest, 'digest': roadmap.digest, 'seed': roadmap.seed,
            'settings': asdict(roadmap.settings), 'stations': roadmap.stations,
            'stats': roadmap.stats, 'version': __version__}
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=TMP_SUFFIX, dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as stream:
            np.savez(stream, meta=np.array(json.dumps(meta)), **roadmap.arrays())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def remove_stale_tmp(cache_dir, now: Optional[float] = None) -> list:
    """
    Remove the temporary files of writers killed in ``cache_dir``; return their paths.

    Only files named as ``save`` names them and unchanged for ``STALE_TMP`` seconds: by
    age, not by writer pid, which another host or container sharing the cache would not
    tell apart from a dead one.
    """
    now = time.time() if now is None else now
    removed = []
    try:
        candidates = list(Path(cache_dir).glob(f'roadmap-*.npz*{TMP_SUFFIX}'))
    except OSError:
        return removed
    for tmp in candidates:
        try:
            age = now - tmp.stat().st_mtime
            if age < STALE_TMP:
                continue
            tmp.unlink()
        except FileNotFoundError:  # renamed by its writer, or removed by another process
            continue
        except OSError as exc:
            logger.warning('cannot remove stale roadmap cache file %s: %s', tmp, exc)
            continue
        logger.info('removed %s, left %.1f h ago by a roadmap cache writer that was killed',
                    tmp, age / 3600)
        removed.append(tmp)
    return removed


class _Rejected(Exception):
    def __init__(self, status: CacheStatus, reason: str):
        super().__init__(reason)
        self.status = status


def load(path: Path, key: str, cell_digest: str) -> Roadmap:
    """Return the verified roadmap stored at ``path``; raise _Rejected when unusable."""
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data['meta']))
            arrays = {name: data[name] for name in ('nodes', 'clearance', 'sampler', 'edges',
                                                    'lengths')}
    except FileNotFoundError:
        raise _Rejected(CacheStatus.MISSING, 'no cached file') from None
    except Exception as exc:  # noqa: B902 - any failure to parse means a corrupt file
        raise _Rejected(CacheStatus.CORRUPT, f'unreadable ({type(exc).__name__}: {exc})') from None
    if meta.get('cell') != cell_digest:
        raise _Rejected(CacheStatus.OTHER_CELL, 'the file was built for another cell')
    if meta.get('key') != key:
        raise _Rejected(CacheStatus.STALE, 'built with other settings, seed or package version '
                                           f'(version {meta.get("version")})')
    try:
        roadmap = Roadmap(settings=RoadmapSettings(**meta['settings']), seed=int(meta['seed']),
                          stations={name: tuple(tuple(e) for e in entries)
                                    for name, entries in meta['stations'].items()},
                          stats=meta['stats'], **arrays)
        consistent = (roadmap.edges.size == 0 or int(roadmap.edges.max()) < roadmap.node_count)
    except Exception as exc:  # noqa: B902
        raise _Rejected(CacheStatus.CORRUPT, f'inconsistent content ({exc})') from None
    if not consistent or roadmap.digest != meta.get('digest'):
        raise _Rejected(CacheStatus.CORRUPT, 'content does not match its digest')
    return roadmap


def load_or_build(cell, settings: RoadmapSettings = RoadmapSettings(), seed: int = 0,
                  cache_dir=DEFAULT_CACHE_DIR, progress=None) -> CachedRoadmap:
    """
    Return the roadmap from the cache when a valid file exists, else build and store it.

    ``cache_dir=None`` disables the cache. A rejected file is logged with the reason and
    replaced by a fresh build.
    """
    started = time.perf_counter()
    if cache_dir is None:
        roadmap = build_roadmap(cell, settings, seed, progress)
        return CachedRoadmap(roadmap, CacheStatus.DISABLED, None,
                             time.perf_counter() - started)
    remove_stale_tmp(cache_dir)
    key = cache_key(cell, settings, seed)
    path = cache_path(cache_dir, key)
    try:
        roadmap = load(path, key, cell.digest)
        return CachedRoadmap(roadmap, CacheStatus.HIT, path, time.perf_counter() - started)
    except _Rejected as rejected:
        status, reason = rejected.status, str(rejected)
    if status is not CacheStatus.MISSING:
        logger.warning('roadmap cache %s rejected: %s; rebuilding', path, reason)
    roadmap = build_roadmap(cell, settings, seed, progress)
    try:
        save(roadmap, path, key, cell.digest)
    except OSError as exc:
        logger.warning('cannot write roadmap cache %s: %s', path, exc)
    return CachedRoadmap(roadmap, status, path, time.perf_counter() - started, reason)
