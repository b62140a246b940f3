"""
The node's parameters: names, defaults, ranges, meaning, and validation.

ROS-free: the node declares its parameters from ``PARAMETERS`` and turns their values into
one frozen ``NodeSettings`` with ``settings_from``; a bad value raises ``ValueError`` naming
the parameter, both at start-up and when a parameter is set at run time.
"""

from dataclasses import dataclass
import math
from pathlib import Path
import re
from typing import Any, Mapping, NamedTuple, Optional, Tuple

from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.planner import SAMPLE_PERIOD_RANGE
from wafer_planner_ros.roadmap.cache import DEFAULT_CACHE_DIR
from wafer_planner_ros.roadmap.graph import MAX_NODES, MAX_SEED
from wafer_planner_ros.service.prepared_stops import SHARE


class Parameter(NamedTuple):
    """One declared parameter."""

    name: str
    default: Any
    description: str
    low: Optional[float] = None
    high: Optional[float] = None


NODE_NAME = re.compile(r'/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*')
"""A node's name, in a namespace or not (``live.robot``)."""
MIB = 1 << 20
MIN_BAG_SIZE = MIB
"""Bytes: room for what every file begins with (the compressed roadmap markers, mostly)."""
MAX_BAG_SIZE = 1 << 50
MIN_BAG_DURATION = 1.0
MAX_BAG_DURATION = 10 * 365 * 86400.0

PARAMETERS: Tuple[Parameter, ...] = (
    Parameter('cell_file', '',
              'cell YAML file (see doc/cell-format.md); empty: the packaged '
              'config/efem_default.yaml'),
    Parameter('roadmap.nodes', 1500, 'sampled roadmap nodes', 10, MAX_NODES),
    Parameter('roadmap.seed', 0, 'roadmap random seed', 0, MAX_SEED),
    Parameter('roadmap.cache_dir', str(DEFAULT_CACHE_DIR),
              'roadmap cache directory; empty disables the cache'),
    Parameter('trajectory.sample_period', 0.01,
              'seconds between the published trajectory points (the breaks of the curve '
              'and its end are added)',
              *SAMPLE_PERIOD_RANGE),
    Parameter('planning.timeout', 2.0,
              'seconds from receipt after which a request is answered TIMEOUT', 0.01, 600.0),
    Parameter('planning.station_table', True,
              'plan every loadport-loadlock pair with the whole-curve optimisation once the '
              'roadmap is loaded (kept in the cache directory) and answer them from it'),
    Parameter('planning.station_table_ports', True,
              'then also the same pairs empty, and inside one port to inside the other '
              'loaded and empty (the port moves take minutes each to plan, once: the table '
              'is stored as each is planned, and a restart goes on from there)'),
    Parameter('planning.optimise_budget', 0.12,
              'seconds the whole-curve optimisation may spend on a request the station table '
              'does not hold (the best proven curve by then is returned; with none proven '
              "yet, it runs on to its first, up to half-way to the request's deadline); 0: "
              'the corridor curve only', 0.0, 600.0),
    Parameter('planning.max_queue', 32,
              'requests waiting to be planned; more are answered BUSY', 1, 10000),
    Parameter('stops.ahead_share', SHARE,
              "share of a core spent making a running trajectory's controlled stops ahead of "
              'it, so that a stop request is answered without finding one (it follows the '
              'move to the moment made first, at most 20 ms where making them fits the '
              'share, more where it does not); 0: off', 0.0, 1.0),
    Parameter('recording.enabled', True, 'record every query to MCAP'),
    Parameter('recording.directory', '~/.ros/wafer_planner/recordings',
              'where the recordings are written'),
    Parameter('recording.max_bag_size', 100 * MIB,
              'bytes a recording file may take before the next file is started (a query is '
              f'never split across files); 0: no split by size, else at least {MIN_BAG_SIZE}',
              0, MAX_BAG_SIZE),
    Parameter('recording.max_bag_duration', 86400.0,
              'seconds after which a recording file takes no more queries (the next one is '
              f'started); 0: no split by time, else at least {MIN_BAG_DURATION:g}',
              0.0, MAX_BAG_DURATION),
    Parameter('recording.keep', 100,
              'recording files (of every recording of this node in recording.directory) '
              'kept, the oldest removed first, never the one being written; 0: all',
              0, 1000000),
    Parameter('markers.frame_id', 'efem', 'frame of the published markers'),
    Parameter('live.port', 0,
              'TCP port of the Foxglove WebSocket live view (needs foxglove-sdk and '
              'websockets); 0: off',
              0, 65535),
    Parameter('live.host', '127.0.0.1',
              'address the live view listens on (127.0.0.1: this machine only; another, e.g. '
              '0.0.0.0 for every interface, is logged as a warning: the view has no '
              'authentication)'),
    Parameter('live.max_clients', 4,
              'clients the live view serves at once; one more is refused', 1, 64),
    Parameter('live.robot', '/wafer_sim',
              'the robot node whose arm markers and wafer acceleration the live view shows, '
              'beside /joint_states (the simulated arm by default); empty: /joint_states '
              'alone'),
)

_BY_NAME = {p.name: p for p in PARAMETERS}


@dataclass(frozen=True)
class NodeSettings:
    """Validated parameter values."""

    cell_file: Path
    nodes: int
    seed: int
    cache_dir: Optional[Path]
    """None: the cache is disabled."""
    sample_period: float
    timeout: float
    station_table: bool
    station_table_ports: bool
    """The station table also holds the empty moves and the moves through the ports."""
    optimise_budget: float
    max_queue: int
    recording_enabled: bool
    recording_directory: Path
    recording_max_bag_size: int
    """Bytes; 0: no split by size."""
    recording_max_bag_duration: float
    """Seconds; 0: no split by time."""
    recording_keep: int
    """Files kept; 0: all."""
    frame_id: str
    live_port: int
    """TCP port of the Foxglove live view; 0: off."""
    live_host: str
    live_max_clients: int
    """Clients the live view serves at once."""
    live_robot: str = '/wafer_sim'
    """The robot node the live view shows (``node.live_robot``), absolute; '': none."""
    stops_ahead_share: float = SHARE
    """The share of a core making stops ahead may take (``prepared_stops``); 0: off."""


def check(name: str, value) -> None:
    """Raise ValueError naming ``name`` when ``value`` is unusable for it."""
    spec = _BY_NAME.get(name)
    if spec is None:
        raise ValueError(f'{name} is not a parameter of this node')
    expected = type(spec.default)
    if expected is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if type(value) is not expected:
        raise ValueError(f'{name} must be a {expected.__name__}, got {value!r}')
    if expected is float and not math.isfinite(value):
        raise ValueError(f'{name} must be finite, got {value!r}')
    if spec.low is not None and not spec.low <= value <= spec.high:
        raise ValueError(f'{name} must be in [{spec.low}, {spec.high}], got {value!r}')
    if name in ('markers.frame_id', 'recording.directory', 'live.host') and not value.strip():
        raise ValueError(f'{name} must not be empty')
    if name == 'live.robot' and value.strip() and not NODE_NAME.fullmatch(value.strip()):
        raise ValueError(f'{name} must be a node name such as /wafer_sim (letters, digits '
                         'and _, in parts that do not start with a digit), got '
                         f'{value!r}')
    if name == 'recording.max_bag_size' and 0 < value < MIN_BAG_SIZE:
        raise ValueError(f'{name} must be 0 (no split) or at least {MIN_BAG_SIZE}, '
                         f'got {value!r}')
    if name == 'recording.max_bag_duration' and 0 < value < MIN_BAG_DURATION:
        raise ValueError(f'{name} must be 0 (no split) or at least {MIN_BAG_DURATION}, '
                         f'got {value!r}')


def settings_from(values: Mapping[str, Any]) -> NodeSettings:
    """Return the settings for parameter values (missing ones take their defaults)."""
    merged = {p.name: p.default for p in PARAMETERS}
    merged.update(values)
    for name, value in merged.items():
        check(name, value)
    cache = merged['roadmap.cache_dir'].strip()
    return NodeSettings(
        cell_file=Path(merged['cell_file']).expanduser() if merged['cell_file'].strip()
        else default_cell_path(),
        nodes=merged['roadmap.nodes'], seed=merged['roadmap.seed'],
        cache_dir=Path(cache).expanduser() if cache else None,
        sample_period=float(merged['trajectory.sample_period']),
        timeout=float(merged['planning.timeout']),
        station_table=merged['planning.station_table'],
        station_table_ports=merged['planning.station_table_ports'],
        optimise_budget=float(merged['planning.optimise_budget']),
        max_queue=merged['planning.max_queue'],
        recording_enabled=merged['recording.enabled'],
        recording_directory=Path(merged['recording.directory']).expanduser(),
        recording_max_bag_size=merged['recording.max_bag_size'],
        recording_max_bag_duration=float(merged['recording.max_bag_duration']),
        recording_keep=merged['recording.keep'],
        frame_id=merged['markers.frame_id'],
        live_port=merged['live.port'], live_host=merged['live.host'].strip(),
        live_max_clients=merged['live.max_clients'],
        live_robot=_absolute(merged['live.robot'].strip()),
        stops_ahead_share=float(merged['stops.ahead_share']))


def _absolute(name: str) -> str:
    """Return a node name with its leading slash ('' stays '')."""
    return name if not name or name.startswith('/') else f'/{name}'
