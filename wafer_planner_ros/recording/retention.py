"""
Retention: at most ``keep`` bag files in a recording directory, the oldest removed first.

The files counted are the MCAP files of every bag of one node in one recording directory:
``<dir>/<node>_<UTC time>/*.mcap``, as ``recorder.bag_name`` names the bags (a bag named
otherwise counts its own files only). Oldest first means by the bag's time, then by split
number. The file being written is never removed, nor anything but MCAP files and the
``metadata.yaml`` of a bag left without any: such a bag directory is removed once empty
(a ``*.mcap.cut`` kept by ``wafer-recover`` keeps it). A bag that keeps some of its files
has its ``metadata.yaml``, if it has one, rewritten (``rewrite_metadata``) to list only
those, so that ``ros2 bag`` and ``rosbags``, which refuse a bag whose listed files are
missing, still open it.
"""

import logging
import os
from pathlib import Path
import re
from typing import List, Optional, Tuple

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.bag import bag_files, METADATA_FILE, write_metadata_file
from wafer_planner_ros.recording.reading import describe

logger = logging.getLogger(__name__)

_BAG_NAME = re.compile(r'^(?P<node>.+)_\d{4}_\d{2}_\d{2}-\d{2}_\d{2}_\d{2}_\d{6}$')
"""``<node>_<UTC time>``: ``recorder.bag_name``."""


def sibling_bags(bag: Path) -> List[Path]:
    """Return the bags of ``bag``'s node in its parent directory, oldest first (``bag`` too)."""
    bag = Path(bag)
    named = _BAG_NAME.match(bag.name)
    if named is None:
        return [bag]
    node = named.group('node')
    try:
        entries = list(os.scandir(bag.parent))
    except OSError:
        return [bag]
    found = {Path(e.path) for e in entries if e.is_dir(follow_symlinks=False)
             and (m := _BAG_NAME.match(e.name)) is not None and m.group('node') == node}
    return sorted(found | {bag}, key=lambda p: p.name)


def prune(bag: Path, room: int,
          protect: Optional[Path] = None) -> Tuple[List[Path], List[Path]]:
    """
    Remove the oldest files of ``bag``'s node until at most ``room`` are left.

    Return (the files removed, the bags other than ``bag`` that lost files and keep some,
    for ``rewrite_metadata``). ``protect`` (the file being written) counts but is never
    removed. Bags other than ``bag`` left without files are removed. A file that cannot be
    removed is logged and counted as kept.
    """
    files = [f for b in sibling_bags(bag) for f in bag_files(b)]
    removed = []
    for file in files:
        if len(files) - len(removed) <= max(room, 0):
            break
        if protect is not None and file == Path(protect):
            continue
        try:
            file.unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            logger.warning('retention: %s not removed: %s', file, exc.strerror or exc)
            continue
        removed.append(file)
        logger.info('retention: removed %s', file)
    touched = []
    for directory in sorted({f.parent for f in removed} - {Path(bag)}):  # not the one written
        if bag_files(directory):
            touched.append(directory)
        else:
            _remove_bag(directory)
    return removed, touched


def rewrite_metadata(bag: Path, attempts: int = 3) -> None:
    """
    List in ``bag``'s ``metadata.yaml`` (when it has one) only the files still there.

    ``prune`` may remove more of them meanwhile (it runs in another thread): the files are
    looked at again after writing, and a bag found empty is removed.
    """
    bag = Path(bag)
    for _ in range(attempts):
        if not (bag / METADATA_FILE).exists():
            return
        files = bag_files(bag)
        if not files:
            _remove_bag(bag)
            return
        try:
            write_metadata_file(bag, describe(bag))
        except (OSError, WaferPlannerError):  # a file removed while it was read
            continue
        if bag_files(bag) == files:
            return


def _remove_bag(directory: Path) -> None:
    try:
        (directory / METADATA_FILE).unlink(missing_ok=True)
        directory.rmdir()
    except OSError:  # something else is kept in it (a recovered .cut file, say)
        return
    logger.info('retention: removed %s', directory)
