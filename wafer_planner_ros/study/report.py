"""
A study's report: its best variants as a table, and three figures.

- ``heatmap.png``: the swap cycle per wafer over two parameters (each square the best
  variant with those two values; random samples drawn as points);
- ``pareto.png``: the swap cycle against the footprint, the Pareto front (no variant both
  faster and smaller) joined;
- ``best.png``: the best variant's cell with its fastest swap cycle (planned again: a
  variant's motions are a function of its cell and the study's settings).
"""

import functools
import math
from pathlib import Path
from typing import Callable, List, Optional, Sequence

import numpy as np

from wafer_planner_ros.study.evaluate import FAILED, INCOMPLETE, INVALID, PLANNED

FIGURES = 'figures'


def planned(rows: Sequence[dict]) -> List[dict]:
    """Return the rows planned in full, fastest swap cycle first."""
    return sorted((r for r in rows if r.get('status') == PLANNED),
                  key=lambda r: (r['swap_cycle'], r['index']))


def parameter_value(about: dict, row: dict, name: str) -> float:
    """Return a row's value of ``name`` (the base cell's when the row leaves it out)."""
    if name in row.get('parameters', {}):
        return float(row['parameters'][name])
    from wafer_planner_ros.study import parameters
    return parameters.value(_base_cell(about['base_text'], about['base_file']), name)


@functools.lru_cache(maxsize=4)
def _base_cell(text: str, file: str):
    """Return the study's base cell, read once per report (not once per row)."""
    from wafer_planner_ros.cell.document import read_cell_yaml
    return read_cell_yaml(text, file)


def best_table(about: dict, rows: Sequence[dict], count: int = 10) -> str:
    """
    Return the summary and the ``count`` fastest variants, against the base cell.

    Then the first ``count`` invalid or failed variants with their reasons.
    """
    statuses = [r.get('status') for r in rows]
    lines = [f"study {about['name']}: {len(rows)} variants: "
             + ', '.join(f'{statuses.count(s)} {s}' for s in (PLANNED, INCOMPLETE, INVALID,
                                                              FAILED))]
    base = next((r for r in rows if r['variant'] == about.get('base_variant')), None)
    reference = base['swap_cycle'] if base and base.get('status') == PLANNED else None
    if base is not None:
        lines.append(f'base cell: {_cycle_text(base)}')
    best = planned(rows)[:count]
    if not best:
        lines.append('no variant was planned in full')
        return '\n'.join(lines)
    lines.append(f"{'#':>3} {'variant':<17}{'s/wafer':>8}{'wafers/h':>9}{'vs base':>8}"
                 f"{'m²':>6}{'clear mm':>9}  parameters")
    for rank, row in enumerate(best, 1):
        ratio = '-' if reference is None else f"{row['swap_cycle'] / reference:.3f}"
        values = ', '.join(f'{k}={_short(v)}' for k, v in row['parameters'].items()) \
            or '(the base cell)'
        lines.append(f"{rank:>3} {row['variant']:<17}{row['swap_cycle']:>8.3f}"
                     f"{row['wafers_per_hour']:>9.0f}{ratio:>8}{row['footprint']:>6.2f}"
                     f"{row['min_clearance'] * 1e3:>9.1f}  {values}")
    refused = [row for row in rows if row.get('status') in (INVALID, FAILED)]
    for row in refused[:count]:
        lines.append(f"{row['status']}: {row['variant']} "
                     f"({', '.join(f'{k}={_short(v)}' for k, v in row['parameters'].items())}"
                     f"): {row.get('reason', '')}")
    if len(refused) > count:
        lines.append(f'... and {len(refused) - count} more invalid or failed (results.jsonl '
                     'has every reason)')
    return '\n'.join(lines)


def write_figures(about: dict, rows: Sequence[dict], directory, axes: Optional[Sequence[str]],
                  say: Callable[[str], None] = lambda text: None) -> List[Path]:
    """Write the report's figures into ``directory/figures``; return their paths."""
    out = Path(directory).expanduser() / FIGURES
    out.mkdir(parents=True, exist_ok=True)
    done = planned(rows)
    written = []
    names = list(axes) if axes else [
        n for n in about.get('parameters', [])
        if len({parameter_value(about, r, n) for r in done}) > 1]
    if axes and any(n not in about.get('parameters', []) for n in axes):
        raise ValueError(f"--axes: the study varies {', '.join(about.get('parameters', []))}"
                         f", not {' and '.join(axes)}")
    if len(names) >= 2 and done:
        written.append(_heatmap(about, done, names[:2], out / 'heatmap.png'))
    else:
        say('no heat map: fewer than two parameters take more than one value among the '
            'variants planned in full')
    if done:
        written.append(_pareto(about, done, out / 'pareto.png'))
        written.append(_best(about, done[0], out / 'best.png'))
    return written


def pareto_front(rows: Sequence[dict]) -> List[dict]:
    """Return the rows no other row beats on both swap cycle and footprint, smallest first."""
    front, fastest = [], math.inf
    for row in sorted(rows, key=lambda r: (r['footprint'], r['swap_cycle'])):
        if row['swap_cycle'] < fastest:
            front.append(row)
            fastest = row['swap_cycle']
    return front


def _heatmap(about: dict, rows: Sequence[dict], names: Sequence[str], path: Path) -> Path:
    from matplotlib.figure import Figure
    x = np.array([parameter_value(about, r, names[0]) for r in rows])
    y = np.array([parameter_value(about, r, names[1]) for r in rows])
    z = np.array([r['swap_cycle'] for r in rows])
    xs, ys = np.unique(x), np.unique(y)
    figure = Figure(figsize=(7, 5.5))
    ax = figure.subplots()
    if len(xs) * len(ys) <= 4 * len(rows):  # a grid: one square per pair of values
        grid = np.full((len(ys), len(xs)), np.nan)
        for xi, yi, zi in zip(np.searchsorted(xs, x), np.searchsorted(ys, y), z):
            grid[yi, xi] = zi if np.isnan(grid[yi, xi]) else min(grid[yi, xi], zi)
        image = ax.imshow(grid, origin='lower', aspect='auto', cmap='viridis_r',
                          extent=_extent(xs) + _extent(ys))
        for yi, xi in zip(*np.nonzero(~np.isnan(grid))):
            ax.text(xs[xi], ys[yi], f'{grid[yi, xi]:.2f}', ha='center', va='center',
                    fontsize=8, color='white')
    else:
        image = ax.scatter(x, y, c=z, cmap='viridis_r', s=30)
    figure.colorbar(image, ax=ax, label='swap cycle (s of motion per wafer)')
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.set_title(f"{about['name']}: swap cycle per wafer (best of the variants at each point)",
                 fontsize=10)
    figure.savefig(path, dpi=100, bbox_inches='tight')
    return path


def _extent(values: np.ndarray) -> list:
    step = np.min(np.diff(values)) if len(values) > 1 else max(abs(values[0]) * 0.1, 0.01)
    return [values[0] - step / 2, values[-1] + step / 2]


def _pareto(about: dict, rows: Sequence[dict], path: Path) -> Path:
    from matplotlib.figure import Figure
    figure = Figure(figsize=(7, 5))
    ax = figure.subplots()
    ax.scatter([r['footprint'] for r in rows], [r['swap_cycle'] for r in rows], s=18,
               color='tab:blue', alpha=0.6, label='variants planned in full')
    front = pareto_front(rows)
    ax.step([r['footprint'] for r in front], [r['swap_cycle'] for r in front], where='post',
            color='tab:red', marker='o', label='Pareto front')
    base = next((r for r in rows if r['variant'] == about.get('base_variant')), None)
    if base is not None:
        ax.scatter([base['footprint']], [base['swap_cycle']], marker='*', s=160,
                   color='black', label='base cell', zorder=3)
    ax.set_xlabel('footprint (m², the bounding box of the enclosure)')
    ax.set_ylabel('swap cycle (s of motion per wafer)')
    ax.legend()
    figure.savefig(path, dpi=100, bbox_inches='tight')
    return path


def _best(about: dict, row: dict, path: Path) -> Path:
    from wafer_planner_ros.cell.document import read_cell_yaml
    from wafer_planner_ros.cell.model import Cell
    from wafer_planner_ros.planner import Planner, PlannerSettings
    from wafer_planner_ros.plotting import plot_cycle
    from wafer_planner_ros.roadmap.builder import build_roadmap
    from wafer_planner_ros.roadmap.graph import RoadmapSettings
    from wafer_planner_ros.service.cycle import swap_cycle
    from wafer_planner_ros.study import parameters
    document = parameters.apply(read_cell_yaml(about['base_text'], about['base_file']),
                                row['parameters'])
    cell = Cell.from_dict(document, source=f"variant {row['variant']}")
    roadmap = build_roadmap(cell, RoadmapSettings(nodes=about['nodes']), about['seed'])
    planner = Planner(cell, roadmap, PlannerSettings(method=about['method']))
    fastest = min((s for s in row['swaps'] if s['cycle'] is not None),
                  key=lambda s: s['cycle'])
    plot_cycle(cell, swap_cycle(planner, fastest['loadport'], fastest['loadlock']), path)
    return path


def _cycle_text(row: dict) -> str:
    if row.get('status') != PLANNED:
        return f"{row.get('status')}: {row.get('reason', '')}"
    return (f"{row['swap_cycle']:.3f} s of motion per wafer (mean over its "
            f"{len(row['swaps'])} loadport/loadlock pairs), {row['wafers_per_hour']:.0f} "
            f"wafers/h; fastest pair {row['best_swap_cycle']:.3f} s")


def _short(value) -> str:
    return f'{value:.4g}' if isinstance(value, float) else str(value)
