"""
The node's process at start-up: where numba keeps the kernels, and saying what loads.

The node is ready before numba is imported (``kernels``); its loading thread then loads the
kernels while the roadmap serves (``worker``). ``numba_cache`` puts numba's cache under the
node's cache directory (set before numba is imported), ``kernels_announced`` logs that the
kernels are being compiled, with progress, when they are (the first start after an install
or an upgrade), ``since_process_start`` measures readiness from the process's start, and
``core_warnings_to`` sends the core's warnings (Python ``logging``: the recorder's, the
caches', the optimisers') to the node's log, where the rest of what it says goes.
"""

import contextlib
import logging
import os
from pathlib import Path
import threading
import time
from typing import Optional

from wafer_planner_ros import kernels

ANNOUNCE_AFTER = 1.0
"""s after which kernels still being compiled are announced."""
ANNOUNCE_EVERY = 5.0
"""s between the progress lines while the kernels are compiled."""


@contextlib.contextmanager
def kernels_announced(logger):
    """
    Log, while the body runs, that the compiled kernels are being compiled, if they are.

    Loading them from numba's cache takes a fraction of a second; compiling them, at the
    first start after an install or an upgrade, about 20 s: that is announced after
    ``ANNOUNCE_AFTER`` seconds, with progress every ``ANNOUNCE_EVERY`` seconds.
    """
    done, begun, before = threading.Event(), time.monotonic(), kernels.compiled_count()

    def watch() -> None:
        announced = False
        while not done.wait(ANNOUNCE_EVERY if announced else ANNOUNCE_AFTER):
            compiled = kernels.compiled_count() - before
            if not compiled:
                continue
            if not announced:
                where = kernels.cache_directory() or "numba's cache"
                logger.info('compiling the planning kernels for this machine: the first '
                            'start after an install or an upgrade takes about 20 s (they '
                            f'are kept in {where})')
                announced = True
                continue
            logger.info(f'compiling the planning kernels: {compiled} compiled so far, '
                        f'{time.monotonic() - begun:.0f} s')

    watcher = threading.Thread(target=watch, name='wafer_planner_kernels', daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        watcher.join()
        compiled, seconds = kernels.compiled_count() - before, time.monotonic() - begun
        if compiled:
            logger.info(f'planning kernels compiled: {compiled} in {seconds:.1f} s; later '
                        'starts load them')
        else:
            logger.info(f'planning kernels loaded in {seconds:.2f} s')


def numba_cache(cache_dir: Optional[Path]) -> None:
    """Have numba keep its compiled kernels under ``cache_dir`` (before numba is loaded)."""
    if cache_dir is not None and 'NUMBA_CACHE_DIR' not in os.environ \
            and not kernels.loaded():
        os.environ['NUMBA_CACHE_DIR'] = str(Path(cache_dir) / 'numba')


def since_process_start() -> str:
    """Return ', 0.42 s after the process started' (Linux), or '' where that is unknown."""
    try:
        with open('/proc/self/stat') as stat:
            ticks = int(stat.read().rsplit(')', 1)[1].split()[19])
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf('SC_CLK_TCK')
    except (OSError, ValueError, IndexError, AttributeError):
        return ''
    return f', {age:.2f} s after the process started'


class _ToNodeLog(logging.Handler):
    """Hand warnings and errors to a logger that never raises (``faults.SafeLogger``)."""

    def __init__(self, log):
        super().__init__(logging.WARNING)
        self._log = log

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = f'{record.name}: {record.getMessage()}'
        except Exception:  # noqa: B902 - a record whose arguments do not format
            text = f'{record.name}: {record.msg!r}'
        (self._log.error if record.levelno >= logging.ERROR else self._log.warning)(text)


def core_warnings_to(log) -> logging.Handler:
    """Send the package's Python-logging warnings and errors to ``log``; return the handler."""
    handler = _ToNodeLog(log)
    core = logging.getLogger('wafer_planner_ros')
    core.addHandler(handler)
    core.propagate = False  # not to Python's last-resort stderr as well
    return handler
