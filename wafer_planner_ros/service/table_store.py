"""
A station table's file: where it is kept, its layout, and how it is written and read.

One JSON file per table key in the cache directory (``table_path``). The file (``FORMAT``
2) stores the key, the SHA-256 of its content (``content_digest``) and each pair's entry
(``service.table_entry``), but no figure of its verification; besides, what its plans depend
on besides the stations (``basis``) and each station as written (``stations``), so that a
table of re-taught stations can inherit the entries of the unchanged ones
(``inheritable``). Files are written to a temporary name and renamed, so a crash never
leaves half a file. What is read from a file is only parsed here: checking it against the
planner, and verifying its entries, is the caller's (``service.table``).
"""

import hashlib
import json
import os
from pathlib import Path
import tempfile
from typing import Dict, NamedTuple, Tuple

import numpy as np

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.stations import station_name

TMP_SUFFIX = '.tmp'
FORMAT = 2
"""The layout of a table file. Format 1 stored each entry's verification figures and
answered with them; format 2 stores none, they are computed on load."""
MAX_DONORS = 20
"""Most table files (the newest) looked at for entries to inherit."""


class TableFile(NamedTuple):
    """The content of a table file, parsed (``read_table``), not yet checked."""

    key: str
    entries: list
    """Each pair's entry as stored, its ``pair`` included."""
    digest: str
    failures: list
    layout: int
    """Its ``FORMAT`` (1 when it names none)."""
    failed: Dict[Tuple[str, str], str]
    """``failures`` by pair."""
    pairs: list
    """The pair of each of ``entries``."""


def table_path(cache_dir, key: str) -> Path:
    """Return the file of a table key in a cache directory."""
    return Path(cache_dir) / f'table-{key[:16]}.json'


def save_table(table, cache_dir) -> Path:
    """Write a table (a ``StationTable``) atomically; return its path."""
    path = table_path(cache_dir, table.key)
    entries = [dict(entry, pair=list(pair)) for pair, entry in sorted(table.entries.items())]
    failures = [[*pair, reason] for pair, reason in sorted(table.failures.items())]
    document = {'key': table.key, 'version': __version__, 'format': FORMAT, 'load': table.load,
                'digest': content_digest([entries, failures]), 'entries': entries,
                'failures': failures, 'basis': table.basis, 'stations': table.stations}
    return write_json(path, document)


def write_json(path: Path, document) -> Path:
    """Write ``document`` as JSON to ``path`` atomically (a temporary name, renamed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=TMP_SUFFIX, dir=path.parent)
    try:
        with os.fdopen(fd, 'w') as stream:
            json.dump(document, stream, default=plain)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def read_table(path: Path) -> TableFile:
    """Return the content of the table file ``path``; raise whatever reading it raises."""
    document = json.loads(path.read_text())
    key, entries = document['key'], document['entries']
    digest, failures = document['digest'], document['failures']
    layout = document.get('format', 1)
    failed = {(a, b): str(reason) for a, b, reason in failures}
    pairs = [tuple(str(name) for name in entry['pair']) for entry in entries]
    return TableFile(key, entries, digest, failures, layout, failed, pairs)


def donor_files(cache_dir) -> list:
    """Return the newest table files in ``cache_dir`` (``MAX_DONORS``), newest first."""
    return sorted(Path(cache_dir).glob('table-*.json'),
                  key=lambda path: path.stat().st_mtime, reverse=True)[:MAX_DONORS]


def inheritable(path: Path, basis: str, stations: Dict[str, str], known) -> dict:
    """
    Return the entries of the table file ``path`` whose two stations are as written now.

    By pair, of the ``known`` pairs only; none when the file is of another ``basis`` or
    format, or its content does not match its digest. Raise whatever reading it raises.
    """
    document = json.loads(path.read_text())
    if document.get('basis') != basis or document.get('format') != FORMAT or \
            content_digest([document['entries'], document['failures']]) != document['digest']:
        return {}
    before = document['stations']
    kept = {}
    for entry in document['entries']:
        pair = tuple(str(name) for name in entry['pair'])
        if pair in known and all(before.get(station_name(name)) == stations[station_name(name)]
                                 for name in pair):
            kept[pair] = {name: value for name, value in entry.items() if name != 'pair'}
    return kept


def content_digest(entries: list) -> str:
    """Return the SHA-256 (hex) of a table file's content: its entries and failures."""
    text = json.dumps(entries, sort_keys=True, default=plain)
    return hashlib.sha256(text.encode()).hexdigest()


def plain(value):
    """Return a numpy scalar or array as JSON data (``json.dumps``'s ``default``)."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON data')
