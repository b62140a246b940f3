"""
Failing safely in the node: a failure as a bounded sentence, and a logger that never raises.

Every request gets exactly one answer whatever goes wrong, so what reports a failure must
not fail itself: an exception whose ``str`` raises, a reason of megabytes, a log line with a
lone surrogate (rclpy refuses those) or a logger after shutdown; a service callback that
fails answers so (``guarded_service``, for a node with a ``log``).
"""

import functools

REASON = 300
"""Most characters of a failure's reason in an answer or the status."""


def reason_of(exc: BaseException, with_type: bool = True) -> str:
    """Return an exception as a bounded sentence (``OverflowError: ...``); never raise."""
    try:
        text = str(exc)
    except Exception:  # noqa: B902 - an exception that cannot say what it is
        text = ''
    text = ' '.join(text.split())  # one line (a YAML error has several)
    text = f'{type(exc).__name__}: {text}' if with_type or not text else text
    return text if len(text) <= REASON else text[:REASON] + '...'


class SafeLogger:
    """
    The node's logger, which never raises: logging must not stop an answer.

    One call site per level: rclpy refuses a call site whose severity changes.
    """

    def __init__(self, logger):
        self._logger = logger

    def info(self, text: str) -> None:
        try:
            self._logger.info(_loggable(text))
        except Exception:  # noqa: B902 - e.g. after the context is shut down
            pass

    def warning(self, text: str) -> None:
        try:
            self._logger.warning(_loggable(text))
        except Exception:  # noqa: B902 - e.g. after the context is shut down
            pass

    def error(self, text: str) -> None:
        try:
            self._logger.error(_loggable(text))
        except Exception:  # noqa: B902 - e.g. after the context is shut down
            pass


def _loggable(text: str) -> str:
    """Return ``text`` as the logger takes it (it refuses lone surrogates)."""
    try:
        text.encode('utf-8')
        return text
    except UnicodeEncodeError:
        return text.encode('utf-8', 'backslashreplace').decode('utf-8')


def guarded_service(callback):
    """Wrap a service callback: a failure is answered (success false, the reason), not raised."""
    @functools.wraps(callback)
    def guarded(node, request, response):
        try:
            return callback(node, request, response)
        except Exception as exc:  # noqa: B902 - the node serves on
            node.log.error(f'{callback.__name__}: internal error: {reason_of(exc)}')
            response.success, response.message = False, f'internal error: {reason_of(exc)}'
            return response
    return guarded
