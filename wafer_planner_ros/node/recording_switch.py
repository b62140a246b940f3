"""
Recording switched on and off while the node runs: ``~/set_recording`` and ``recording.enabled``.

The node records when ``recording.enabled`` is true at start-up, and from then on as
``~/set_recording`` or a new value of ``recording.enabled`` says. The parameter keeps telling
the truth: switched by the service, or stopped by itself (a failed disk), the recording sets it
without being switched a second time. Each switch is logged; once the node is being shut down
(Ctrl-C, SIGTERM) its logger cannot reach ``/rosout``, and the closing is printed instead.
"""

import sys
from typing import Tuple

from rclpy.parameter import Parameter

from wafer_planner_ros.node.recording import NodeRecording


class RecordingSwitch:
    """Start and stop the node's recording as asked; see the module."""

    def __init__(self, node, recording: NodeRecording):
        """Switch ``recording`` for ``node`` (its parameters, settings, logger and context)."""
        self._node, self._recording = node, recording
        self._switching = False
        """``recording.enabled`` is being set to tell the truth: that switches nothing."""

    def switch(self, on: bool) -> Tuple[bool, str]:
        """Start or stop recording (``~/set_recording``); return (success, the sentence)."""
        if on:
            success = self.start()
            message = (f'recording to {self._recording.last_directory}'
                       if success else self._recording.last_error)
        else:
            success, message = self._stop()
            self._log_closed(success, message)
        self.sync_enabled()
        return success, message

    def follow(self, enabled: bool) -> None:
        """Start or stop recording as ``recording.enabled`` was just set (unless set here)."""
        if self._switching:
            return
        if enabled:
            self.start()
        else:
            self.stop()

    def sync_enabled(self) -> None:
        """Keep recording.enabled telling the truth (without switching a second time)."""
        recording = bool(self._recording.status()['recording'])
        if self._node.get_parameter('recording.enabled').value == recording:
            return
        self._switching = True
        try:
            self._node.set_parameters([Parameter('recording.enabled', value=recording)])
        finally:
            self._switching = False

    def start(self) -> bool:
        """Start recording into ``recording.directory``; return whether it records."""
        try:
            directory = self._recording.start(self._node.settings.recording_directory)
        except OSError as exc:
            self._node.get_logger().error(f'{exc}; planning goes on without recording')
            return False
        self._node.get_logger().info(f'recording to {directory}')
        return True

    def stop(self) -> None:
        """Close the recording, saying how (nothing when not recording)."""
        self._log_closed(*self._stop())

    def _log_closed(self, success: bool, message: str) -> None:
        """Log ``message`` about the closing (printed once the node is shutting down)."""
        if message == 'not recording':
            return
        if not self._node.context.ok():  # after Ctrl-C or SIGTERM the logger cannot reach /rosout
            print(f'[wafer_planner] {message}', file=sys.stderr, flush=True)
        elif success:
            self._node.get_logger().info(message)
        else:
            self._node.get_logger().error(message)

    def _stop(self) -> tuple:
        """Close the recording; return (closed properly, a sentence saying so)."""
        directory, error = self._recording.stop()
        if directory is None:
            return True, 'not recording'
        if error:
            return False, f'recording {directory} not closed properly: {error}'
        return True, f'recording closed: {directory}'
