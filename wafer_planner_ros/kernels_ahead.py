"""
The kernels built ahead of time: one extension module for this machine, loaded without numba.

Loading numba and the kernels from its cache takes long at every start; the module this
builds loads far sooner, without numba (``kernels_lookup.load_ahead``). :func:`build` takes
every signature the process has of each kernel (compiled or loaded from numba's cache: after
``service.warmup.compile_kernels``, those the planner calls) and compiles them with numba's
ahead-of-time compiler (``numba.pycc``) for this processor into
``kernels_lookup.ahead_directory()``, with a manifest of which function is which kernel for which
argument types (``kernels_keys.argument_types``). It needs a C compiler.

Left to numba: the kernels that reach ``objmode`` (the exact orientation test's slow path
for coordinates out of its fast range, so every polygon check): numba's ahead-of-time
compiler cannot build them. They are checked interpreted when small, and loaded from
numba's cache otherwise. Signatures of literal or omitted arguments are left out too: a
call fills in its defaults (``Kernel.__call__``), and literals arise only inside compiled
code. A kernel made with ``nogil=True`` releases the interpreter's lock in its built form
too (numba's compiler takes one set of options for a whole module: set here per kernel).

The build is written into a temporary directory beside its place and renamed into it (the
previous build, of older kernels, renamed away first), so that a reader sees a whole build
or none.
"""

import contextlib
import json
import os
from pathlib import Path
import shutil
import tempfile
import time
from typing import Callable, Dict, List, Optional, Tuple
import warnings

from wafer_planner_ros import kernels, kernels_keys, kernels_lookup


def buildable(every: List[kernels.Kernel]) -> Tuple[List[kernels.Kernel], List[kernels.Kernel]]:
    """Split the kernels into those numba's ahead-of-time compiler builds and the rest."""
    reaching: Dict[int, bool] = {}

    def reaches_objmode(k: kernels.Kernel) -> bool:
        if id(k) not in reaching:
            reaching[id(k)] = False  # a cycle does not reach it by itself
            called = [k.function.__globals__.get(name) for name in kernels_keys.global_names(
                k.function.__code__)]
            reaching[id(k)] = any(v is kernels.objmode for v in called) or any(
                reaches_objmode(v) for v in called if isinstance(v, kernels.Kernel))
        return reaching[id(k)]

    left = [k for k in every if reaches_objmode(k)]
    return [k for k in every if not reaches_objmode(k)], left


def unlisted(manifest: dict) -> List[str]:
    """
    Return the modules of the package's buildable kernels a build's manifest does not list.

    A module of kernels added since that build (its kernels would compile at their first
    use): the manifest's own check covers only the modules it lists.
    """
    ours = [k for k in kernels.registered()
            if k.__module__.split('.')[0] == kernels.__name__.split('.')[0]]
    return sorted({k.__module__ for k in buildable(ours)[0]} - set(manifest['modules']))


def _argument_type(numba_type) -> Optional[object]:
    """Return ``kernels_keys.argument_types``'s name of a numba type; None for other types."""
    from numba.core import types
    from numba.np import numpy_support
    if isinstance(numba_type, types.Array):
        return [numpy_support.as_dtype(numba_type.dtype).str, numba_type.ndim,
                numba_type.layout, not numba_type.mutable, numba_type.aligned]
    if isinstance(numba_type, types.Literal) or isinstance(numba_type, types.Omitted):
        return None
    name = str(numba_type)
    return name if name in set(kernels_keys.SCALARS.values()) else None


@contextlib.contextmanager
def _released_gil(functions: set):
    """Compile ``functions`` (by id) with ``release_gil`` while the body runs."""
    from numba.pycc import compiler
    original = compiler.compile_extra

    def compile_extra(typing_context, target_context, function, args, return_type, flags,
                      **options):
        if id(function) in functions:
            flags = flags.copy()
            flags.release_gil = True
        return original(typing_context, target_context, function, args, return_type, flags,
                        **options)

    compiler.compile_extra = compile_extra
    try:
        yield
    finally:
        compiler.compile_extra = original


def build(progress: Optional[Callable[[str], None]] = None) -> dict:
    """
    Build every signature this process has of the package's kernels ahead of time.

    Returns ``directory``, ``signatures`` (built), ``kernels`` (built), ``left``
    (kernels left to numba, by name), ``seconds`` and ``built`` (False when the build
    was there already). Raises ``RuntimeError`` when numba's compiler fails (no C
    compiler, for one): the kernels are then numba's, as before.
    """
    say = progress or (lambda step: None)
    begun = time.monotonic()
    ours = [k for k in kernels.registered()
            if k.__module__.split('.')[0] == kernels.__name__.split('.')[0]]
    modules = sorted({k.__module__ for k in ours})
    identity = kernels_keys.ahead_identity()
    directory = kernels_lookup.ahead_directory(identity)
    built, left = buildable(ours)
    found = {'directory': str(directory), 'left': [k.__qualname__ for k in left]}
    try:
        manifest = kernels_lookup.ahead_manifest()
    except (kernels_lookup.NoBuildAhead, OSError):
        manifest = None
    if manifest is not None and unlisted(manifest):
        manifest = None  # kernels added since: built again, with them
    if manifest is not None:
        return {**found, 'built': False, 'seconds': time.monotonic() - begun,
                'kernels': len(manifest['kernels']),
                'signatures': sum(len(v) for v in manifest['kernels'].values())}
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # numba's notice that pycc will change
        try:
            from numba.pycc import CC
        except ImportError as exc:  # a numba without its ahead-of-time compiler
            raise RuntimeError(f'the ahead-of-time build failed: {exc}') from exc
    compiler = CC(kernels_keys.AHEAD_MODULE, source_module=kernels)
    compiler.target_cpu = 'host'
    compiler.verbose = False
    table: Dict[str, list] = {}
    released = set()
    for index, k in enumerate(built):
        dispatcher = k.compiled
        for number, result in enumerate(dispatcher.overloads.values()):
            named = [_argument_type(t) for t in result.signature.args]
            if any(t is None for t in named):
                continue
            symbol = f'k{index}_{number}'
            compiler.export(symbol, result.signature)(dispatcher.py_func)
            table.setdefault(f'{k.__module__}:{k.__qualname__}', []).append([named, symbol])
            if k.options.get('nogil'):
                released.add(id(dispatcher.py_func))
    signatures = sum(len(v) for v in table.values())
    say(f'building {signatures} signatures of {len(table)} kernels ahead of time for this '
        'processor (about 30 s)')
    directory.parent.mkdir(parents=True, exist_ok=True)
    _remove_abandoned(directory.parent)
    staging = Path(tempfile.mkdtemp(prefix='.building-', dir=directory.parent))
    try:
        compiler.output_dir = str(staging)
        try:
            with _released_gil(released), warnings.catch_warnings():
                warnings.simplefilter('ignore')
                compiler.compile()
        except Exception as exc:  # noqa: B902 - numba's, the C compiler's: said as one
            raise RuntimeError(f'the ahead-of-time build failed: {exc}') from exc
        manifest = {'file': compiler.output_file, 'modules': modules,
                    'digest': kernels_lookup.kernels_digest(modules), 'kernels': table,
                    'left_to_numba': found['left'], 'identity': identity}
        (staging / kernels_keys.AHEAD_MANIFEST).write_text(json.dumps(manifest, indent=1))
        _install(staging, directory)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return {**found, 'built': True, 'seconds': time.monotonic() - begun,
            'kernels': len(table), 'signatures': signatures}


def _install(staging: Path, directory: Path) -> None:
    """Put the build in ``staging`` in place of ``directory``'s (renames: whole or none)."""
    previous = None
    if directory.exists():
        previous = Path(tempfile.mkdtemp(prefix='.previous-', dir=directory.parent))
        os.replace(directory, previous)  # onto the empty directory just made
    try:
        os.rename(staging, directory)
    except OSError:
        if not (directory / kernels_keys.AHEAD_MANIFEST).exists():
            raise  # not another build's, done meanwhile
    finally:
        if previous is not None:
            shutil.rmtree(previous, ignore_errors=True)


ABANDONED_AFTER = 3600.0
"""s after which a build's temporary directory is taken as abandoned (its build killed)."""


def _remove_abandoned(root: Path) -> None:
    """Remove the temporary directories of builds killed before they ended."""
    for left in [*root.glob('.building-*'), *root.glob('.previous-*')]:
        try:
            if time.time() - left.stat().st_mtime > ABANDONED_AFTER:
                shutil.rmtree(left, ignore_errors=True)
        except OSError:
            continue  # removed meanwhile
