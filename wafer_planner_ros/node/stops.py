"""
The node's controlled stops: what it published, and stop requests answered at once.

Every trajectory the node publishes under a request id is kept (the last ``KEPT``) with
the planner that made it, so the limit set it keeps; a stop request
(``service.requests.stop_request``) names one of them and a moment, and is answered on a
thread of its own, never behind planning, with the controlled stop (``Planner.stop``): a
trajectory that starts exactly in the published one's state at that moment and comes to
rest on its path. The stop is published like any answer (its trajectory, then its
``~/result``) under the stop request's id, stamped when it starts (the stopped trajectory's
``header.stamp`` plus ``at``: a controller that replaces the rest of a trajectory from a
new one's stamp, as ``joint_trajectory_controller`` does, splices it exactly there), and
kept under that id too: a stop of a stop works. A trajectory not kept is
``UNKNOWN_TRAJECTORY``; a moment outside it ``OUTSIDE_TRAJECTORY``, one where it rests
``AT_REST``. Every stop request gets exactly
one answer, whatever happens. A plan request may start in motion too (``"from":
{"trajectory": ..., "at": ...}``): ``divert`` plans it from a kept trajectory, on the
planning thread like any plan.

Stop requests come in on a subscription of their own (``stop_requests``), which the stop
thread waits on (``serve``): a request is taken, answered, published and recorded by that
one thread (``deliver``: the node's publishing, called from it), never behind the node's
executor. While a kept trajectory runs (its stamp passed, its end not yet: the latest
such), a thread of its own makes its stops ahead of it (``service.prepared_stops``)
whenever no stop request is being answered, within the share of a core
``stops.ahead_share`` allows (0: none), so that a request is answered from one made ahead,
the move followed to it first (at most ``prepared_stops.EVERY`` s where making them fits
the share, a stride of such moments where it does not).
"""

from collections import OrderedDict
from dataclasses import dataclass
import threading
import time
from typing import Callable, Optional, Tuple

from wafer_planner_ros import giving_way
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.node import messages
from wafer_planner_ros.node.faults import reason_of
from wafer_planner_ros.node.messages import Sent
from wafer_planner_ros.service.prepared_stops import EVERY, PreparedStops
from wafer_planner_ros.service.requests import Request
from wafer_planner_ros.service.stop_maker import StopMaker

KEPT = 256
"""Published trajectories kept for stop requests (the oldest forgotten first)."""
WAIT = 0.05
"""s the stop thread waits for a request at a time (it ends within that once stopped)."""


class Stops:
    """The kept trajectories, the stop-answering thread and the one making stops ahead."""

    def __init__(self, serve: Callable[[float], bool], deliver: Callable,
                 answer_error: Callable, answer_internal: Callable, logger, clock: Callable,
                 share: Callable[[], float]):
        """
        Start the threads.

        ``serve(timeout)`` waits up to ``timeout`` s for a stop request and takes it in the
        calling thread, the stop thread (its callback calls ``answer``); False: no more
        will come (``StopRequests.serve``). ``deliver(kind, message, number)`` publishes an
        answer at once, in the calling thread, then records it; ``answer_error`` and
        ``answer_internal`` are the worker's (one answer per query, counted there);
        ``clock()`` is the node's time now, as the stamps are (``sec``, ``nanosec``);
        ``share()`` the share of a core making stops ahead may take now (0: none made).
        """
        self._serve, self._deliver = serve, deliver
        self._logger, self._clock, self._share = logger, clock, share
        self._answer_error, self._answer_internal = answer_error, answer_internal
        self._lock = threading.Condition()
        self._kept = OrderedDict()
        """request id -> (planner, result, roadmap) of the trajectories published."""
        self._answering = False
        self._prepared: Optional[Tuple[str, PreparedStops]] = None
        """The running trajectory's id and its stops made ahead."""
        self._stopping = False
        self._finders = StopMaker()
        """The process finding the stops made ahead (started at the first)."""
        self._threads = [threading.Thread(target=target, name=name, daemon=True)
                         for name, target in (('wafer_planner_stop', self._work),
                                              ('wafer_planner_stop_ahead', self._prepare))]
        for thread in self._threads:
            thread.start()

    def keep(self, request_id: str, planner, result, roadmap, stamp) -> None:
        """
        Keep a published answer for stop requests (an answer without an id is not).

        ``stamp``: its ``header.stamp``, when it starts (a stop of it starts ``at`` later).
        """
        if not request_id:
            return
        with self._lock:
            self._kept.pop(request_id, None)
            self._kept[request_id] = (planner, result, roadmap, stamp)
            while len(self._kept) > KEPT:
                self._kept.popitem(last=False)
            self._lock.notify_all()  # a new trajectory to make stops ahead of

    def divert(self, service, request, deadline: float) -> tuple:
        """
        Return (answer, stamp) of a plan request whose start is in motion (``Moving``).

        The move leaves the kept trajectory it names at its moment, planned by ``service``
        as any request it answers (``PlanningService.divert``: within its budget, the one
        curve from the moving state sought only until shortly before the robot passes that
        moment); stamped when it starts, as a stop is.
        Raise PlanningError: ``UNKNOWN_TRAJECTORY`` for a trajectory not kept,
        ``INVALID_REQUEST`` for another load than the trajectory's, else as
        ``Planner.divert`` does.
        """
        moving = request.start
        with self._lock:
            kept = self._kept.get(moving.trajectory)
        if kept is None:
            raise PlanningError(ErrorCode.UNKNOWN_TRAJECTORY,
                                f'no trajectory {moving.trajectory!r} published by this node '
                                f'(it keeps the last {KEPT})')
        result, stamp = kept[1], kept[3]
        if request.load != result.load:
            # The wafer is on the blade or not: that does not change in motion.
            raise PlanningError(ErrorCode.INVALID_REQUEST,
                                f'{moving.trajectory!r} moves {result.load}: a move left in '
                                f'motion keeps its load, not {request.load}')
        starts = later(stamp, moving.at)
        # The robot passes the moment at its stamp (the node's clock: the system's).
        leaves = time.monotonic() + starts.sec + 1e-9 * starts.nanosec - time.time()
        return service.divert(result.trajectory, moving.at, request.goal, moving.trajectory,
                              deadline, request.load, leaves), starts

    def answer(self, number: int, request, received: float) -> None:
        """
        Answer stop request ``number`` in this thread: once, whatever happens.

        ``request``: a ``service.requests.StopRequest``, received at ``received``
        (``time.monotonic()``); called by ``serve``'s callback.
        """
        with self._lock:
            kept = self._kept.get(request.trajectory)
            prepared = self._prepared
            self._answering = True  # the stops made ahead wait
        try:
            ahead = None
            try:
                share = self._share()
                # Made ahead of this very trajectory (an id published again names the last).
                if prepared is not None and kept is not None and share > 0.0 and \
                        prepared[1].trajectory is kept[1].trajectory:
                    ahead = prepared[1].ahead_of(request.at, share)
            except Exception as exc:  # noqa: B902 - then found for the moment itself
                self._logger.error(f'stops made ahead not used: {reason_of(exc)}')
            self._answer(number, request, received, kept, ahead)
        finally:
            with self._lock:
                self._answering = False
                self._lock.notify_all()

    def stop(self) -> None:
        """Have the threads end once idle."""
        with self._lock:
            self._stopping = True
            self._lock.notify_all()

    def join(self, timeout: float) -> None:
        """Wait up to ``timeout`` seconds for the threads, then end the finding process."""
        end = time.monotonic() + timeout
        for thread in self._threads:
            thread.join(max(0.0, end - time.monotonic()))
        self._finders.close()

    def _work(self) -> None:
        """Take and answer the stop requests (``serve``) until stopped."""
        while not self._stopping:
            try:
                if not self._serve(WAIT):
                    return
            except Exception as exc:  # noqa: B902 - the thread outlives any one request
                self._logger.error(f'stop thread: {reason_of(exc)}')

    def _prepare(self) -> None:
        """Make the running trajectory's stops ahead of it, while no request is answered."""
        giving_way.background()
        while True:
            with self._lock:
                while self._answering:
                    if self._stopping:
                        return
                    self._lock.wait()
                if self._stopping:
                    return
                share = self._share()
                running = self._running() if share > 0.0 else None
                if running is None:
                    self._prepared = None
                else:
                    planner, result = self._kept[running[0]][:2]
                    if self._prepared is None or \
                            self._prepared[1].trajectory is not result.trajectory:
                        self._prepared = (running[0], PreparedStops(
                            result.trajectory, _maker(self._finders, planner, result)))
                prepared = self._prepared
                index = None
                if prepared is not None:
                    prepared[1].forget_before(running[1])
                    index = prepared[1].wanted(running[1], share)
                if index is None:
                    self._lock.wait(EVERY)
                    continue
            try:
                prepared[1].make(index)
            except Exception as exc:  # noqa: B902 - the thread outlives any one stop
                self._logger.error(f'stops ahead of {prepared[0]}: {reason_of(exc)}; none '
                                   'made ahead of it any more')
                prepared[1].give_up()

    def _running(self) -> Optional[Tuple[str, float]]:
        """Return (id, seconds along) of the latest kept trajectory running now, or None."""
        now = _seconds(self._clock())
        for request_id in reversed(self._kept):
            result, stamp = self._kept[request_id][1], self._kept[request_id][3]
            elapsed = now - _seconds(stamp)
            if 0.0 <= elapsed < result.trajectory.duration:
                return request_id, elapsed
        return None

    def _answer(self, number: int, request, received: float, kept, ahead) -> None:
        """
        Answer one stop request (its one answer, whatever happens).

        ``ahead``: its stop made ahead (``PreparedStops.ahead_of``), or None.
        """
        label = f'{request.trajectory} at {request.at:.6g} s'
        if kept is None:
            self._answer_error(number, request.request_id, ErrorCode.UNKNOWN_TRAJECTORY,
                               f'no trajectory {request.trajectory!r} published by this node '
                               f'(it keeps the last {KEPT})', label, 'rest')
            return
        planner, result, roadmap, stamp = kept
        begun = time.monotonic()
        try:
            stopped = planner.stop(result.trajectory, request.at, request.trajectory,
                                   result.load, result.verification, ahead)
        except PlanningError as exc:
            self._answer_error(number, request.request_id, exc.code, exc.message, label,
                               'rest', (time.monotonic() - begun) * 1e3, roadmap)
            return
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            self._answer_internal(number, request.request_id, exc, 'stopping', label, 'rest',
                                  (time.monotonic() - begun) * 1e3, roadmap)
            return
        try:
            # Stamped when it starts: ``at`` after the trajectory it stops (a controller
            # replaces the rest of that one from there).
            starts = later(stamp, request.at)
            answer = messages.plan_answer(
                stopped, Request(request.request_id, label, 'rest'), roadmap,
                planner.cell.robot.joint_names, starts, (time.monotonic() - received) * 1e3)
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            self._answer_internal(number, request.request_id, exc, 'answering', label, 'rest',
                                  None, roadmap)
            return
        self._deliver(Sent.ANSWER, answer, number)
        self.keep(request.request_id, planner, stopped, roadmap, starts)


def _maker(finders: StopMaker, planner, result) -> Callable:
    """
    Return how the stops of a kept answer are made ahead: under its limit set, verified.

    Found by ``finders``' process, verified here.
    """
    if not result.verification.proven:
        return lambda moment: None  # none to follow its path from: each found when asked
    planner = planner.for_load(result.load)
    find = finders.finder(result.trajectory, planner.cell.robot)
    return lambda moment: planner.prepare_stop(result.trajectory, moment, result.verification,
                                               made=find(moment))


def _seconds(stamp) -> float:
    """Return a ROS time (anything with ``sec`` and ``nanosec``) in seconds."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def later(stamp, seconds: float) -> 'Stamp':
    """Return a ROS time (anything with ``sec`` and ``nanosec``) ``seconds`` later."""
    total = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec) + round(seconds * 1e9)
    return Stamp(total // 1_000_000_000, total % 1_000_000_000)


@dataclass(frozen=True)
class Stamp:
    """A ROS time: whole seconds and nanoseconds."""

    sec: int
    nanosec: int
