"""A child's loop: one reply per message, whatever the reply function does."""

from multiprocessing import Pipe
import threading

from wafer_planner_ros.service.child_process import serve


def test_every_message_gets_one_reply_even_one_that_fails_or_cannot_be_sent():
    requests, to_child = Pipe(duplex=False)
    from_child, replies = Pipe(duplex=False)

    def reply(message):
        if message == 'fail':
            raise ValueError('no such thing')
        if message == 'unsendable':
            return ('made', lambda: None)  # a function defined here does not pickle
        return ('made', message)
    child = threading.Thread(target=serve, args=(requests, replies, reply))
    child.start()
    for message in ('a', 'fail', 'unsendable', 'b'):
        to_child.send(message)
    got = [from_child.recv() for _ in range(4)]
    to_child.close()  # the loop ends once its pipe closes
    child.join(timeout=5.0)
    assert not child.is_alive()
    assert got[0] == ('made', 'a') and got[3] == ('made', 'b')
    assert got[1] == ('error', 'ValueError: no such thing')
    assert got[2][0] == 'error' and got[2][1].startswith('its answer could not be sent')
