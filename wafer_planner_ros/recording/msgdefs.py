"""
Message definitions as rosbag2 stores them: ``ros2msg`` schema text and the type hash.

rosbag2 writes, for each type, its ``.msg`` text, then for every type it depends on (depth
first, each once) a line of 80 ``=``, a line ``MSG: pkg/Type`` and that type's text. The
text and the ``RIHS01_`` hash come from the message packages' ``share/<pkg>/msg`` folders
(found on ``AMENT_PREFIX_PATH``, else under this Python's prefix, where the PyPI wheels put
them), so this needs neither rclpy nor a sourced ROS installation.
"""

import functools
import json
import os
from pathlib import Path
import sys
from typing import List, Tuple

from wafer_planner_ros.errors import WaferPlannerError

SEPARATOR = '=' * 80
PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))


def _prefixes() -> List[Path]:
    paths = [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return paths + [Path(sys.prefix)]


def _split(type_name: str) -> Tuple[str, str]:
    """Return (package, Type) of ``pkg/Type`` or ``pkg/msg/Type``."""
    parts = type_name.split('/')
    if len(parts) == 3 and parts[1] == 'msg':
        return parts[0], parts[2]
    if len(parts) != 2:
        raise WaferPlannerError(f'not a message type name: {type_name!r}')
    return parts[0], parts[1]


@functools.lru_cache(maxsize=None)
def _file(package: str, name: str, suffix: str) -> str:
    for prefix in _prefixes():
        path = prefix / 'share' / package / 'msg' / f'{name}{suffix}'
        if path.is_file():
            return path.read_text()
    raise WaferPlannerError(
        f'no definition of {package}/msg/{name} ({suffix}) under share/{package}/msg in '
        + ', '.join(str(p) for p in _prefixes()))


def dependencies(package: str, text: str) -> List[str]:
    """Return the ``pkg/Type`` of every non-primitive field of a ``.msg`` text, in order."""
    found = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        words = line.split()
        if len(words) < 2 or '=' in words[1]:
            continue  # a constant (``int32 ADD=0``) or not a field
        base = words[0].split('[', 1)[0].split('<=', 1)[0]
        if base in PRIMITIVES:
            continue
        if '/' in base:
            found.append('/'.join(_split(base)))
        elif base == 'Header':
            found.append('std_msgs/Header')
        else:
            found.append(f'{package}/{base}')
    return found


@functools.lru_cache(maxsize=None)
def definition(type_name: str) -> str:
    """Return the full ``ros2msg`` definition of ``type_name`` (``pkg/msg/Type``)."""
    package, name = _split(type_name)
    text = _file(package, name, '.msg')
    parts, seen = [text.rstrip('\n')], {f'{package}/{name}'}

    def visit(pkg: str, body: str) -> None:
        for dependency in dependencies(pkg, body):
            if dependency in seen:
                continue
            seen.add(dependency)
            dep_pkg, dep_name = _split(dependency)
            dep_text = _file(dep_pkg, dep_name, '.msg')
            parts.append(f'{SEPARATOR}\nMSG: {dependency}\n{dep_text.rstrip(chr(10))}')
            visit(dep_pkg, dep_text)
    visit(package, text)
    return '\n'.join(parts) + '\n'


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """Return the ``RIHS01_...`` hash of ``type_name`` from its type description file."""
    package, name = _split(type_name)
    description = json.loads(_file(package, name, '.json'))
    full = f'{package}/msg/{name}'
    for entry in description.get('type_hashes', []):
        if entry.get('type_name') == full:
            return entry['hash_string']
    raise WaferPlannerError(f'share/{package}/msg/{name}.json has no hash for {full}')
