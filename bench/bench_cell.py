"""
Benchmark: reading and validating cell files, large and hostile.

- Polygon validity of four valid 5,000-vertex polygons: a comb (a notched wall, many
  collinear edges that do not touch, and collinear points along its base), a star (long
  edges whose bounding boxes overlap a lot), a zig-zag, and the star with one coordinate of
  1e-300 (exact arithmetic in Python for the turns that involve it); ours
  (``simple_polygon``) against GEOS (shapely's ``is_valid``) on the same points, median of
  5 warm runs, and our first call (numba's cache load included).
- A whole cell file (``Cell.from_text``): the default cell, and the default cell whose
  loadlock wall is a 5,000-vertex comb of 1 mm notches.
- Hostile files: a "billion laughs" alias bomb, 50 MB of YAML, a 4 MiB file near the limit.

Prints a table and writes ``bench/results/cell.json``. Usage: ``make bench`` or
``python bench/bench_cell.py [--vertices 5000] [--repeat 5]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import statistics
import sys
import time

import numpy as np
import shapely
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.polygons import simple_polygon

RESULTS = Path(__file__).resolve().parent / 'results' / 'cell.json'


def comb(vertices: int) -> np.ndarray:
    """Return a comb of about ``vertices`` points (a 5 cm grid): teeth up from a base."""
    teeth = (vertices - 2) // 4
    base = vertices - 4 * teeth  # the base's corners and collinear points on it
    xs = np.linspace(2 * teeth - 1, 0, base)
    bottom = np.column_stack([xs[::-1], np.zeros(base)])
    top = []
    for k in reversed(range(teeth)):  # right to left along the top
        x = 2 * k
        top += [(x + 1, 1), (x + 1, 2), (x, 2), (x, 1)]
    return np.vstack([bottom, top]) * 0.05


def star(vertices: int) -> np.ndarray:
    """Return a star of ``vertices`` points alternately 1 m and 0.2 m from the centre."""
    angle = np.linspace(0.0, 2 * np.pi, vertices, endpoint=False)
    radius = np.where(np.arange(vertices) % 2 == 0, 1.0, 0.2)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


def zigzag(vertices: int) -> np.ndarray:
    """Return a zig-zag band: a saw-tooth top over a flat bottom 1 m below."""
    teeth = vertices - 2
    x = np.linspace(0.0, 5.0, teeth)
    y = np.where(np.arange(teeth) % 2 == 0, 1.0, 1.5)
    return np.vstack([[[0.0, 0.0], [5.0, 0.0]], np.column_stack([x, y])[::-1]])


def notched_cell(vertices: int) -> str:
    """Return the default cell's text with its loadlock wall (y = -0.45) a comb of notches."""
    teeth = (vertices - 4) // 4
    x = np.linspace(-0.85, 0.85, 2 * teeth + 2)[1:-1].reshape(-1, 2)
    wall = [(-0.85, -0.45)]
    for a, b in x:  # a 1 mm notch out of the enclosure between a and b
        wall += [(a, -0.45), (a, -0.451), (b, -0.451), (b, -0.45)]
    wall += [(0.85, -0.45), (0.85, 0.45), (-0.85, 0.45)]
    text = default_cell_path().read_text()
    old = '[[-0.85, -0.45], [0.85, -0.45], [0.85, 0.45], [-0.85, 0.45]]'
    assert old in text
    return text.replace(old, json.dumps([[round(u, 6), v] for u, v in wall]))


def _median(function, repeat: int) -> tuple:
    """Return (median seconds, every run) of ``function()`` called ``repeat`` times."""
    runs = []
    for _ in range(repeat):
        started = time.perf_counter()
        function()
        runs.append(time.perf_counter() - started)
    return statistics.median(runs), runs


def _refusal(text) -> tuple:
    """Return (seconds, message length) of reading a file that must be refused."""
    started = time.perf_counter()
    try:
        Cell.from_text(text, 'hostile.yaml')
    except CellError as exc:
        return time.perf_counter() - started, len(str(exc))
    raise AssertionError('the hostile file was accepted')


def main() -> int:
    """Time everything and write the results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--vertices', type=int, default=5000)
    parser.add_argument('--repeat', type=int, default=5)
    args = parser.parse_args()
    polygons = []

    def tiny(vertices):  # one coordinate below 2**-300: its turns take the exact slow path
        points = star(vertices)
        points[0, 1] = 1e-300
        return points

    for name, make in (('comb', comb), ('star', star), ('zigzag', zigzag),
                       ('star, one coordinate 1e-300', tiny)):
        points = make(args.vertices)
        started = time.perf_counter()
        polygon = simple_polygon(points)
        first = time.perf_counter() - started
        ours, _ = _median(lambda: simple_polygon(points), args.repeat)
        geos, _ = _median(lambda: shapely.Polygon(points).is_valid, args.repeat)
        assert shapely.Polygon(points).is_valid and len(polygon.points) == len(points)
        polygons.append({'polygon': name, 'vertices': len(points), 'first_s': first,
                         'ours_s': ours, 'geos_s': geos, 'ours_over_geos': ours / geos})
    default_text = default_cell_path().read_text()
    notched = notched_cell(args.vertices)
    cell = Cell.from_text(notched, 'notched.yaml')
    cells = [{'cell': 'default', 'vertices': 4,
              'seconds': _median(lambda: Cell.from_text(default_text, 'd'), args.repeat)[0]},
             {'cell': 'default with a notched wall', 'vertices': len(cell.boundary),
              'seconds': _median(lambda: Cell.from_text(notched, 'n'), args.repeat)[0]}]
    rows = ['&l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]']
    rows += [f'&l{i} [{", ".join([f"*l{i - 1}"] * 10)}]' for i in range(1, 9)]
    bomb = 'laughs: [' + ', '.join(rows) + ']\n'
    big = 'x: [' + ', '.join(['0.5'] * 12_500_000) + ']\n'
    near = default_text + '# ' + 'c' * (4 * 1024 * 1024 - len(default_text) - 100) + '\n'
    hostile = []
    for name, text in (('alias bomb (10**9 strings)', bomb), ('50 MB of YAML', big)):
        seconds, length = _refusal(text)
        hostile.append({'file': name, 'bytes': len(text), 'refused_s': seconds,
                        'message_chars': length})
    seconds = _median(lambda: Cell.from_text(near, 'near.yaml'), args.repeat)[0]
    hostile.append({'file': '4 MiB cell (comments)', 'bytes': len(near), 'read_s': seconds})
    print(f"{'polygon':28} {'vertices':>8} {'first s':>8} {'ours ms':>8} {'GEOS ms':>8} "
          f"{'ours/GEOS':>9}")
    for r in polygons:
        print(f"{r['polygon']:28} {r['vertices']:>8} {r['first_s']:>8.3f} "
              f"{r['ours_s'] * 1e3:>8.2f} {r['geos_s'] * 1e3:>8.2f} {r['ours_over_geos']:>9.2f}")
    for r in cells:
        print(f"cell {r['cell']} ({r['vertices']} boundary vertices): "
              f"{r['seconds'] * 1e3:.1f} ms")
    for r in hostile:
        what = f"refused in {r['refused_s'] * 1e3:.2f} ms, message {r['message_chars']} " \
            'characters' if 'refused_s' in r else f"read in {r['read_s'] * 1e3:.0f} ms"
        print(f"{r['file']} ({r['bytes']:,} bytes): {what}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': 'cell files: polygon validity against GEOS, whole cells, hostile files',
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform()},
        'repeat': args.repeat, 'polygons': polygons, 'cells': cells, 'hostile': hostile},
        indent=2) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
