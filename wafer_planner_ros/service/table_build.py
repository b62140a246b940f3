"""
The build order of a station table: which pairs are planned, and how each is had.

A pair whose reverse is already planned gets that trajectory backwards in time
(``Trajectory.backwards``, ``table_entry.reversed_entry``), verified again: every limit,
the clearance and the proof are the same for a motion and its reverse, so planning both
directions would take twice as long for the same cycle time. Any other pair is planned;
given the table of another limit set (a ``donor``: the loaded moves' for the empty ones),
its curve of the pair is taken instead when it is faster and passes this planner's
verification (``adoption.faster``). A pair that cannot be planned is recorded with the
reason, and never planned again in that table (``missing``).
"""

from typing import Callable, Optional, Sequence, Tuple

from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.service.adoption import faster
from wafer_planner_ros.service.table_entry import plan_entry, reversed_entry


def plan_pairs(planner: Planner, pairs: Sequence[Tuple[str, str]], entries: dict,
               verified: dict, failures: dict,
               progress: Optional[Callable[[int, int, str], None]] = None,
               donor=None) -> None:
    """
    Plan ``pairs`` in order into ``entries``, ``verified`` and ``failures`` (by pair).

    ``progress(done, total, pair)`` after each pair; ``donor``: a ``StationTable`` of
    another limit set, or None (see the module's description).
    """
    for done, (start, goal) in enumerate(pairs, 1):
        pair = (start, goal)
        try:
            back = entries.get((goal, start))
            if back is None:
                result = planner.plan(start, goal)
                if donor is not None and pair in donor.entries:
                    result = faster(planner, result, donor.answer(planner, start, goal))
                entries[pair], verified[pair] = plan_entry(result), result.verification
            else:
                entries[pair], verified[pair] = reversed_entry(planner, pair, back)
        except PlanningError as exc:
            failures[pair] = f'{exc.code.value}: {exc.message}'
        if progress is not None:
            progress(done, len(pairs), f'{start}->{goal}')


def missing(entries: dict, failures: dict, pairs) -> list:
    """Return the ``pairs`` neither in ``entries`` nor in ``failures``, in order."""
    return [pair for pair in pairs if pair not in failures and pair not in entries]
