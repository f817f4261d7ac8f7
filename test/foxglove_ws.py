"""
A Foxglove WebSocket client for the tests (protocol ``foxglove.sdk.v1``, the SDK's server).

It speaks the protocol from its text, independently of the server's code: the server sends
``serverInfo`` and ``advertise`` (JSON text frames: channels with their topic, encoding,
schema name and schema); the client sends ``subscribe`` with its own subscription ids; each
message then comes as a binary frame: opcode 1, uint32 subscription id, uint64 timestamp
[ns], payload (little endian). A client made with ``read=False`` subscribes and then never
reads again: the slow client whose socket buffers fill.
"""

import contextlib
import json
import struct
import threading

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOL = 'foxglove.sdk.v1'
MESSAGE_DATA = 1


class FoxgloveClient:
    """Connect, subscribe to `topics` once advertised, collect their messages (a thread)."""

    def __init__(self, port, topics, read=True, host='127.0.0.1', timeout=30.0):
        """Connect and start reading; `topics` are subscribed as soon as all are advertised."""
        self.topics = set(topics)
        self.read = read
        self.channels = {}             # topic -> advertised channel (dict)
        self.messages = {topic: [] for topic in self.topics}   # (timestamp ns, payload)
        self.subscribed = threading.Event()
        self.error = None
        self._changed = threading.Condition()
        self._subscriptions = {}       # subscription id -> topic
        self._connection = contextlib.ExitStack()
        self.socket = self._connection.enter_context(connect(
            f'ws://{host}:{port}', subprotocols=[SUBPROTOCOL], open_timeout=timeout,
            close_timeout=1.0, max_size=None))
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        try:
            while True:
                frame = self.socket.recv()
                if isinstance(frame, str):
                    self._control(json.loads(frame))
                    if self.subscribed.is_set() and not self.read:
                        return         # the slow client: never reads again
                else:
                    self._data(frame)
        except ConnectionClosed:
            pass
        except Exception as error:   # noqa: B902 - reported to the waiting test
            self.error = error
        finally:
            with self._changed:
                self._changed.notify_all()

    def _control(self, message):
        if message.get('op') == 'advertise':
            for channel in message['channels']:
                self.channels[channel['topic']] = channel
            if not self.subscribed.is_set() and self.topics <= set(self.channels):
                subscriptions = []
                for number, topic in enumerate(sorted(self.topics), start=1):
                    self._subscriptions[number] = topic
                    subscriptions.append({'id': number,
                                          'channelId': self.channels[topic]['id']})
                self.socket.send(json.dumps({'op': 'subscribe',
                                             'subscriptions': subscriptions}))
                self.subscribed.set()

    def _data(self, frame):
        opcode, subscription, timestamp = struct.unpack_from('<BIQ', frame)
        if opcode != MESSAGE_DATA:
            return
        topic = self._subscriptions[subscription]
        with self._changed:
            self.messages[topic].append((timestamp, frame[13:]))
            self._changed.notify_all()

    def decoded(self, topic):
        """Return `topic`'s payloads decoded: JSON as dicts, CDR as bytes."""
        encoding = self.channels[topic]['encoding']
        return [json.loads(payload) if encoding == 'json' else payload
                for _, payload in self.messages[topic]]

    def wait_for(self, counts, timeout):
        """Wait until each topic of `counts` has that many messages; raise on timeout."""
        def done():
            return all(len(self.messages[t]) >= n for t, n in counts.items())
        self.wait_until(done, timeout, lambda: f'{ {t: len(self.messages[t]) for t in counts} }'
                        f' of {counts}')

    def wait_until(self, done, timeout, what):
        """Wait until `done()` holds (checked at each message); raise naming `what()`."""
        with self._changed:
            if not self._changed.wait_for(lambda: done() or self.error or
                                          not self._thread.is_alive(), timeout) or not done():
                raise AssertionError(f'Foxglove client: {what()} within {timeout} s'
                                     f' (error: {self.error!r})')

    def close(self):
        """Close the connection (a vanished client, when done abruptly mid-run)."""
        self._connection.close()
        self._thread.join(10.0)
