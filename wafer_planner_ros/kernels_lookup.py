"""
Finding and loading this machine's build of the kernels ahead of time, without numba.

``wafer-kernels`` builds every kernel it can into one extension module for this machine
(``kernels_ahead``), kept beside numba's cache (:func:`ahead_directory`). :func:`load_ahead`
loads it and hands each kernel its built functions (``kernels.Kernel.use_built``). The
build is used only by the Python, numpy and numba it was built with, on the same processor
(``kernels_keys.ahead_identity``), and only while the kernels' code is what it was built
from (:func:`kernels_digest`): anything else finds no build (:class:`NoBuildAhead`), and
the kernels are numba's.
"""

import hashlib
import importlib
import importlib.util
import json
from pathlib import Path
from typing import Optional

import numpy as np

from wafer_planner_ros.kernels import cache_root, registered
from wafer_planner_ros.kernels_keys import ahead_identity, AHEAD_MANIFEST, AHEAD_MODULE
from wafer_planner_ros.kernels_keys import file_digest, global_names, hashable


def ahead_root() -> Path:
    """Return where the builds ahead of time are kept: beside numba's cache."""
    return cache_root() / 'ahead-of-time'


class NoBuildAhead(Exception):
    """There is no build ahead of time for this machine and these kernels (it says why)."""


def ahead_directory(identity: Optional[dict] = None) -> Path:
    """Return where the build for this machine is (built or not)."""
    return ahead_root() / (identity or ahead_identity())['key']


def kernels_digest(modules) -> str:
    """
    Return a digest of the kernels of ``modules`` (imported): what a build of them compiled.

    Each kernel's name and options, the source file of its module and the values of the
    constants it uses (a kernel's compiled code holds the values they had): any change to a
    kernel, or to a kernel it calls, changes it.
    """
    wanted = set(modules)
    digest, sources = hashlib.sha256(), {}
    for k in sorted(registered(), key=lambda k: (k.__module__, k.__qualname__)):
        if k.__module__ not in wanted:
            continue
        path = k.function.__code__.co_filename
        if path not in sources:
            sources[path] = file_digest(Path(path))
        digest.update(f'{k.__module__}:{k.__qualname__}:{sources[path]}:'
                      f'{sorted(k.options.items())}'.encode())
        for name in sorted(global_names(k.function.__code__)):
            value = k.function.__globals__.get(name)
            if isinstance(value, np.ndarray):
                digest.update(f'{name}={value.dtype.str}{value.shape}'.encode() + value.tobytes())
            elif isinstance(value, (bool, int, float, complex, str, tuple)):
                digest.update(f'{name}={value!r}'.encode())
    return digest.hexdigest()[:20]


def ahead_manifest() -> dict:
    """
    Return the manifest of this machine's build, its kernels checked; raise if there is none.

    The kernel modules it lists are imported first. Raises :class:`NoBuildAhead` when
    nothing was built for this machine (its Python, numpy, numba and processor) or the
    kernels changed since, ``OSError`` when the manifest cannot be read.
    """
    return _checked_manifest(ahead_directory())


def _checked_manifest(directory: Path) -> dict:
    """Return the manifest in ``directory``, its kernels checked (``ahead_manifest``)."""
    path = directory / AHEAD_MANIFEST
    try:
        manifest = json.loads(path.read_text())
        modules = manifest['modules']
    except FileNotFoundError:
        raise NoBuildAhead(f'none built for this machine in {ahead_root()}') from None
    except (ValueError, KeyError, TypeError) as exc:
        raise OSError(f'{path} is not a build manifest: {exc!r}') from exc
    try:
        for name in modules:
            importlib.import_module(name)
    except ImportError as exc:
        raise NoBuildAhead(f'the build in {directory} is of kernels this package no longer '
                           f'has ({exc})') from exc
    if kernels_digest(modules) != manifest.get('digest'):
        raise NoBuildAhead(f'the kernels changed since the build in {directory}')
    return manifest


def load_ahead() -> int:
    """
    Load this machine's build of the kernels; return how many signatures it has.

    Numba is not imported. Raises :class:`NoBuildAhead` when there is no build for this
    machine and these kernels, ``OSError`` or ``ImportError`` when a build is there but
    cannot be read or loaded: the kernels are then numba's.
    """
    directory = ahead_directory()
    manifest = _checked_manifest(directory)
    spec = importlib.util.spec_from_file_location(AHEAD_MODULE, directory / manifest['file'])
    if spec is None:
        raise ImportError(f'{directory / manifest["file"]} cannot be loaded')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    by_name = {f'{k.__module__}:{k.__qualname__}': k for k in registered()}
    tables = {}
    for name, built in manifest['kernels'].items():
        if name not in by_name:
            raise ImportError(f'{directory} builds {name}, which is not a kernel')
        tables[name] = {hashable(types_): getattr(module, symbol) for types_, symbol in built}
    for name, table in tables.items():
        by_name[name].use_built(table)
    return sum(len(table) for table in tables.values())


def ahead_count() -> int:
    """Return how many kernel signatures this process runs as built ahead of time."""
    return sum(k.ahead() for k in registered())
