"""
The sweep: every variant of a study file, each planned once, into its results.

Variants already in the results are not planned again (a resumed study does the missing
ones). Once every variant has its row, the file is rewritten in the study's order, so a
study stopped and resumed leaves the same file as one run without a stop (rows differ only
in ``cost``).
"""

from dataclasses import dataclass
from typing import Callable

from wafer_planner_ros import __version__
from wafer_planner_ros.study.report import best_table
from wafer_planner_ros.study.runner import run_variants
from wafer_planner_ros.study.spec import cell_key, Study


@dataclass(frozen=True)
class Outcome:
    """What a study run printed and whether it went well."""

    text: str
    ok: bool
    """False when a variant failed (its worker died or it raised, twice)."""


def about(study: Study) -> dict:
    """Return what ``DIR/study.json`` says of ``study``."""
    return {'name': study.name, 'signature': study.signature, 'version': __version__,
            'base_variant': cell_key(study.base),
            'study_file': str(study.path) if study.path else '',
            'study_text': study.path.read_text() if study.path else '',
            'base_file': str(study.base_path), 'base_text': study.base_text,
            'nodes': study.nodes, 'seed': study.seed, 'method': study.method,
            'parameters': parameter_names(study)}


def parameter_names(study: Study) -> list:
    """Return the names of the parameters the study varies, in the order the file gives."""
    names = [name for name, _ in study.grid]
    for item in study.listed:
        names += list(item)
    names += [name for name, _ in study.ranges]
    return list(dict.fromkeys(names))


def sweep(study: Study, executor, results, say: Callable[[str], None]) -> Outcome:
    """Plan every variant of ``study`` not yet in ``results``; return the summary."""
    variants = study.variants()
    held = sum(v.key in results.rows for v in variants)
    say(f'{study.name}: {len(variants)} variants, {held} already in {results.directory}')
    run_variants(study, variants, executor, results, progress=say)
    places = {v.key: v.index for v in variants}
    results.sort(lambda row: (places.get(row['variant'], len(places)),))
    rows = [results.rows[v.key] for v in variants]
    return Outcome(best_table(about(study), rows), all(r['status'] != 'failed' for r in rows))
