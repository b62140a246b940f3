"""
Giving way: long computations pause while an answer someone is waiting for is made.

Python runs one thread at a time (the interpreter lock) and, while several want to run,
switches between them every few milliseconds: an answer made beside a plan being computed
takes about twice its own time. A thread making such an answer (the node's stop thread)
marks it ``urgent()``; every other thread pauses at its next ``give_way()`` until no
answer is urgent, for at most ``LONGEST`` s at a time, so that a lock the urgent thread
needs, held by a paused thread, delays it that long at most, never for good. Every
compiled kernel's call gives way (``kernels.Kernel``): planning, the roadmap's build and
the verification of stops made ahead call kernels every few microseconds to
milliseconds. Nothing else changes: a paused computation goes on where it was.

The operating system is asked the same (``background``): the threads whose work nobody
waits for (the roadmap's load, the stops made ahead) run at a lower scheduling priority,
so that on a busy machine an urgent thread waking up gets a core. Planning does not: a
planning thread at a lower priority took its next request later on a busy machine, and a
burst of requests then found the queue full.
"""

from contextlib import contextmanager
import gc
import os
import threading

LONGEST = 0.02
"""s one ``give_way`` pauses at most."""
BACKGROUND = 5
"""How much lower a ``background`` thread's scheduling priority is (Linux nice levels)."""

_urgent = {}
"""The threads (idents) making an urgent answer now: how many ``urgent`` contexts deep."""
_changed = threading.Condition()
_collecting = [True]
"""Whether the garbage collector was on when urgent work began."""


@contextmanager
def urgent():
    """
    Make the calling thread's work urgent while in the context (nested: the outermost).

    The cyclic garbage collector waits too: it is off while any work is urgent (unless it
    was off before), so that no collection starts in the middle of it.
    """
    ident = threading.get_ident()
    with _changed:
        if not _urgent:
            _collecting[0] = gc.isenabled()
            gc.disable()
        _urgent[ident] = _urgent.get(ident, 0) + 1
    try:
        yield
    finally:
        with _changed:
            _urgent[ident] -= 1
            if not _urgent[ident]:
                del _urgent[ident]
                if not _urgent and _collecting[0]:
                    gc.enable()
                _changed.notify_all()


def urgent_now() -> bool:
    """Return whether any thread's work is urgent now (cheap: for the hottest loops)."""
    return bool(_urgent)


def give_way() -> None:
    """Pause while another thread's work is urgent (``LONGEST`` s at most); else return."""
    if not _urgent or threading.get_ident() in _urgent:
        return
    with _changed:
        _changed.wait_for(lambda: not _urgent or threading.get_ident() in _urgent, LONGEST)


def background() -> None:
    """Lower the calling thread's scheduling priority by ``BACKGROUND`` (where the OS can)."""
    try:
        native = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, native,
                       os.getpriority(os.PRIO_PROCESS, native) + BACKGROUND)
    except (AttributeError, OSError):
        pass  # not Linux, or not allowed: the same work, at the same priority
