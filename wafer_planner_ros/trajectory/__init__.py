"""
From a path to a verified timed curve: corridor, B-spline, optimisers, proof, verification.

Where a change belongs: a new kind of limit, one object in ``constraints`` (its rows, its
check, its order in time), with compiled rows in ``rows``; the safe corridor, ``corridor``;
the curve interface everything after the planner uses, ``curve`` (the B-spline:
``bspline``); the knot-time optimiser, ``timing_problem`` and ``timing``; the whole-curve
optimiser, ``shape_problem``, ``coarse`` and ``shape`` on ``sqp``, and its start from a
kept optimum moved to new ends, ``warm``; their settings,
``tuning``; a curve that continues a motion (a divert), ``continuing``, and curves played
in turn, ``chained``; a way to shape and time a curve, chosen by ``PlannerSettings.method``,
``methods``; the collision proof, ``proof``; the dense check every answer passes,
``verify``; where a motion comes closest to a wall, ``approach``; timed parts of a plan,
``stopwatch``.
"""
