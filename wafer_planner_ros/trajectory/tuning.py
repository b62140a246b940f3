"""
The optimisers' tuning: one frozen set of settings each, and why each default is what it is.

``TimingSettings`` tunes the knot-time optimiser (``trajectory.timing``), and the
whole-curve optimiser where it takes the same steps (the margin, the dense check, giving
up); ``ShapeSettings`` tunes the rest of the whole-curve optimiser (``trajectory.shape``).
Each setting says what it does and why its default is the one that pays; the experiments
that chose the defaults, with their figures, are in doc/benchmark.md ("How the optimisers'
defaults were chosen").
"""

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
    """s: the shortest span when the cell does not limit jerk. Then nothing else keeps the
    acceleration from stepping within one span, and spans as short as ``min_interval`` let
    it jump at a jerk no drive gives; with spans this long a step of the whole acceleration
    range takes at least this long."""

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
    """Solves with added samples at most: further rounds shorten the cycle only slightly,
    for much more planning time."""
    samples_per_span: int = 1
    """Wafer-acceleration samples per span in the first round (1: the paper's, every knot)."""
    rescale_tolerance: float = 1e-3
    """Samples stop being added once Eq. 12 would slow the answer by less than this."""
    ftol: float = 1e-5
    """s: SLSQP's stopping precision on the total time."""
    give_up_margin: float = 0.02
    """A round's optimum this much above the best so far gives the problem up. More samples
    only add constraints, so a round's optimum is about a lower bound of the final one: it
    has come out above the final one by far less than this margin, so it stops only
    problems that cannot win."""
    active: float = 1.0 - 0.7 ** 2
    """Control-point constraints at 70 % of their limit or more are kept in the solver; the
    others are left out (an active set) and added back when an answer brings them closer.
    Fewer rows make each subproblem cheaper: the same cycle times as keeping more of them,
    in less time."""
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
    with more vertices gets one span per vertex (``methods.WholeCurve``). Its subproblems
    are small, and its optimum starts the fine stage so near the answer that the two stages
    take far less time than one stage from the corridor curve, for the same fastest curve
    per pair."""
    qp_iterations: int = QP_ITERATIONS
    """daqp iterations per subproblem at most (``sqp``)."""
    coarse_give_up: float = 1.15
    """A coarse optimum this many times the best cycle time so far gives the combination up
    (``give_up_above``, plus ``TimingSettings.give_up_margin`` after a converged round). A
    coarse optimum lies above the fine one it leads to, often well above; the winning
    combinations' coarse stages have stayed just below where they would be given up: a
    close margin, which gives up the hopeless combinations early and no winner."""
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
    the tip of the port's wedge, ``geometry.ports``; the proof keeps the rule itself).
    Without the disc, an optimum that sweeps past a mouth with the blade turned sits on the
    wedge's tip, a corner the optimiser cuts between its samples round after round. Where
    the start already comes that near a mouth, turned, the coarse stage is also tried
    under the rule alone (``methods.WholeCurve.finish``); within a time budget the rule
    alone is kept throughout."""
    watch: float = 0.05
    """m: bodies this near a wall at a sample have their clearance constrained there."""
    max_rounds: int = 6
    """Solves at most, each after adding samples where the last answer fell short."""
    warm_rounds: int = 2
    """Within a time budget, rounds in a row at most that start from the last round's
    optimum where the proof refuted it, with its quasi-Newton matrix (``shape``): a few
    iterations each, where from the last proven curve most of the first round's were taken
    again. Some such chains never prove a curve (the optimum moves from one wall to the
    next); after this many a round starts from the last proven curve, with every sample
    added so far, as each round does without a budget (there, more thorough: a chain
    proved a coarse curve in a slower way round a pillar, where those rounds went on to
    the faster one; doc/benchmark.md)."""
    max_iterations: int = 100
    """SLSQP iterations per solve at most."""
    ftol: float = 1e-4
    """s: SLSQP's stopping precision on the total time."""
    budget_ftol: float = 1e-3
    """s: the same within a time budget. A coarser precision ends each solve sooner, for a
    cycle time only a fraction of a per cent longer: within a budget the time matters more
    than that last fraction. Unbudgeted work (the station table) keeps ``ftol``."""
