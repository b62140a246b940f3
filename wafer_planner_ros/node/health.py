"""
The node's health on ``/diagnostics``: its status summed up as one level and one sentence.

The node publishes it once a second (and to the live view). The level and the sentence come
from the status (``~/get_status``): ready or not, a failed rebuild (the previous roadmap
serving), what the node is busy with, a recording that failed or stalled; the values repeat
the status's main keys, so that a diagnostics viewer shows them without asking the node.
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

KEYS = ('ready', 'nodes', 'edges', 'hash', 'station_table', 'station_table_empty',
        'station_table_rejected', 'queue', 'served', 'failed', 'rebuild_failed',
        'last_rebuild_error', 'recording', 'recording_directory', 'recording_error',
        'recording_lost', 'answers_before_recorded')
"""The status's keys repeated as the health's values."""


def diagnostics(status: dict, name: str) -> DiagnosticArray:
    """Return node ``name``'s health, its ``status`` summed up (the caller stamps it)."""
    if status['ready']:
        level, message = DiagnosticStatus.OK, 'ready'
        if status['rebuild_failed']:
            level = DiagnosticStatus.WARN
            message = (f"rebuild failed: {status['last_rebuild_error']}; serving the "
                       f"previous roadmap {status['hash'][:12]}")
        elif status['busy_with'] == 'kernels':
            message = 'ready; loading the planning kernels and the station table'
        elif status['busy_with'] == 'station_table':
            message = 'ready; planning the station table'
        elif status['busy_with'] == 'load':
            message = 'ready; rebuilding the roadmap'
    elif status['busy_with'] == 'load':
        level, message = DiagnosticStatus.WARN, 'loading the roadmap'
    else:
        level = DiagnosticStatus.ERROR
        message = f"roadmap not loaded: {status['last_rebuild_error']}"
    if status['recording_error']:
        level = max(level, DiagnosticStatus.WARN)
        message += f"; {status['recording_error']}"
    elif status.get('recording_stalled'):
        level = max(level, DiagnosticStatus.WARN)
        message += ('; recording stalled: the disk has not synced for 0.25 s, answers go '
                    'out before they are on it')
    report = DiagnosticStatus(level=level, name=f'{name}: health', message=message,
                              hardware_id='wafer_planner',
                              values=[KeyValue(key=k, value=str(status.get(k, '')))
                                      for k in KEYS])
    return DiagnosticArray(status=[report])
