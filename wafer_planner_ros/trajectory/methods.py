"""
Ways to shape and time a curve through a safe corridor.

The planner gives a method the corridor of every elbow-branch combination and asks for a
``Draft`` (cheap: its ``estimate`` orders the combinations), then finishes the drafts most
promising first, telling each the cycle time it need not beat. A method returns a curve
(any ``Trajectory``) with its own figures; the planner verifies it. Methods are named by
``PlannerSettings.method``; ``METHODS`` lists them.
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar, Mapping, Optional, Tuple

from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.corridor import Corridor
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem
from wafer_planner_ros.trajectory.tuning import TimingSettings


@dataclass(frozen=True, eq=False)
class Draft:
    """A method's starting point for one corridor."""

    estimate: float
    """s: the cycle time of the starting point (what finishing it improves on)."""
    work: object
    """The method's own state, handed back to ``finish``."""


@dataclass(frozen=True, eq=False)
class Shaped:
    """A finished curve, not yet verified."""

    trajectory: Trajectory
    initial_cycle_time: float
    """s: the cycle time the method started from."""
    metrics: Mapping = field(default_factory=dict)
    """The method's own figures (solver iterations and the like)."""
    warnings: Tuple[str, ...] = ()


class CurveMethod(ABC):
    """A way to shape and time a curve through a corridor for one cell's robot."""

    name: ClassVar[str]

    def __init__(self, cell, settings: TimingSettings):
        """Keep the cell and the optimiser's tuning."""
        self.cell = cell
        self.settings = settings

    @abstractmethod
    def draft(self, corridor: Corridor) -> Draft:
        """Return the starting point for a corridor."""

    @abstractmethod
    def finish(self, draft: Draft, give_up_above: Optional[float] = None) -> Optional[Shaped]:
        """Return the finished curve; None once it shows it cannot beat ``give_up_above`` s."""


class KnotTiming(CurveMethod):
    """
    The paper's timing (sections 4.3 and 5).

    The corridor's control points stay where they are; the span durations are optimised
    from the λ-scaled uniform timing (Eq. 12).
    """

    name = 'knot-timing'

    def draft(self, corridor: Corridor) -> Draft:
        """Return the λ-scaled uniform timing of the corridor's control points."""
        problem = TimingProblem(corridor.control_points, self.cell.robot, self.settings)
        start = scaled_start(problem)
        return Draft(float(start[0].sum()), (problem, start))

    def finish(self, draft: Draft, give_up_above: Optional[float] = None) -> Optional[Shaped]:
        """Return the spline with optimised span durations (``timing.optimise``)."""
        problem, start = draft.work
        timing = optimise(problem, start, give_up_above)
        if timing is None:
            return None
        warnings = () if timing.optimised else (
            f'time optimisation failed ({timing.message}); returning the λ-scaled timing',)
        metrics = {'lambda': timing.scale, 'optimised': timing.optimised,
                   'solver_iterations': timing.iterations,
                   'constraint_rounds': timing.rounds, 'wafer_samples': timing.samples}
        return Shaped(CubicBSpline.from_intervals(problem.points, timing.intervals),
                      draft.estimate, metrics, warnings)


METHODS = {method.name: method for method in (KnotTiming,)}
"""The methods by name."""
