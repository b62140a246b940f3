"""
A study's directory: its rows, appended as variants finish, and one writer at a time.

``DIR/results.jsonl`` holds one JSON object per line, one per variant, keyed by
``variant`` (the content hash of its cell); each is written and flushed to disk as the
variant finishes, so a study killed at any moment loses only the variants under way. A
line cut off by the kill is dropped when the study is opened again (and said so); any
other unreadable line is refused, never overwritten. ``DIR/study.json`` says which study
the rows belong to (its signature, the study file and the base cell as given): a study
with another signature is refused the directory. ``DIR/.lock`` is held (``flock``) while a
study writes, so a second one is refused, not interleaved.
"""

import fcntl
import json
import os
from pathlib import Path
import tempfile
from typing import Callable, Dict, List, Optional, Tuple

RESULTS = 'results.jsonl'
STUDY = 'study.json'
LOCK = '.lock'


class ResultsError(Exception):
    """A directory that holds another study's rows, is in use, or cannot be read."""


class Results:
    """The rows of a study directory, open for appending (a context manager)."""

    def __init__(self, directory, about: dict, say: Callable[[str], None] = lambda text: None):
        """
        Open (or create) ``directory`` for the study ``about`` (its ``signature`` and more).

        Raises ResultsError when another study writes there or its rows are another's.
        """
        self.directory = Path(directory).expanduser()
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            self._lock = open(self.directory / LOCK, 'a+')
        except OSError as exc:
            raise ResultsError(f'{self.directory}: {exc.strerror or exc}') from None
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock.seek(0)
            holder = self._lock.read().strip() or 'another process'
            self._lock.close()
            raise ResultsError(f'{self.directory} is being written by another study '
                               f'({holder}): one study writes a directory at a time') from None
        try:
            self._lock.seek(0)
            self._lock.truncate()
            self._lock.write(f'pid {os.getpid()}\n')
            self._lock.flush()
            self._claim(about)
            self.rows: Dict[str, dict] = {}
            self.order: List[str] = []
            self._read(say)
            self._stream = open(self.directory / RESULTS, 'a')
        except BaseException:
            self._lock.close()
            raise

    def __enter__(self) -> 'Results':
        """Return the open results."""
        return self

    def __exit__(self, *exc) -> None:
        """Close the file and give up the directory."""
        self.close()

    def close(self) -> None:
        """Close the file and give up the directory."""
        self._stream.close()
        self._lock.close()

    def add(self, row: dict) -> None:
        """Append ``row`` (on disk before this returns); a variant already held is kept."""
        if row['variant'] in self.rows:
            return
        self._stream.write(json.dumps(row, sort_keys=True) + '\n')
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self.rows[row['variant']] = row
        self.order.append(row['variant'])

    def sort(self, key: Callable[[dict], tuple]) -> None:
        """Rewrite the file with its rows ordered by ``key`` (atomically: renamed over it)."""
        order = sorted(self.order, key=lambda variant: key(self.rows[variant]))
        if order == self.order:
            return
        path = self.directory / RESULTS
        handle, temporary = tempfile.mkstemp(dir=self.directory, prefix='.results.')
        with os.fdopen(handle, 'w') as stream:
            for variant in order:
                stream.write(json.dumps(self.rows[variant], sort_keys=True) + '\n')
            stream.flush()
            os.fsync(stream.fileno())
        self._stream.close()
        os.replace(temporary, path)
        self._stream = open(path, 'a')
        self.order = order

    def _claim(self, about: dict) -> None:
        path = self.directory / STUDY
        if path.exists():
            held = read_about(self.directory)
            if held.get('signature') != about['signature']:
                raise ResultsError(
                    f"{self.directory} holds the rows of another study ({held.get('name')}, "
                    f"signature {held.get('signature')}; this one is {about['signature']}: "
                    'another base cell, roadmap, method or package version): give another '
                    '--out')
            return
        handle, temporary = tempfile.mkstemp(dir=self.directory, prefix='.study.')
        with os.fdopen(handle, 'w') as stream:
            json.dump(about, stream, indent=2, sort_keys=True)
        os.replace(temporary, path)

    def _read(self, say: Callable[[str], None]) -> None:
        path = self.directory / RESULTS
        rows, good, size = _read_lines(path, 'the file is left as it is')
        for row in rows:
            if row['variant'] not in self.rows:
                self.order.append(row['variant'])
            self.rows[row['variant']] = row
        if good < size:  # the last line, cut off by a kill
            with open(path, 'r+b') as stream:
                stream.truncate(good)
            say(f'{path}: its last line was cut off (the study was stopped while writing '
                'it); that variant is done again')


def read_about(directory) -> dict:
    """Return ``DIR/study.json``: which study the rows of ``directory`` belong to."""
    path = Path(directory).expanduser() / STUDY
    try:
        with open(path) as stream:
            about = json.load(stream)
    except FileNotFoundError:
        raise ResultsError(f'{path.parent}: no study has written there ({STUDY} is '
                           'missing)') from None
    except (OSError, ValueError) as exc:
        raise ResultsError(f'{path}: unreadable ({exc})') from None
    if not isinstance(about, dict):
        raise ResultsError(f'{path}: not a study description')
    return about


def read_rows(directory) -> List[dict]:
    """Return the rows of ``directory`` in file order (a cut-off last line left out)."""
    return _read_lines(Path(directory).expanduser() / RESULTS)[0]


def _read_lines(path: Path, after: str = '') -> Tuple[List[dict], int, int]:
    """
    Return the whole lines of ``path`` as rows, the bytes they span and the file's size.

    A last line without its newline (a write cut off by a kill) is not a row. A whole line
    that is not a row with a ``variant`` raises :class:`ResultsError` naming its number.
    """
    try:
        with open(path, 'rb') as stream:
            data = stream.read()
    except FileNotFoundError:
        return [], 0, 0
    rows: List[dict] = []
    good = 0
    for number, line in enumerate(data.split(b'\n')[:-1], 1):
        try:
            row = json.loads(line)
        except ValueError:
            row = None
        if not isinstance(row, dict) or 'variant' not in row:
            raise ResultsError(f'{path}, line {number}: not a row of results'
                               + (f'; {after}' if after else ''))
        rows.append(row)
        good += len(line) + 1
    return rows, good, len(data)


def without_cost(row: Optional[dict]) -> Optional[dict]:
    """Return the row without ``cost`` (what differs from run to run)."""
    return None if row is None else {k: v for k, v in row.items() if k != 'cost'}
