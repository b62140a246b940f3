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

Child processes doing such work (``pausing``: the node's planning process) are stopped
while an answer is urgent (``SIGSTOP``, continued by ``SIGCONT`` as the last urgent answer
is made): a child left running keeps a core of a two-core machine from the answer's
threads and the middleware's, where the kernels' pauses keep only the lock from them. A
stopped child goes on where it was, a few milliseconds later.

The operating system is asked the same (``background``): the threads whose work nobody
waits for (the roadmap's load, the stops made ahead) run at a lower scheduling priority,
so that on a busy machine an urgent thread waking up gets a core. Planning does not: a
planning thread at a lower priority took its next request later on a busy machine, and a
burst of requests then found the queue full.
"""

from contextlib import contextmanager
import gc
import os
import signal
import threading
import weakref

LONGEST = 0.02
"""s one ``give_way`` pauses at most."""
BACKGROUND = 5
"""How much lower a ``background`` thread's scheduling priority is (Linux nice levels)."""

_urgent = {}
"""The threads (idents) making an urgent answer now: how many ``urgent`` contexts deep."""
_changed = threading.Condition()
_collecting = [True]
"""Whether the garbage collector was on when urgent work began."""
_pausing = weakref.WeakSet()
"""The child processes stopped while any work is urgent (``pausing``)."""
_paused = []
"""The processes stopped by the urgent work under way (continued when it ends)."""


def pausing(child) -> None:
    """
    Stop ``child`` while any work is urgent, from now on for as long as it lives.

    ``child``: an object whose ``running()`` returns its running ``subprocess.Popen``, or
    None while none runs.
    """
    with _changed:
        _pausing.add(child)


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
            _signal(list(filter(None, (child.running() for child in _pausing))),
                    signal.SIGSTOP, _paused)
        _urgent[ident] = _urgent.get(ident, 0) + 1
    try:
        yield
    finally:
        with _changed:
            _urgent[ident] -= 1
            if not _urgent[ident]:
                del _urgent[ident]
                if not _urgent:
                    if _collecting[0]:
                        gc.enable()
                    paused, _paused[:] = list(_paused), []
                    _signal(paused, signal.SIGCONT, [])
                _changed.notify_all()


def _signal(processes, number: int, sent: list) -> None:
    """Send signal ``number`` to each running process of ``processes``; list them in ``sent``."""
    for process in processes:
        try:
            process.send_signal(number)  # nothing once it has ended (and been waited for)
            sent.append(process)
        except OSError:
            pass  # ended meanwhile


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
