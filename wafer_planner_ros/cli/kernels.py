"""
``wafer-kernels``: compile the planning kernels for this machine once, or check they are.

The set-up (``make run``, ``make test``) runs it after an install: every compiled kernel is
compiled and kept in numba's cache (``kernels.cache_root``), where the node and every tool
find it, so that no start, request or rebuild compiles. A second run only loads them.
``--check`` compiles nothing: exit 1 when some kernel is not in the cache.
"""

import argparse
import sys
import time

from wafer_planner_ros import kernels
from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, run
from wafer_planner_ros.service.warmup import compile_kernels


def main(argv=None) -> int:
    """Run wafer-kernels."""
    parser = argparse.ArgumentParser(prog='wafer-kernels', description=__doc__.split('\n')[1])
    parser.add_argument('--check', action='store_true',
                        help='compile nothing; exit 1 when some kernel is not in the cache')
    args = parser.parse_args(argv)
    begun = time.monotonic()
    loaded = kernels.load_cached()
    missing = kernels.uncached()
    where = kernels.cache_root()
    if args.check or not missing:
        if missing:
            print(f'{len(missing)} of {len(kernels.registered())} planning kernels are not '
                  f'compiled in {where}: ' + ', '.join(k.__qualname__ for k in missing))
            return EXIT_FAILURE
        print(f'planning kernels: {loaded} signatures of {len(kernels.registered())} kernels '
              f'loaded from {where} in {time.monotonic() - begun:.2f} s')
        return EXIT_OK
    print(f'compiling the planning kernels into {where} (once per install, about 40 s on '
          'two cores):', flush=True)

    def progress(step: str) -> None:
        print(f'  [{time.monotonic() - begun:5.1f} s] {step}', flush=True)

    made = compile_kernels(progress)
    print(f'planning kernels: {made["compiled"]} signatures compiled, {made["signatures"]} '
          f'in all, in {time.monotonic() - begun:.1f} s')
    missing = kernels.uncached()
    if missing:
        print('not compiled by the workload: ' + ', '.join(k.__qualname__ for k in missing),
              file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
