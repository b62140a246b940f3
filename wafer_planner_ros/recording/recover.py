"""
Making a recording cut off by a crash complete: ``wafer-recover``.

The records written before the cut (``reading.read``) are rewritten into a complete,
indexed MCAP file; the cut file is kept beside it with the suffix ``.cut``; and
``metadata.yaml`` is written. Do not run it on a recording that is still being written.
"""

import os
from pathlib import Path

from mcap.writer import CompressionType, Writer

from wafer_planner_ros.recording.bag import METADATA_FILE, metadata_yaml, write_metadata_file
from wafer_planner_ros.recording.reading import mcap_file, read, Recording

DAMAGED_SUFFIX = '.cut'
"""Appended to the name of the file ``recover`` replaced."""


def recover(path) -> Recording:
    """
    Make the bag at ``path`` complete: indexed MCAP file and ``metadata.yaml``.

    A cut file is rewritten from its readable records and kept beside the new one with the
    suffix ``.cut``. A complete file is left as it is (only a missing ``metadata.yaml`` is
    written). Returns what was read.
    """
    file = mcap_file(path)
    recording = read(file)
    directory = file.parent
    if not recording.complete:
        partial = file.with_name(file.name + '.partial')
        with open(partial, 'wb') as stream:
            write(recording, stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(file, file.with_name(file.name + DAMAGED_SUFFIX))
        os.replace(partial, file)
    if not recording.complete or not (directory / METADATA_FILE).exists():
        write_metadata_file(directory, _metadata_text(recording, file.name))
    return recording


def write(recording: Recording, stream) -> None:
    """Write the records of ``recording`` as one complete MCAP file."""
    writer = Writer(stream, compression=CompressionType.NONE)
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
    writer.add_metadata('rosbag2', {'serialized_metadata': _metadata_text(
        recording, Path(recording.path).name)})
    writer.finish()


def _metadata_text(recording: Recording, file_name: str) -> str:
    times = [m.log_time for m in recording.messages]
    return metadata_yaml(file_name, recording.topics(), recording.counts(),
                         min(times, default=0), max(times, default=0))
