"""
What the kernels' build ahead of time is keyed by: the machine, and each call's argument types.

A build ahead of time (``kernels_ahead``) is one extension module (``AHEAD_MODULE``) with a
manifest beside it (``AHEAD_MANIFEST``) that says which built function is which kernel for
which argument types. Built code trusts that its arguments are exactly of the types it was
built for, so a call runs it only when ``argument_types`` of its arguments is one of those
(``kernels.Kernel``); and a build runs only on the Python, numpy and numba it was built with,
on the same processor (``ahead_identity``: the build's directory is named by it). What it
was built from, the kernels' code and the constants it uses, is checked on load
(``kernels_lookup.kernels_digest``, from ``global_names`` and ``file_digest``).

Nothing here imports numba: reading the build's keys must not cost numba's import.
"""

import hashlib
import importlib.util
import json
from pathlib import Path
import platform
import sys
import types
from typing import Optional

import numpy as np

AHEAD_MODULE = 'wafer_planner_ros_kernels'
"""The name of the extension module built ahead of time (its ``PyInit_`` function's)."""
AHEAD_MANIFEST = 'manifest.json'
"""The file beside it that says which function is which kernel for which argument types."""

SCALARS = {float: 'float64', np.float64: 'float64', int: 'int64', np.int64: 'int64',
           bool: 'bool', np.bool_: 'bool', complex: 'complex128', np.complex128: 'complex128'}
"""An argument's Python type -> the numba type a kernel is built for."""


def argument_types(args: tuple) -> Optional[tuple]:
    """
    Return the types of ``args`` as the build names them, None when one has no such type.

    An array is ``(dtype, ndim, layout, readonly, aligned)`` as numba types it (layout 'C',
    'F' or 'A' from numpy's flags): the built code trusts that its arguments are exactly
    of the types it was built for, so a call matches only on all of these.
    """
    found = []
    for value in args:
        kind = SCALARS.get(type(value))
        if kind is None:
            if type(value) is not np.ndarray:
                return None
            flags = value.flags
            layout = 'C' if flags.c_contiguous else 'F' if flags.f_contiguous else 'A'
            kind = (value.dtype.str, value.ndim, layout, not flags.writeable, flags.aligned)
        found.append(kind)
    return tuple(found)


def ahead_identity() -> dict:
    """
    Return what a build ahead of time is valid for, and ``key``: a digest of all of it.

    The Python, numpy and numba (its build's version file) that run it and the processor
    (model and instruction-set flags: the code is built for this one). The kernels' own
    code is checked on load (``kernels_digest``).
    """
    facts = {'python': sys.version, 'machine': platform.machine(), 'numpy': np.__version__,
             'numba': file_digest(_numba_version_file()), 'cpu': _processor()}
    facts['key'] = hashlib.sha256(json.dumps(facts, sort_keys=True).encode()).hexdigest()[:20]
    return facts


def hashable(value):
    """Return JSON's lists as tuples, all the way down."""
    return tuple(hashable(v) for v in value) if isinstance(value, list) else value


def _numba_version_file() -> Optional[Path]:
    """Return numba's version file (its release and build), found without importing it."""
    spec = importlib.util.find_spec('numba')
    return None if spec is None or not spec.origin else Path(spec.origin).parent / '_version.py'


def file_digest(path: Optional[Path]) -> str:
    """Return a digest of the file's bytes ('' when there is none)."""
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()[:20] if path else ''
    except OSError:
        return ''


def _processor() -> str:
    """Return the processor's model and flags (Linux), else what ``platform`` says."""
    try:
        with open('/proc/cpuinfo') as info:
            first = info.read().split('\n\n', 1)[0]
    except OSError:
        return platform.processor()
    wanted = [line.split(':', 1)[1].strip() for line in first.splitlines()
              if line.split(':', 1)[0].strip() in ('vendor_id', 'model name', 'flags',
                                                   'Features', 'CPU part')]
    return hashlib.sha256('\n'.join(wanted).encode()).hexdigest()[:20]


def global_names(code: types.CodeType) -> set:
    """Return the global names a function's code uses, its nested functions' included."""
    found = set(code.co_names)
    for constant in code.co_consts:
        if isinstance(constant, types.CodeType):
            found |= global_names(constant)
    return found
