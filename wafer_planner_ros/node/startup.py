"""
The node's process at start-up: the compiled kernels loaded early, and saying what loads.

The node is ready only once it can answer: its roadmap loaded and the compiled kernels too
(``worker``). ``load_kernels`` starts loading the kernels in a thread of their own as the
process starts, beside the imports, the node's set-up and the roadmap's load: the build
``wafer-kernels`` made ahead of time for this machine (``kernels_lookup.load_ahead``, a few
milliseconds, numba not imported), else numba's cache (``kernels.load_cached``, about a
second). ``kernels_ready`` waits for that and, only if some kernel is in neither (an
upgrade of the package, another machine), compiles them (``service.warmup``), announced
by ``kernels_announced`` with progress. ``since_process_start`` measures readiness from
the process's start, and ``core_warnings_to`` sends the core's warnings (Python
``logging``: the recorder's, the caches', the optimisers') to the node's log, where the
rest of what it says goes.
"""

import contextlib
import logging
import os
import threading
import time
from typing import Callable, Optional

from wafer_planner_ros import kernels, kernels_lookup

ANNOUNCE_AFTER = 1.0
"""s after which kernels still being compiled are announced."""
ANNOUNCE_EVERY = 5.0
"""s between the progress lines while the kernels are compiled."""


@contextlib.contextmanager
def kernels_announced(logger):
    """
    Log, while the body runs, that the compiled kernels are being compiled, if they are.

    Loading them from numba's cache takes a fraction of a second; compiling them, when the
    set-up did not (``wafer-kernels``), takes far longer: that is announced after
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
                logger.info('compiling the planning kernels for this machine: not found in '
                            f'{kernels.cache_root()} (`wafer-kernels` compiles them ahead, '
                            'as the set-up does); about 40 s, requests are answered '
                            'ROADMAP_NOT_READY meanwhile')
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


class _KernelLoading:
    """The kernels' load, once per process, in a thread of its own (the module's description)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._thread: Optional[threading.Thread] = None
        self._compiled = threading.Event()
        """Set once every kernel is loaded or compiled."""
        self.ahead = 0
        """Signatures loaded from the build made ahead of time."""
        self.loaded = 0
        """Signatures loaded from numba's cache."""
        self.seconds = 0.0
        self.error: Optional[BaseException] = None
        self.ahead_error: Optional[BaseException] = None
        self.no_build = ''
        """Why there is no build ahead of time to load (``kernels_lookup.NoBuildAhead``)."""

    def start(self) -> None:
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._load, daemon=True,
                                                name='wafer_planner_kernels_load')
                self._thread.start()

    def _load(self) -> None:
        begun = time.monotonic()
        try:
            from wafer_planner_ros.service import warmup  # noqa: F401 - every kernel's module
        except Exception as exc:  # noqa: B902 - then they compile when used
            self.error = exc
            return
        try:
            self.ahead = kernels_lookup.load_ahead()
        except kernels_lookup.NoBuildAhead as exc:
            self.no_build = str(exc)
        except Exception as exc:  # noqa: B902 - a build that does not load: numba's cache
            self.ahead_error = exc
        if not self.ahead:
            try:
                self.loaded = kernels.load_cached()
            except Exception as exc:  # noqa: B902 - then they compile when used
                self.error = exc
        self.seconds = time.monotonic() - begun

    def ready(self, logger, compiling: Callable[[], None]) -> None:
        self.start()
        self._thread.join()
        if self._compiled.is_set():
            return
        with self._lock:  # one compile at a time (a rebuild cannot start meanwhile anyway)
            if self._compiled.is_set():
                return
            if self.ahead_error is not None:
                logger.warning(f'the planning kernels built ahead of time in '
                               f'{kernels_lookup.ahead_root()} could not be loaded: '
                               f"{self.ahead_error}; using numba's cache")
            if self.ahead:
                logger.info(f'planning kernels loaded in {self.seconds:.3f} s: {self.ahead} '
                            'signatures built ahead of time for this machine')
                self._compiled.set()
                return
            if self.error is not None:
                logger.warning(f'the planning kernels could not be loaded from '
                               f'{kernels.cache_root()}: {self.error}')
            if self.no_build:
                logger.info(f'planning kernels built ahead of time: {self.no_build} '
                            "(`wafer-kernels` builds them); loading them from numba's cache")
            missing = kernels.uncached()
            if missing:
                compiling()
                from wafer_planner_ros.service.warmup import compile_kernels
                with kernels_announced(logger):
                    compile_kernels()
            else:
                logger.info(f'planning kernels loaded in {self.seconds:.2f} s: {self.loaded} '
                            "signatures from numba's cache")
            self._compiled.set()


_KERNELS = _KernelLoading()


def load_kernels() -> None:
    """Start loading the compiled kernels (once; returns at once)."""
    _KERNELS.start()


def kernels_ready(logger, compiling: Callable[[], None] = lambda: None) -> None:
    """
    Return once every kernel is loaded: built ahead, cached, or compiled now if missing.

    ``compiling()`` is called first when they must be compiled (tens of seconds), which
    ``kernels_announced`` then logs with progress.
    """
    _KERNELS.ready(logger, compiling)


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
