"""The roadmap cache: hits, and every kind of bad file reported and rebuilt."""

import logging
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from wafer_planner_ros.roadmap import cache
from wafer_planner_ros.roadmap.cache import CacheStatus, load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings

SMALL = RoadmapSettings(nodes=200)


@pytest.fixture()
def built(default_cell, tmp_path):
    """Build a small roadmap into an empty cache; return (first result, cache dir)."""
    first = load_or_build(default_cell, SMALL, 3, tmp_path)
    return first, tmp_path


def test_second_load_is_a_verified_hit_with_the_same_roadmap(default_cell, built):
    first, folder = built
    assert first.status is CacheStatus.MISSING and first.path.is_file()
    second = load_or_build(default_cell, SMALL, 3, folder)
    assert second.hit and second.path == first.path
    assert second.roadmap.digest == first.roadmap.digest
    for name, array in first.roadmap.arrays().items():
        assert np.array_equal(array, second.roadmap.arrays()[name])
    assert second.roadmap.stations == first.roadmap.stations
    assert second.roadmap.stats == first.roadmap.stats


def test_other_seed_or_settings_use_another_file(default_cell, built):
    first, folder = built
    other = load_or_build(default_cell, SMALL, 4, folder)
    assert other.status is CacheStatus.MISSING and other.path != first.path


def _rejected(default_cell, folder, status, caplog):
    with caplog.at_level(logging.WARNING, logger='wafer_planner_ros.roadmap.cache'):
        result = load_or_build(default_cell, SMALL, 3, folder)
    assert result.status is status
    assert any('rebuilding' in r.getMessage() for r in caplog.records)
    again = load_or_build(default_cell, SMALL, 3, folder)
    assert again.hit and again.roadmap.digest == result.roadmap.digest
    return result


def test_stale_key_is_reported_and_rebuilt(default_cell, built, monkeypatch, caplog):
    first, folder = built
    monkeypatch.setattr(cache, '__version__', '0.0.0-old')
    old_key = cache.cache_key(default_cell, SMALL, 3)
    cache.save(first.roadmap, first.path, old_key, default_cell.digest)
    monkeypatch.undo()
    result = _rejected(default_cell, folder, CacheStatus.STALE, caplog)
    assert 'version 0.0.0-old' in result.reason


def test_truncated_file_is_reported_and_rebuilt(default_cell, built, caplog):
    first, folder = built
    data = first.path.read_bytes()
    first.path.write_bytes(data[:len(data) // 2])
    _rejected(default_cell, folder, CacheStatus.CORRUPT, caplog)


def test_garbage_file_is_reported_and_rebuilt(default_cell, built, caplog):
    first, folder = built
    first.path.write_bytes(b'\x00garbage' * 1000)
    _rejected(default_cell, folder, CacheStatus.CORRUPT, caplog)


def test_tampered_content_fails_its_digest(default_cell, built, caplog):
    first, folder = built
    with np.load(first.path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays['nodes'] = arrays['nodes'] + 1e-9
    np.savez(first.path, **arrays)
    result = _rejected(default_cell, folder, CacheStatus.CORRUPT, caplog)
    assert 'digest' in result.reason


def test_file_from_another_cell_is_reported_and_rebuilt(default_cell, cell, built, caplog):
    if cell.digest == default_cell.digest:
        pytest.skip('needs a cell other than the default one')
    first, folder = built
    other = load_or_build(cell, SMALL, 3, folder / 'other')
    shutil.copyfile(other.path, first.path)
    _rejected(default_cell, folder, CacheStatus.OTHER_CELL, caplog)


def test_unwritable_cache_still_builds(default_cell, tmp_path, caplog):
    blocker = tmp_path / 'file'
    blocker.write_text('not a directory')
    with caplog.at_level(logging.WARNING, logger='wafer_planner_ros.roadmap.cache'):
        result = load_or_build(default_cell, SMALL, 3, blocker / 'cache')
    assert result.roadmap.node_count >= 200
    assert any('cannot write' in r.getMessage() for r in caplog.records)


def test_disabled_cache_builds_without_files(default_cell, tmp_path):
    result = load_or_build(default_cell, SMALL, 3, None)
    assert result.status is CacheStatus.DISABLED and result.path is None


_KILLED_WRITER = """
import os, signal, sys
from pathlib import Path
from types import SimpleNamespace
import numpy as np
from wafer_planner_ros.roadmap import cache
from wafer_planner_ros.roadmap.graph import RoadmapSettings


def savez(stream, **arrays):  # killed half way through writing, as by SIGKILL or OOM
    stream.write(b'PK' + bytes(5000))
    stream.flush()
    os.kill(os.getpid(), signal.SIGKILL)


np.savez = savez
roadmap = SimpleNamespace(digest='d', seed=0, settings=RoadmapSettings(), stations={},
                          stats={}, arrays=dict)
cache.save(roadmap, Path(sys.argv[1]), 'key', 'cell')
"""


def _killed_writer(path) -> list:
    """Run ``cache.save`` to ``path`` in a process killed while writing; return what it left."""
    before = set(path.parent.glob('*'))
    run = subprocess.run([sys.executable, '-c', _KILLED_WRITER, str(path)], timeout=60)
    assert run.returncode == -signal.SIGKILL
    return sorted(set(path.parent.glob('*')) - before)


def test_a_killed_writers_temporary_file_is_removed_once_stale(default_cell, built, caplog):
    first, folder = built
    (old,) = _killed_writer(first.path)
    assert old.name.startswith(first.path.name) and old.stat().st_size >= 5000
    (recent,) = _killed_writer(folder / 'roadmap-0123456789abcdef.npz')
    kept = [folder / 'notes.tmp', folder / 'roadmap-old.txt']  # not the cache's
    stale = time.time() - cache.STALE_TMP - 60
    for path in kept:
        path.write_text('someone else')
    for path in (old, *kept):
        os.utime(path, (stale, stale))
    with caplog.at_level(logging.INFO, logger='wafer_planner_ros.roadmap.cache'):
        again = load_or_build(default_cell, SMALL, 3, folder)
    assert again.hit
    assert not old.exists() and recent.exists() and all(path.exists() for path in kept)
    assert [r.getMessage() for r in caplog.records if str(old) in r.getMessage()]
    assert not [r for r in caplog.records if str(recent) in r.getMessage()]
    # One still being written (changed just now) is never taken for a killed writer's.
    assert cache.remove_stale_tmp(folder) == []
    assert cache.remove_stale_tmp(folder, time.time() + cache.STALE_TMP + 1) == [recent]
