"""
Compiled kernels: numba functions that import numba only when one is first called.

Importing numba and loading the kernels from its cache takes long enough to matter at every
start: the node starts it as its process starts (``node.startup``) and is ready once it is
done. A function decorated with :func:`kernel` is a :class:`Kernel`: calling it calls its
numba dispatcher (``numba.njit(cache=True, ...)``), made on the first call. The dispatcher
is made from a copy of the function whose globals name the compiled form of every other
kernel it calls, so kernels call kernels in compiled code as numba functions do.
``Kernel.interpreted`` runs the same code as plain Python (the kernels it calls interpreted
too): a cell file's polygons and its stations' clearances are checked that way when they
are small (``sized``), so that reading a cell needs no numba.
:data:`objmode` stands for ``numba.objmode`` in a kernel (a no-op when interpreted).

Where numba keeps them: ``NUMBA_CACHE_DIR`` when it is set, else :func:`cache_root`
(``$XDG_CACHE_HOME/wafer_planner_ros/numba``, by default ``~/.cache/...``), the same for the
node and every tool whatever their other cache directories, set when numba is first imported
here. ``wafer-kernels`` compiles every kernel into it once after an install
(``service.warmup``); :func:`load_cached` then loads them all without compiling any, and
:func:`uncached` names the kernels that would still compile.

Ahead of time: ``wafer-kernels`` also builds every kernel it can into one extension module
for this machine (``kernels_ahead``, numba's ``pycc``). Once ``kernels_lookup`` has loaded
it (without importing numba, far sooner than numba's cache), a kernel called with arguments
of a type it was built for runs the built code (``Kernel.use_built``); any other call goes
to numba as above. What a build and a call are keyed by is ``kernels_keys``'s.

Only this module and the build (``kernels_ahead``) import numba (a contract in
``setup.cfg``).
"""

import contextlib
import os
from pathlib import Path
import threading
import types
from typing import Callable, List, Optional

from wafer_planner_ros import giving_way
from wafer_planner_ros.kernels_keys import argument_types

_LOCK = threading.RLock()
_KERNELS: List['Kernel'] = []
_MADE = threading.Event()
"""Set once any kernel's dispatcher is made (numba is imported)."""


class _ObjectMode:
    """The stand-in for ``numba.objmode`` (see the module's description)."""

    def __call__(self, **declared):
        """Return a context that does nothing (interpreted code is Python already)."""
        return contextlib.nullcontext()


objmode = _ObjectMode()


class Kernel:
    """A numba kernel compiled on its first call; see the module's description."""

    def __init__(self, function: Callable, options: dict):
        """Keep the Python function and the ``numba.njit`` options (``cache=True`` added)."""
        self.function = function
        self.options = {'cache': True, **options}
        self._compiled = None
        self._interpreted = None
        self._ahead: Optional[dict] = None
        """Argument types (``argument_types``) -> the built function (``load_ahead``)."""
        code = function.__code__
        self._arity = code.co_argcount
        self._defaults = function.__defaults__ or ()
        self.__name__ = function.__name__
        self.__qualname__ = function.__qualname__
        self.__doc__ = function.__doc__
        self.__module__ = function.__module__
        self.__wrapped__ = function

    def __call__(self, *args):
        """
        Call the compiled kernel: built ahead of time for these argument types, or numba's.

        Numba is imported and the kernel made the first time a call needs it. First it
        gives way to an urgent answer being made in another thread (``giving_way``).
        """
        if giving_way.urgent_now():
            giving_way.give_way()
        ahead = self._ahead
        if ahead is not None:
            if len(args) < self._arity:  # built with every argument: the defaults added
                args_all = args + self._defaults[len(args) - self._arity:]
            else:
                args_all = args
            function = ahead.get(argument_types(args_all))
            if function is not None:
                return function(*args_all)
        compiled = self._compiled
        if compiled is None:
            compiled = self.compiled
        return compiled(*args)

    def __repr__(self) -> str:
        """Say which function this is."""
        return f'<kernel {self.__module__}.{self.__qualname__}>'

    @property
    def compiled(self):
        """Return the numba dispatcher (made, not yet compiled, on first use)."""
        if self._compiled is not None:
            return self._compiled
        numba = _numba()  # outside the lock: Python's import lock serialises the import
        with _LOCK:
            if self._compiled is None:
                function = _rebound(self.function, lambda k: k.compiled, numba.objmode)
                self._compiled = numba.njit(**self.options)(function)
                _MADE.set()
            return self._compiled

    @property
    def interpreted(self) -> Callable:
        """Return the function as plain Python, calling the other kernels interpreted."""
        if self._interpreted is not None:
            return self._interpreted
        with _LOCK:
            if self._interpreted is None:
                self._interpreted = _rebound(self.function, lambda k: k.interpreted, objmode)
            return self._interpreted

    def compiled_count(self) -> int:
        """Return how many signatures of this kernel were compiled, not loaded from cache."""
        compiled = self._compiled
        return 0 if compiled is None else sum(list(compiled.stats.cache_misses.values()))

    def load_cached(self) -> int:
        """
        Load every signature numba's cache holds for this kernel on this machine; return how many.

        Entries made for another machine or another version of the function's code are left
        alone (numba would not use them either).
        """
        if not self.options.get('cache'):
            return 0  # made with cache=False: numba keeps nothing of it
        dispatcher = self.compiled
        cache = dispatcher._cache  # numba 0.68's cache: its index lists the signatures
        index = cache._cache_file._load_index()
        current = cache._index_key((), dispatcher.targetctx.codegen())[1:]
        signatures = [key[0] for key in index if tuple(key[1:]) == current]
        for signature in signatures:
            dispatcher.compile(signature)  # found in the cache: loaded, not compiled
        return len(signatures)

    def ahead(self) -> int:
        """Return how many signatures of this kernel this process has built ahead of time."""
        return len(self._ahead or ())

    def use_built(self, table: dict) -> None:
        """Run the built functions of ``table`` (argument types -> function) from now on."""
        self._ahead = table

    def signatures(self) -> list:
        """Return the signatures this process has of the kernel (compiled or loaded)."""
        compiled = self._compiled
        return [] if compiled is None else list(compiled.signatures)


def kernel(function: Callable = None, **options):
    """Make ``function`` a :class:`Kernel`; used bare or with ``numba.njit`` options."""
    def decorate(function: Callable) -> Kernel:
        made = Kernel(function, options)
        with _LOCK:
            _KERNELS.append(made)
        return made
    return decorate if function is None else decorate(function)


def loaded() -> bool:
    """Return whether numba has been imported by a kernel's first call."""
    return _MADE.is_set()


def sized(work: int, limit: int) -> Callable[[Kernel], Callable]:
    """
    Return how to run kernels on a problem of size ``work``: ``form(kernel)(*args)``.

    Interpreted when ``work`` is at most ``limit`` and the kernel has no compiled form
    loaded yet (neither built ahead of time nor numba loaded: a small check at start-up,
    cheaper than loading numba), compiled otherwise.
    """
    if work <= limit:
        return lambda k: k if k.ahead() or loaded() else k.interpreted
    return lambda k: k


def cache_root() -> Path:
    """Return where numba keeps the kernels (see the module's description)."""
    configured = os.environ.get('NUMBA_CACHE_DIR')
    if configured:
        return Path(configured)
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return Path(base) / 'wafer_planner_ros' / 'numba'


def _numba():
    """Import numba, its cache directory set first (``cache_root``)."""
    os.environ.setdefault('NUMBA_CACHE_DIR', str(cache_root()))
    import numba
    return numba


def registered() -> List['Kernel']:
    """Return every kernel of the modules imported so far."""
    with _LOCK:
        return list(_KERNELS)


def load_cached() -> int:
    """Load every kernel's cached signatures (``Kernel.load_cached``); return how many."""
    return sum(k.load_cached() for k in registered())


def uncached() -> List['Kernel']:
    """
    Return the kernels that a call would still compile (after ``load_cached``, ``load_ahead``).

    Those without any signature that no other kernel calls: a kernel called only from
    compiled code is compiled into its callers and has no signature of its own.
    """
    everything = registered()
    called = {id(value) for k in everything for name in k.function.__code__.co_names
              if isinstance(value := k.function.__globals__.get(name), Kernel)}
    return [k for k in everything
            if not k.signatures() and not k.ahead() and id(k) not in called]


def compiled_count() -> int:
    """Return how many kernel signatures this process compiled rather than loaded."""
    return sum(k.compiled_count() for k in registered())


def cache_directory() -> str:
    """Return where numba keeps the compiled kernels ('' before any is made)."""
    with _LOCK:
        made = [k._compiled for k in _KERNELS if k._compiled is not None]
    for dispatcher in made:
        path = dispatcher.stats.cache_path
        if path:
            return str(path)
    return ''


def _rebound(function: Callable, form: Callable[[Kernel], Callable], mode) -> Callable:
    """Return a copy of ``function`` whose global kernels are ``form`` of each."""
    names = dict(function.__globals__)
    for name in function.__code__.co_names:
        value = names.get(name)
        if isinstance(value, Kernel):
            names[name] = form(value)
        elif value is objmode:
            names[name] = mode
    copy = types.FunctionType(function.__code__, names, function.__name__,
                              function.__defaults__, function.__closure__)
    copy.__qualname__ = function.__qualname__
    copy.__doc__ = function.__doc__
    copy.__kwdefaults__ = function.__kwdefaults__
    copy.__module__ = function.__module__
    return copy
