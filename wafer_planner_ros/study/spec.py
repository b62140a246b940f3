"""
The study file: a base cell and what varies.

::

    study:
      name: example                  # optional (default: the file's name)
      base: efem_default.yaml        # the cell varied, relative to this file
      roadmap: {nodes: 600, seed: 0} # each variant's roadmap (default: 1500 nodes, seed 0)
      method: whole-curve            # or knot-timing (``wafer-plan --method``)
      grid:                          # every combination of these values
        robot.link_lengths[0]: [0.34, 0.36]
        boundary.width: [1.6, 1.7]
      list:                          # and these variants, as given
        - {robot.link_lengths[0]: 0.40, robot.link_lengths[1]: 0.32}
      random: {samples: 20, seed: 1} # and samples drawn uniformly within ``ranges``
      ranges:                        # [low, high] of each parameter (random, --search)
        robot.link_lengths[0]: [0.30, 0.42]

The variants are the base cell itself, then the grid's (the last parameter varying
fastest), the list's and the random samples', in that order; a variant that repeats an
earlier one's cell is the same variant. ``parameters.py`` names what can vary.
"""

from dataclasses import dataclass
import hashlib
import itertools
import json
from pathlib import Path
import random as random_module
from typing import Dict, Optional, Tuple

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.document import read_cell_file, read_cell_yaml
from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.roadmap.graph import check_seed, RoadmapSettings
from wafer_planner_ros.study import parameters
from wafer_planner_ros.trajectory.methods import METHODS, WholeCurve

KEYS = ('name', 'base', 'roadmap', 'method', 'grid', 'list', 'random', 'ranges')
DEFAULT_METHOD = WholeCurve.name
"""How each variant's motions are made unless the study says: the node's (its station
table and its moves through the ports, non-stop)."""
MAX_VARIANTS = 1_000_000
"""Most variants a study file may describe (a grid multiplies quickly)."""


class StudyError(ValueError):
    """A study file that cannot be run; the message names the key and the value."""


@dataclass(frozen=True)
class Variant:
    """One cell of a study: the parameters that made it from the base cell, and its text."""

    key: str
    """The content hash of its cell (16 hex digits): the row's key in the results."""
    index: int
    """Its place in the study's order (the first place, if it repeats)."""
    values: Dict[str, float]
    """Parameter name -> value (the base cell's values are left out)."""
    document: dict
    """The cell document (plain data, as a cell file holds it)."""


@dataclass(frozen=True)
class Study:
    """A study read from its file."""

    name: str
    path: Optional[Path]
    base_path: Path
    base_text: str
    base: dict
    """The base cell's document."""
    nodes: int
    seed: int
    method: str
    grid: Tuple[Tuple[str, tuple], ...]
    listed: Tuple[Dict[str, float], ...]
    samples: int
    sample_seed: int
    ranges: Tuple[Tuple[str, Tuple[float, float]], ...]

    @classmethod
    def from_file(cls, path) -> 'Study':
        """Read and check a study file; raise StudyError naming the bad key."""
        path = Path(path)
        try:
            data = read_cell_yaml(read_cell_file(path), str(path))
        except CellError as exc:
            raise StudyError(str(exc)) from None
        return cls.from_dict(data, path)

    @classmethod
    def from_dict(cls, data, path: Optional[Path] = None) -> 'Study':
        """Check a parsed study document (``path``: where relative names are found)."""
        top = _mapping(data, '', ('study',))
        study = _mapping(top['study'], 'study', KEYS)
        base_path = _base_path(study.get('base'), path)
        try:
            base_text = read_cell_file(base_path).decode()
            base = read_cell_yaml(base_text, str(base_path))
        except (CellError, OSError, UnicodeDecodeError) as exc:
            raise StudyError(f'study.base: {exc}') from None
        roadmap = _mapping(study.get('roadmap', {}), 'study.roadmap', ('nodes', 'seed'))
        nodes, seed = roadmap.get('nodes', RoadmapSettings.nodes), roadmap.get('seed', 0)
        try:
            RoadmapSettings(nodes=nodes)
        except ValueError as exc:
            raise StudyError(f'study.roadmap.nodes: {exc}') from None
        try:
            check_seed(seed)
        except ValueError as exc:
            raise StudyError(f'study.roadmap.seed: {exc}') from None
        method = study.get('method', DEFAULT_METHOD)
        if method not in METHODS:
            raise StudyError(f'study.method: {method!r} is not one of '
                             f'{", ".join(sorted(METHODS))}')
        grid = tuple((name, tuple(_numbers(values, f'study.grid.{name}', base, name)))
                     for name, values in _mapping(study.get('grid', {}), 'study.grid').items())
        listed = study.get('list', [])
        if not isinstance(listed, list):
            raise StudyError('study.list: must be a list of mappings (parameter: value)')
        listed = tuple({name: _number(v, f'study.list[{i}].{name}', base, name)
                        for name, v in _mapping(item, f'study.list[{i}]').items()}
                       for i, item in enumerate(listed))
        ranges = tuple((name, _range(bounds, f'study.ranges.{name}', base, name))
                       for name, bounds in _mapping(study.get('ranges', {}),
                                                    'study.ranges').items())
        sampling = _mapping(study.get('random', {}), 'study.random', ('samples', 'seed'))
        samples, sample_seed = sampling.get('samples', 0), sampling.get('seed', 0)
        for key, number in (('samples', samples), ('seed', sample_seed)):
            if isinstance(number, bool) or not isinstance(number, int) or number < 0:
                raise StudyError(f'study.random.{key}: must be an integer >= 0, got '
                                 f'{number!r}')
        if samples and not ranges:
            raise StudyError('study.random: samples need study.ranges to draw from')
        count = (len(list(itertools.product(*(v for _, v in grid)))) if grid else 0) \
            + len(listed) + samples
        if count > MAX_VARIANTS:
            raise StudyError(f'the study describes {count:,} variants: at most '
                             f'{MAX_VARIANTS:,}')
        name = study.get('name', path.stem if path is not None else 'study')
        if not isinstance(name, str) or not name.strip():
            raise StudyError(f'study.name: must be a non-empty string, got {name!r}')
        return cls(name, path, base_path, base_text, base, int(nodes), int(seed), method,
                   grid, listed, int(samples), int(sample_seed), ranges)

    @property
    def signature(self) -> str:
        """
        Return the hash of what makes a variant's row (16 hex digits).

        The base cell, the roadmap's settings, the method and the package's version: a
        results directory holds the rows of one signature only.
        """
        text = json.dumps({'base': self.base, 'nodes': self.nodes, 'seed': self.seed,
                           'method': self.method, 'version': __version__}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def variants(self) -> list:
        """Return the study's variants in order, each cell once."""
        chosen = [{}]
        if self.grid:
            names = [name for name, _ in self.grid]
            chosen += [dict(zip(names, combination))
                       for combination in itertools.product(*(v for _, v in self.grid))]
        chosen += [dict(item) for item in self.listed]
        chosen += self.samples_drawn()
        found, variants = set(), []
        for values in chosen:
            variant = self.variant(values, len(variants))
            if variant.key not in found:
                found.add(variant.key)
                variants.append(variant)
        return variants

    def samples_drawn(self) -> list:
        """Return the random samples (the same for the same seed, on any machine)."""
        draw = random_module.Random(self.sample_seed)
        return [{name: draw.uniform(low, high) for name, (low, high) in self.ranges}
                for _ in range(self.samples)]

    def variant(self, values: dict, index: int) -> Variant:
        """Return the variant of the base cell with ``values`` applied."""
        document = parameters.apply(self.base, values)
        return Variant(cell_key(document), index, dict(values), document)


def cell_key(document: dict) -> str:
    """Return the content hash of a cell document (16 hex digits; layout-independent)."""
    text = json.dumps(document, sort_keys=True, separators=(',', ':'))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _mapping(value, path: str, allowed=None) -> dict:
    if not isinstance(value, dict):
        raise StudyError(f'{path or "the study file"}: must be a mapping, got '
                         f'{type(value).__name__}')
    for key in value:
        if allowed is not None and key not in allowed:
            raise StudyError(f'{path + "." if path else ""}{key}: unknown key (expected one '
                             f'of: {", ".join(allowed)})')
    return value


def _base_path(value, path: Optional[Path]) -> Path:
    if value is None:
        return default_cell_path()
    if not isinstance(value, str) or not value.strip():
        raise StudyError(f'study.base: must be a cell file name, got {value!r}')
    base = Path(value).expanduser()
    if not base.is_absolute() and path is not None:
        base = path.parent / base
    if not base.is_file() and not Path(value).is_absolute():
        packaged = default_cell_path().parent / value  # a packaged cell, by name
        if packaged.is_file():
            return packaged
    return base


def _number(value, where: str, base: dict, name: str) -> float:
    try:
        parameters.check(base, name)
    except parameters.ParameterError as exc:
        raise StudyError(f'{where}: {exc}') from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or value != value or value in (float('inf'), float('-inf')):
        raise StudyError(f'{where}: must be a finite number, got {value!r}')
    return float(value)


def _numbers(values, where: str, base: dict, name: str) -> list:
    if not isinstance(values, list) or not values:
        raise StudyError(f'{where}: must be a non-empty list of numbers, got {values!r}')
    return [_number(v, f'{where}[{i}]', base, name) for i, v in enumerate(values)]


def _range(bounds, where: str, base: dict, name: str) -> Tuple[float, float]:
    if not isinstance(bounds, list) or len(bounds) != 2:
        raise StudyError(f'{where}: must be [low, high], got {bounds!r}')
    low, high = (_number(v, f'{where}[{i}]', base, name) for i, v in enumerate(bounds))
    if not low < high:
        raise StudyError(f'{where}: low must be below high, got [{low}, {high}]')
    return low, high
