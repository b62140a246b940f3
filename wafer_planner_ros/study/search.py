"""
The search: an Optuna (TPE) study over ``study.ranges``, minimising the swap cycle per wafer.

Trials are asked in batches of ``BATCH`` (whatever the number of workers), each batch by a
TPE sampler seeded with ``study.random.seed`` and the batch's number and told every trial
before it, then run on the executor like a sweep's variants. So the trials are a function
of the study file alone: a search stopped and started again asks the same trials, finds
those already in the results (rows are keyed by their cell) and runs only the others. A
variant that is invalid or not planned in full is a failed trial to the sampler. The base
cell is planned first, to compare with.
"""

from typing import Callable

from wafer_planner_ros.study.evaluate import PLANNED
from wafer_planner_ros.study.report import best_table, planned
from wafer_planner_ros.study.runner import run_variants
from wafer_planner_ros.study.spec import Study, StudyError
from wafer_planner_ros.study.sweep import about, Outcome

BATCH = 8
"""Trials asked at once (the same on any executor: the trials do not depend on it)."""


def search(study: Study, trials: int, executor, results, say: Callable[[str], None]) -> Outcome:
    """Run the search's ``trials`` trials (and the base cell); return the summary."""
    if not study.ranges:
        raise StudyError('--search needs study.ranges: the [low, high] of each parameter '
                         'searched')
    import optuna
    from optuna.distributions import FloatDistribution
    from optuna.trial import create_trial, TrialState
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    distributions = {name: FloatDistribution(low, high) for name, (low, high) in study.ranges}
    base = study.variant({}, 0)
    run_variants(study, [base], executor, results, progress=say)
    told, variants = [], [base]
    while len(told) < trials:
        batch = len(told) // BATCH
        sampler = optuna.samplers.TPESampler(seed=study.sample_seed * 1_000_003 + batch)
        tpe = optuna.create_study(direction='minimize', sampler=sampler)
        for params, row in told:
            ok = row.get('status') == PLANNED
            tpe.add_trial(create_trial(params=params, distributions=distributions,
                                       value=row['swap_cycle'] if ok else None,
                                       state=TrialState.COMPLETE if ok else TrialState.FAIL))
        asked = [tpe.ask(distributions).params for _ in range(min(BATCH, trials - len(told)))]
        chosen = [study.variant(params, len(told) + n + 1) for n, params in enumerate(asked)]
        say(f'search: trials {len(told) + 1}-{len(told) + len(chosen)} of {trials}')
        run_variants(study, chosen, executor, results, progress=say,
                     tags={v.key: {'trial': v.index} for v in chosen})
        told += [(params, results.rows[v.key]) for params, v in zip(asked, chosen)]
        variants += chosen
    places = {}
    for variant in variants:
        places.setdefault(variant.key, variant.index)
    results.sort(lambda row: (places.get(row['variant'], len(variants) + 1),))
    rows = [results.rows[key] for key in places]
    text = best_table(about(study), rows)
    best, reference = (planned(rows) or [None])[0], results.rows[base.key]
    if best is not None and reference.get('status') == PLANNED:
        text += (f"\nsearch: the best of {trials} trials, {best['variant']}, takes "
                 f"{best['swap_cycle']:.3f} s per wafer against the base cell's "
                 f"{reference['swap_cycle']:.3f} s "
                 f"({best['swap_cycle'] / reference['swap_cycle']:.3f} x; "
                 f"{best['wafers_per_hour']:.0f} against "
                 f"{reference['wafers_per_hour']:.0f} wafers per hour of motion)")
    return Outcome(text, all(r['status'] != 'failed' for r in rows))
