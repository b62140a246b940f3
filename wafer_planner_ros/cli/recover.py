"""
wafer-recover: make a recording cut off by a crash complete, indexed and readable.

After SIGKILL or a power cut the MCAP file being written has no summary, index or footer and
the bag has no ``metadata.yaml``, so ``ros2 bag`` and ``rosbags`` refuse it. This rewrites
every record written before the cut into a complete file (the cut one is kept as
``*.mcap.cut``) and writes ``metadata.yaml`` listing every file of the bag (a split bag's
earlier files are complete already; those retention removed are not listed). A complete
recording is left as it is.
"""

import argparse
import sys

from wafer_planner_ros.cli.common import EXIT_FAILURE, EXIT_OK, run
from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.recover import DAMAGED_SUFFIX, recover


def main(argv=None) -> int:
    """Run wafer-recover."""
    parser = argparse.ArgumentParser(prog='wafer-recover', description=__doc__.split('\n')[1])
    parser.add_argument('bags', nargs='+', metavar='BAG',
                        help='recording directory (or one of its .mcap files)')
    args = parser.parse_args(argv)
    code = EXIT_OK
    for bag in args.bags:  # one that cannot be recovered does not stop the others
        try:
            recording = recover(bag)
        except (WaferPlannerError, OSError) as exc:
            print(f'{bag}: not recovered: {exc}', file=sys.stderr)
            code = EXIT_FAILURE
            continue
        counts = ', '.join(f'{topic} {n}' for topic, n in recording.counts().items())
        files = len(recording.files)
        contents = (f"{files} file{'' if files == 1 else 's'}, "
                    f'{len(recording.messages)} messages ({counts}), '
                    f'{len(recording.attachments)} attachments, '
                    f'{len(recording.metadata)} metadata records')
        if recording.complete:
            print(f'{bag}: complete, nothing to recover: {contents}')
        else:
            kept = ', '.join(f.name + DAMAGED_SUFFIX for f in recording.cut_files)
            print(f'{bag}: cut off ({recording.cut}); recovered {contents}; kept as they '
                  f'were: {kept}')
    return code


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
