"""
Making a recording cut off by a crash complete: ``wafer-recover``.

Every file of the bag that ends before its footer (the last one, when the node was killed;
no other is left so, as a file is finished before the next one is started) is rewritten
from its readable records (``reading.read_file``) into a complete, indexed MCAP file, and
the cut file is kept beside it with the suffix ``.cut``; a file without a single readable
record (killed as it was started) is only set aside so. Then ``metadata.yaml`` is written,
listing every file the bag holds now (retention may have removed the oldest). Do not run it
on a recording that is still being written.
"""

import os
from pathlib import Path

from mcap.writer import CompressionType, Writer

from wafer_planner_ros.recording.bag import (CHUNK_SIZE, METADATA_FILE, metadata_yaml,
                                             write_metadata_file)
from wafer_planner_ros.recording.reading import (describe, merge, read_file, Recording,
                                                 recording_files, RecordingError)

DAMAGED_SUFFIX = '.cut'
"""Appended to the name of a file ``recover`` replaced or set aside."""


def recover(path) -> Recording:
    """
    Make the bag at ``path`` complete: indexed MCAP files and ``metadata.yaml``.

    ``path`` is a bag directory (every file of it is looked at) or one of its files. A
    complete file is left as it is (only a missing ``metadata.yaml`` is written). Return
    what was read before anything was rewritten, every file in order (``cut_files``: those
    that were cut off, now kept as ``*.cut``).
    """
    files = recording_files(path)
    directory = files[0].parent
    parts, unreadable, changed = [], [], False
    for file in files:
        try:
            recording = read_file(file)
        except RecordingError as exc:
            if len(files) == 1:
                raise
            os.replace(file, file.with_name(file.name + DAMAGED_SUFFIX))
            unreadable.append((file, str(exc)))
            changed = True
            continue
        if not recording.complete:
            _rewrite(recording)
            changed = True
        parts.append(recording)
    if not parts:
        raise RecordingError('; '.join(reason for _, reason in unreadable))
    if changed or not (directory / METADATA_FILE).exists():
        write_metadata_file(directory, describe(directory))
    found = merge(Path(path), parts) if len(parts) > 1 else parts[0]
    for file, reason in unreadable:
        found.complete = False
        found.cut = '; '.join(filter(None, [found.cut, f'{file.name}: {reason}']))
        found.cut_files.append(file)
    return found


def _rewrite(recording: Recording) -> None:
    """Replace a cut file by a complete one holding its records; keep it as ``*.cut``."""
    file = Path(recording.path)
    partial = file.with_name(file.name + '.partial')
    with open(partial, 'wb') as stream:
        write(recording, stream)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(file, file.with_name(file.name + DAMAGED_SUFFIX))
    os.replace(partial, file)


def write(recording: Recording, stream) -> None:
    """Write the records of ``recording`` as one complete MCAP file."""
    writer = Writer(stream, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
    writer.start(profile=recording.profile, library=recording.library)
    schema_ids = {old: writer.register_schema(s.name, s.encoding, s.data)
                  for old, s in recording.schemas.items()}
    channel_ids = {old: writer.register_channel(c.topic, c.message_encoding,
                                                schema_ids.get(c.schema_id, 0), c.metadata)
                   for old, c in recording.channels.items()}
    for message in recording.messages:
        writer.add_message(channel_ids[message.channel_id], log_time=message.log_time,
                           data=message.data, publish_time=message.publish_time,
                           sequence=message.sequence)
    for attachment in recording.attachments:
        writer.add_attachment(attachment.create_time, attachment.log_time, attachment.name,
                              attachment.media_type, attachment.data)
    for metadata in recording.metadata:
        writer.add_metadata(metadata.name, metadata.metadata)
    writer.add_metadata('rosbag2', {'serialized_metadata': metadata_yaml(
        recording.topics(), [recording.info()])})
    writer.finish()
