"""The time optimiser's tuning: one frozen set of values, the defaults measured to pay."""

from dataclasses import dataclass

from wafer_planner_ros.trajectory.sqp import QP_ITERATIONS


@dataclass(frozen=True)
class TimingSettings:
    """How the knot intervals are optimised (``trajectory.timing``)."""

    margin: float = 0.999
    """Limits are tightened by this factor inside the optimiser, so that what lies between
    dense samples stays below the true limits that verification applies."""
    min_interval: float = 1e-3
    """s: the shortest span when the cell limits jerk (Eq. 10 read as a small positive lower
    bound; the jerk control points keep spans from collapsing)."""
    min_interval_without_jerk: float = 0.02
    """s: the shortest span when the cell does not limit jerk. Spans of 1 ms let the
    acceleration step within 1 ms (11,800 rad/s^3 measured); at 20 ms a step of the whole
    acceleration range takes 20 ms or more."""

    def shortest(self, robot) -> float:
        """Return the shortest span (s) for ``robot``: with or without a jerk limit."""
        return self.min_interval if robot.limits.jerk is not None \
            else self.min_interval_without_jerk
    dense_step: float = 1e-3
    """s: the step of the dense check of every answer."""
    limit_tries: int = 8
    """Checks on the verification's own times at most in slowing a timing until it meets
    every limit (``TimingProblem.meet_limits``); one slowing is almost always enough."""
    max_rounds: int = 4
    """Solves with added samples at most (8 gave cycles at most 0.55 % shorter on 108
    problems, at 1.4 x the time)."""
    samples_per_span: int = 1
    """Wafer-acceleration samples per span in the first round (1: the paper's, every knot)."""
    rescale_tolerance: float = 1e-3
    """Samples stop being added once Eq. 12 would slow the answer by less than this."""
    ftol: float = 1e-5
    """s: SLSQP's stopping precision on the total time."""
    give_up_margin: float = 0.02
    """A round's optimum this much above the best so far gives the problem up. More samples
    only add constraints, so a round's optimum is about a lower bound of the final one: on
    the 3 test cells' station pairs it was at most 0.4 % above it."""
    active: float = 1.0 - 0.7 ** 2
    """Control-point constraints at 70 % of their limit or more are kept in the solver."""
    max_iterations: int = 200
    """SLSQP iterations per round at most."""


@dataclass(frozen=True)
class ShapeSettings:
    """How the whole curve is optimised (``trajectory.shape``)."""

    min_spans: int = 16
    """Knots are inserted (halving the longest spans) until the start curve has this many
    spans: a straight two-vertex path has only four, too few to shape."""
    coarse_spans: int = 8
    """Spans of the coarse stage (``coarse``), whose optimum starts the fine one; a path
    with more vertices gets one span per vertex (``methods.WholeCurve``). Over the
    98 elbow-branch combinations of the 3 test cells' station pairs (roadmap seed 1, none
    given up), the two stages took 17 s in all where one stage from the corridor curve
    took 73 s, for the same fastest curve per pair within rounding (cycle time ratio:
    median 1.000, worst 1.003)."""
    qp_iterations: int = QP_ITERATIONS
    """daqp iterations per subproblem at most (``sqp``)."""
    coarse_give_up: float = 1.15
    """A coarse optimum this many times the best cycle time so far gives the combination up
    (``give_up_above``, plus ``TimingSettings.give_up_margin``: 1.173 x, after a converged
    round). On those 98 combinations the coarse stage, stopped at its first proven curve,
    ended at most 1.166 x the best cycle time of its pair for the combination that won
    (median 1.12 x its own fine optimum, at most 1.43 x): a close margin."""
    wafer_samples: int = 3
    """Wafer-acceleration samples per span in the first round."""
    clearance_samples: int = 4
    """Clearance samples per span in the first round."""
    clearance: float = 0.002
    """m: what every body keeps from the walls at the samples (the proof then covers the
    curve between them)."""
    port_kept: float = 0.25
    """The share of a port's lateral tolerance its margins keep at the samples (the proof
    then covers the curve between them; ``geometry.ports``)."""
    port_keep_out: float = 0.02
    """m: the rows keep the wafer centre this far from the mouth of every port the curve
    neither leaves nor enters, where it is turned from that port's heading (a disc round
    the tip of the port's wedge, ``geometry.ports``; the proof keeps the rule itself). On
    the notched test cell an empty move from loadport1 into loadlock1 sweeps past
    loadlock2's mouth with its blade turned; without the disc its optimum sat on the
    wedge's tip, a corner the optimiser cut between its samples round after round. Where
    the start already comes that near a mouth, turned, the coarse stage is also tried
    under the rule alone (``methods.WholeCurve.finish``); within a time budget the rule
    alone is kept throughout."""
    watch: float = 0.05
    """m: bodies this near a wall at a sample have their clearance constrained there."""
    max_rounds: int = 6
    """Solves at most, each after adding samples where the last answer fell short."""
    max_iterations: int = 100
    """SLSQP iterations per solve at most."""
    ftol: float = 1e-4
    """s: SLSQP's stopping precision on the total time."""
    budget_ftol: float = 1e-3
    """s: the same within a time budget. On 60 random joint requests of the default cell it
    took the median planning time from 284 ms to 186 ms for a median cycle time 0.24 %
    longer; with a 0.12 s budget the median answer then came within 0.7 % of the
    unbudgeted one (within 5 % at 1e-4). Unbudgeted work (the station table) keeps
    ``ftol``."""
