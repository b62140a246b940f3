"""Giving way: other threads pause at their kernel calls while one makes an urgent answer."""

import gc
import os
import threading
import time

from wafer_planner_ros import giving_way
from wafer_planner_ros.geometry.predicates import orient
from wafer_planner_ros.giving_way import give_way, urgent


def _turn() -> int:
    """Call a compiled kernel (the left turn of three points: 1)."""
    return orient(0.0, 0.0, 1.0, 0.0, 0.0, 1.0, True)


def _urgent_while(then, order, entered, calls=()):
    """Run ``calls`` inside ``urgent()`` in a thread; append 'answered' when it leaves."""
    def answer():
        with urgent():
            entered.set()
            for call in calls:
                call()
            time.sleep(0.2)  # the other thread reaches its kernel call meanwhile
            order.append('answered')
        then()
    thread = threading.Thread(target=answer)
    thread.start()
    return thread


def test_another_thread_s_kernel_call_waits_until_the_urgent_answer_is_made(monkeypatch):
    monkeypatch.setattr(giving_way, 'LONGEST', 10.0)
    order, entered = [], threading.Event()
    # The urgent thread's own kernel calls and give_way do not wait for it.
    thread = _urgent_while(lambda: None, order, entered, calls=(give_way, _turn))
    entered.wait()
    assert _turn() == 1  # a kernel: it gives way first
    order.append('went on')
    thread.join(timeout=5.0)
    assert not thread.is_alive()
    assert order == ['answered', 'went on']
    assert not giving_way.urgent_now()


def test_a_pause_is_bounded_so_a_lock_held_by_a_paused_thread_never_blocks_for_good(
        monkeypatch):
    monkeypatch.setattr(giving_way, 'LONGEST', 0.01)
    held = threading.Lock()
    order, entered, release = [], threading.Event(), threading.Event()
    with held:
        # The urgent thread needs the lock this (paused) thread holds: it gets it once
        # the pause has run out and this thread lets it go.
        thread = _urgent_while(release.set, order, entered, calls=(held.acquire, held.release))
        entered.wait()
        give_way()
        order.append('paused, went on')
    thread.join(timeout=5.0)
    assert release.is_set() and order == ['paused, went on', 'answered']


def test_a_background_thread_runs_at_a_lower_scheduling_priority():
    seen = {}

    def work():
        native = threading.get_native_id()
        before = os.getpriority(os.PRIO_PROCESS, native)
        giving_way.background()
        seen['change'] = os.getpriority(os.PRIO_PROCESS, native) - before

    thread = threading.Thread(target=work)
    thread.start()
    thread.join()
    # Lowered (up to the lowest priority there is), and only that thread's.
    assert seen['change'] == min(giving_way.BACKGROUND, 19 - os.getpriority(os.PRIO_PROCESS, 0))
    assert seen['change'] > 0 or os.getpriority(os.PRIO_PROCESS, 0) == 19


def test_urgency_lasts_until_the_outermost_urgent_context_ends():
    assert gc.isenabled()
    with urgent():
        with urgent():
            assert giving_way.urgent_now() and not gc.isenabled()
        assert giving_way.urgent_now() and not gc.isenabled()  # the inner one ending does not
    assert not giving_way.urgent_now() and gc.isenabled()
    # The collector stays off after urgent work where it was off before.
    gc.disable()
    try:
        with urgent():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_a_child_process_doing_such_work_is_stopped_while_an_answer_is_urgent():
    import subprocess
    import sys

    class Child:
        def __init__(self):
            self.process = subprocess.Popen([sys.executable, '-c', 'while True: pass'])

        def running(self):
            return self.process

    def state(process) -> str:
        with open(f'/proc/{process.pid}/stat') as stat:
            return stat.read().rsplit(')', 1)[1].split()[0]

    child, ended = Child(), Child()
    ended.process.kill()
    ended.process.wait()  # ended before: nothing is sent to it, nothing fails
    giving_way.pausing(child)
    giving_way.pausing(ended)
    try:
        assert state(child.process) in 'RS'
        with urgent():
            with urgent():  # nested: the outermost continues it
                time.sleep(0.05)
                assert state(child.process) == 'T'  # stopped
            assert state(child.process) == 'T'
        time.sleep(0.05)
        assert state(child.process) in 'RS'  # going on
    finally:
        child.process.kill()
        child.process.wait()
