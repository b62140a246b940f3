"""
``wafer-kernels``: compile the planning kernels for this machine once, or check they are.

The set-up (``make run``, ``make test``) runs it after an install: every compiled kernel is
compiled and kept in numba's cache (``kernels.cache_root``), then built ahead of time into
one extension module for this processor (``kernels_ahead``, beside that cache), where the
node and every tool find them, so that no start, request or rebuild compiles, and the node
loads them in milliseconds. A second run only checks they are there.
``--check`` compiles nothing: exit 1 when some kernel is not in the cache or the build
ahead of time is missing.
"""

import argparse
import sys
import time

from wafer_planner_ros import kernels, kernels_ahead, kernels_lookup
from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, run
from wafer_planner_ros.service.warmup import compile_kernels


def main(argv=None) -> int:
    """Run wafer-kernels."""
    parser = argparse.ArgumentParser(prog='wafer-kernels', description=__doc__.split('\n')[1])
    parser.add_argument('--check', action='store_true',
                        help='compile nothing; exit 1 when some kernel is not in the cache '
                             'or not built ahead of time for this machine')
    args = parser.parse_args(argv)
    begun = time.monotonic()
    loaded = kernels.load_cached()
    missing = kernels.uncached()
    where = kernels.cache_root()
    try:
        manifest, unbuilt = kernels_lookup.ahead_manifest(), ''
    except (kernels_lookup.NoBuildAhead, OSError) as exc:
        manifest, unbuilt = None, str(exc)
    if manifest is not None:
        # A module of kernels added since the build: its kernels would compile at first use.
        unlisted = kernels_ahead.unlisted(manifest)
        if unlisted:
            manifest, unbuilt = None, f'{", ".join(unlisted)} not built ahead of time'
    if args.check or (not missing and manifest is not None):
        if missing:
            print(f'{len(missing)} of {len(kernels.registered())} planning kernels are not '
                  f'compiled in {where}: ' + ', '.join(k.__qualname__ for k in missing))
            return EXIT_FAILURE
        print(f'planning kernels: {loaded} signatures of {len(kernels.registered())} kernels '
              f'loaded from {where} in {time.monotonic() - begun:.2f} s')
        if manifest is None:
            print(f'planning kernels: not built ahead of time: {unbuilt}')
            return EXIT_FAILURE
        table = manifest['kernels']
        print(f'planning kernels: {sum(len(v) for v in table.values())} signatures of '
              f'{len(table)} kernels built ahead of time in {kernels_lookup.ahead_directory()}')
        return EXIT_OK

    def progress(step: str) -> None:
        print(f'  [{time.monotonic() - begun:5.1f} s] {step}', flush=True)

    if missing:
        print(f'compiling the planning kernels into {where} (once per install, about 40 s '
              'on two cores):', flush=True)
        made = compile_kernels(progress)
        print(f'planning kernels: {made["compiled"]} signatures compiled, '
              f'{made["signatures"]} in all, in {time.monotonic() - begun:.1f} s', flush=True)
        missing = kernels.uncached()
        if missing:
            print('not compiled by the workload: ' + ', '.join(k.__qualname__ for k in missing),
                  file=sys.stderr)
            return EXIT_FAILURE
    else:
        compile_kernels()  # loads them all (every signature the planner calls), compiles none
    try:
        made = kernels_ahead.build(progress)
    except RuntimeError as exc:
        print(f"planning kernels: {exc}; the node loads them from numba's cache instead "
              '(about a second more at every start)', file=sys.stderr)
        return EXIT_OK
    done = (f'built ahead of time into {made["directory"]} in {made["seconds"]:.1f} s'
            if made['built'] else f'built ahead of time already in {made["directory"]}')
    print(f'planning kernels: {made["signatures"]} signatures of {made["kernels"]} kernels '
          f'{done}; left to numba (they reach Python code): '
          f'{", ".join(made["left"]) or "none"}')
    return EXIT_OK


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
