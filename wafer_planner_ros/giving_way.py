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
"""

from contextlib import contextmanager
import threading

LONGEST = 0.02
"""s one ``give_way`` pauses at most."""

_urgent = set()
"""The threads (idents) making an urgent answer now."""
_changed = threading.Condition()


@contextmanager
def urgent():
    """Make the calling thread's work urgent while in the context: the others give way."""
    ident = threading.get_ident()
    with _changed:
        _urgent.add(ident)
    try:
        yield
    finally:
        with _changed:
            _urgent.discard(ident)
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
