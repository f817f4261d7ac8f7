"""
Recordings in the rosbag2 layout with MCAP storage: write, read, recover after a crash.

A bag is a directory holding ``metadata.yaml`` (rosbag2 format version 9) and one
``<name>_0.mcap`` written the way ``rosbag2_storage_mcap`` writes it: profile ``ros2``, one
schema per message type with encoding ``ros2msg`` (the installed ``.msg`` text, nested types
appended after a line of 80 ``=`` and ``MSG: pkg/Type``), message encoding ``cdr``, channel
metadata ``offered_qos_profiles`` (YAML) and ``topic_type_hash``, a statistics record,
chunk compression (zstd) and every index. The MCAP records go through the ``mcap`` library's
``Writer``; nothing here encodes a record by hand.

Crash safety: the writer closes a chunk when it reaches ``chunk_size`` bytes or has been open
``chunk_period`` seconds, and writes it straight to the file (unbuffered), so a process that
is killed loses at most the chunk it was filling. ``metadata.yaml`` is written when the bag
opens and again after every chunk. A killed recorder leaves an MCAP file without its summary
and footer: ``mcap``'s streaming reader reads it as it is, and ``recover_bag`` rewrites it as
a complete file (what ``mcap recover`` and ``ros2 bag reindex`` do) so any reader opens it.

Message types are resolved from the installed interfaces (Python classes and the ament
index); no rclpy import, so tools and tests read bags without a ROS graph.
"""

from dataclasses import dataclass, field
import importlib
import os
import re
import time

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer
import yaml

METADATA_FILE = 'metadata.yaml'
ROSBAG2_VERSION = 9
DEFINITION_SEPARATOR = '=' * 80
_NESTED = re.compile(r'([A-Za-z0-9_]+)/([A-Za-z0-9_]+)')
_IDL_TO_MSG = {'boolean': 'bool', 'octet': 'byte', 'double': 'float64', 'float': 'float32',
               'long double': 'float64'}
COMPRESSIONS = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                'none': CompressionType.NONE}


class BagError(RuntimeError):
    """A bag that cannot be written, read or recovered, with the reason."""


# ---------------------------------------------------------------------------- types
def full_type_name(type_name):
    """Return 'pkg/msg/Type' for 'pkg/Type' or 'pkg/msg/Type' (rosbag2 stores the full name)."""
    parts = type_name.split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3:
        return type_name
    raise BagError(f'not a ROS type name: {type_name!r}')


def message_class(type_name):
    """Return the Python class of a message type ('pkg/msg/Type', action sub-messages too)."""
    package, kind, name = full_type_name(type_name).split('/')
    try:
        module = importlib.import_module(f'{package}.{kind}')
    except ImportError as error:
        raise BagError(f'message type {type_name!r} is not installed ({error})') from None
    if hasattr(module, name):
        return getattr(module, name)
    base, _, part = name.rpartition('_')      # e.g. PaintPattern_FeedbackMessage
    interface = getattr(module, base, None)
    if interface is not None and hasattr(getattr(interface, 'Impl', None), part):
        return getattr(interface.Impl, part)
    if interface is not None and hasattr(interface, part):      # services: Request, Event
        return getattr(interface, part)
    raise BagError(f'message type {type_name!r} is not installed')


def _interface_file(type_name):
    """Return the installed .msg file of a type, or None (action/service parts have none)."""
    package, kind, name = full_type_name(type_name).split('/')
    if kind != 'msg':
        return None
    try:
        from ament_index_python.packages import get_package_share_directory
        path = os.path.join(get_package_share_directory(package), 'msg', f'{name}.msg')
    except (ImportError, LookupError):
        return None
    return path if os.path.isfile(path) else None


def type_hash(type_name):
    """Return the installed RIHS01 type hash of a type ('' when the interface has none)."""
    import json
    package, kind, name = full_type_name(type_name).split('/')
    try:
        from ament_index_python.packages import get_package_share_directory
        share = get_package_share_directory(package)
    except (ImportError, LookupError):
        return ''
    for file_name in (name, name.rpartition('_')[0]):      # action/service parts: base file
        path = os.path.join(share, kind, f'{file_name}.json')
        if file_name and os.path.isfile(path):
            with open(path, encoding='utf-8') as stream:
                for entry in json.load(stream).get('type_hashes', []):
                    if entry.get('type_name') == f'{package}/{kind}/{name}':
                        return entry.get('hash_string', '')
    return ''


_IDL_SPELLINGS = ((re.compile(r'sequence<(.+), (\d+)>'), '{}[<={}]'),
                  (re.compile(r'sequence<(.+)>'), '{}[]'),
                  (re.compile(r'(.+)\[(\d+)\]'), '{}[{}]'))


def _field_type_to_msg(idl_type):
    """Return the .msg spelling of an rclpy field type ('sequence<double>' -> 'float64[]')."""
    for pattern, spelling in _IDL_SPELLINGS:
        match = pattern.fullmatch(idl_type)
        if match:
            return spelling.format(_field_type_to_msg(match.group(1)), *match.groups()[1:])
    string = re.fullmatch(r'(w?string)<(\d+)>', idl_type)
    if string:
        return f'{string.group(1)}<={string.group(2)}'
    return _IDL_TO_MSG.get(idl_type, idl_type)


def _own_definition(type_name):
    """Return the type's own .msg text: the installed file, else generated from its fields."""
    path = _interface_file(type_name)
    if path is not None:
        with open(path, encoding='utf-8') as stream:
            return stream.read()
    fields = message_class(type_name).get_fields_and_field_types()
    return ''.join(f'{_field_type_to_msg(kind)} {name}\n' for name, kind in fields.items())


def _nested_types(type_name):
    """Return the message types a type's fields refer to, as 'pkg/Type', in field order."""
    nested = []
    for kind in message_class(type_name).get_fields_and_field_types().values():
        for package, name in _NESTED.findall(kind):
            if f'{package}/{name}' not in nested:
                nested.append(f'{package}/{name}')
    return nested


def _nested_full_name(package, name):
    """Return the full name of a nested type ('helio_msgs/PaintPattern_Feedback' -> action)."""
    for kind in ('msg', 'action', 'srv'):
        try:
            message_class(f'{package}/{kind}/{name}')
            return f'{package}/{kind}/{name}'
        except BagError:
            continue
    raise BagError(f'nested message type {package}/{name} is not installed')


def message_definition(type_name):
    """
    Return the ``ros2msg`` schema text of a type, as rosbag2_storage_mcap writes it.

    The type's own definition, then each nested type once (depth first), each after a line
    of 80 '=' and ``MSG: pkg/Type``.
    """
    text = _own_definition(type_name)
    seen, order, stack = set(), [], list(reversed(_nested_types(type_name)))
    while stack:
        nested = stack.pop()
        if nested in seen:
            continue
        seen.add(nested)
        order.append(nested)
        package, name = nested.split('/')
        stack.extend(reversed(_nested_types(_nested_full_name(package, name))))
    for nested in order:
        package, name = nested.split('/')
        body = _own_definition(_nested_full_name(package, name))
        text = text.rstrip('\n') + f'\n{DEFINITION_SEPARATOR}\nMSG: {nested}\n{body}'
    return text


# ---------------------------------------------------------------------------- metadata
@dataclass
class TopicInfo:
    """One topic of a bag: name, full type, the publishers' offered QoS, count."""

    name: str
    type_name: str
    offered_qos_profiles: list = field(default_factory=list)   # v9 dicts (rosbag2 keys)
    type_hash: str = ''
    message_count: int = 0


def qos_profile_dict(history='keep_last', depth=10, reliability='reliable',
                     durability='volatile', liveliness='automatic'):
    """Return one offered QoS profile as rosbag2 v9 metadata writes it."""
    never = {'sec': 9223372036, 'nsec': 854775807}
    return {'history': history, 'depth': int(depth), 'reliability': reliability,
            'durability': durability, 'deadline': dict(never), 'lifespan': dict(never),
            'liveliness': liveliness, 'liveliness_lease_duration': dict(never),
            'avoid_ros_namespace_conventions': False}


def metadata_type_hash(topic):
    """
    Return the type hash metadata.yaml names for a topic.

    Action and service parts (``pkg/action/X_FeedbackMessage``) are written with ``pkg/Type``
    names in their schema, as rosbag2 spells nested types and as ``mcap_ros2`` (Foxglove)
    parses them; a reader that recomputes the hash from that text (rosbags) types them as
    ``pkg/msg/...`` and gets a different hash, so metadata.yaml leaves their hash empty. The
    MCAP channel keeps the true one (``topic_type_hash``).
    """
    return topic.type_hash if '/msg/' in topic.type_name else ''


def metadata_dict(topics, file_name, start_ns, end_ns, compression):
    """Return the content of metadata.yaml (rosbag2 v9) for `topics` in `file_name`."""
    count = sum(topic.message_count for topic in topics)
    duration = max(0, end_ns - start_ns) if count else 0
    start = start_ns if count else 0
    return {'rosbag2_bagfile_information': {
        'version': ROSBAG2_VERSION,
        'storage_identifier': 'mcap',
        'relative_file_paths': [file_name],
        'duration': {'nanoseconds': int(duration)},
        'starting_time': {'nanoseconds_since_epoch': int(start)},
        'message_count': int(count),
        'topics_with_message_count': [
            {'topic_metadata': {'name': topic.name, 'type': topic.type_name,
                                'serialization_format': 'cdr',
                                'offered_qos_profiles': topic.offered_qos_profiles,
                                'type_description_hash': metadata_type_hash(topic)},
             'message_count': int(topic.message_count)} for topic in topics],
        'compression_format': '',      # chunk compression is inside the MCAP file
        'compression_mode': '',
        'files': [{'path': file_name, 'starting_time': {'nanoseconds_since_epoch': int(start)},
                   'duration': {'nanoseconds': int(duration)}, 'message_count': int(count)}],
        'custom_data': {'writer': 'helio_control.bag_files', 'chunk_compression': compression},
        'ros_distro': 'jazzy',
    }}


def write_metadata(directory, content):
    """Write metadata.yaml atomically (a reader never sees half a file)."""
    path = os.path.join(directory, METADATA_FILE)
    temporary = path + '.tmp'
    with open(temporary, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(content, stream, default_flow_style=False, sort_keys=False)
    os.replace(temporary, path)
    return path


# ---------------------------------------------------------------------------- writing
class BagWriter:
    """
    Write one bag (see the module docstring).

    ``add_topic(TopicInfo)`` before the first message of a topic; ``write(topic, log_time_ns,
    cdr_bytes)``; ``close()`` writes the summary, the footer and the final metadata.
    """

    def __init__(self, directory, chunk_size=1 << 20, chunk_period=2.0, compression='zstd',
                 clock=time.monotonic):
        """Create `directory` (it must not hold a bag already) and start the MCAP file."""
        if compression not in COMPRESSIONS:
            raise BagError(f'compression must be one of {sorted(COMPRESSIONS)}, not '
                           f'{compression!r}')
        if os.path.exists(os.path.join(directory, METADATA_FILE)):
            raise BagError(f'{directory} already holds a bag (metadata.yaml); choose a new '
                           'directory')
        os.makedirs(directory, exist_ok=True)
        self.directory = directory
        self.file_name = f'{os.path.basename(os.path.normpath(directory))}_0.mcap'
        self.path = os.path.join(directory, self.file_name)
        self.compression = compression
        self.chunk_period = chunk_period
        self._clock = clock
        self._stream = open(self.path, 'wb')
        self._writer = Writer(self._stream, chunk_size=chunk_size,
                              compression=COMPRESSIONS[compression], index_types=IndexType.ALL,
                              use_statistics=True, use_summary_offsets=True)
        self._writer.start(profile='ros2', library='helio_control.bag_files (mcap)')
        self.topics = {}
        self._channels = {}
        self._schemas = {}
        self._chunk_opened = None
        self._sequence = 0
        self.start_ns, self.end_ns = None, None
        self.closed = False
        self.write_metadata()

    def add_topic(self, topic):
        """Register a topic (TopicInfo); its schema is written once per type."""
        if topic.name in self.topics:
            return
        topic.type_name = full_type_name(topic.type_name)
        topic.type_hash = topic.type_hash or type_hash(topic.type_name)
        if topic.type_name not in self._schemas:
            self._schemas[topic.type_name] = self._writer.register_schema(
                name=topic.type_name, encoding='ros2msg',
                data=message_definition(topic.type_name).encode('utf-8'))
        qos_yaml = yaml.safe_dump(topic.offered_qos_profiles, default_flow_style=False,
                                  sort_keys=False) if topic.offered_qos_profiles else ''
        self._channels[topic.name] = self._writer.register_channel(
            topic=topic.name, message_encoding='cdr', schema_id=self._schemas[topic.type_name],
            metadata={'offered_qos_profiles': qos_yaml, 'topic_type_hash': topic.type_hash})
        topic.message_count = 0
        self.topics[topic.name] = topic

    def write(self, topic, log_time_ns, data, publish_time_ns=None):
        """Append one serialized message of a registered topic."""
        if topic not in self._channels:
            raise BagError(f'topic {topic!r} was not added to the bag')
        log_time_ns = int(log_time_ns)
        self._sequence += 1
        self._writer.add_message(channel_id=self._channels[topic], log_time=log_time_ns,
                                 publish_time=int(publish_time_ns or log_time_ns),
                                 data=bytes(data), sequence=self._sequence)
        self._stream.flush()     # a chunk the writer just closed reaches the OS at once
        self.topics[topic].message_count += 1
        self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
        self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)
        if self._chunk_opened is None:
            self._chunk_opened = self._clock()
        self.flush_if_due()

    def flush_if_due(self):
        """Close the open chunk when it has been open `chunk_period` seconds."""
        if self._chunk_opened is not None and \
                self._clock() - self._chunk_opened >= self.chunk_period:
            self.flush()

    def flush(self):
        """Close the open chunk, write it to the file, refresh metadata.yaml."""
        self._writer.flush()
        self._chunk_opened = None
        self.write_metadata()

    def write_metadata(self):
        """Write metadata.yaml for what is in the bag so far."""
        return write_metadata(self.directory, metadata_dict(
            list(self.topics.values()), self.file_name, self.start_ns or 0, self.end_ns or 0,
            self.compression))

    def close(self):
        """Finish the file (summary, indexes, footer) and the metadata."""
        if self.closed:
            return
        self.closed = True
        self._writer.finish()
        self._stream.close()
        self.write_metadata()


# ---------------------------------------------------------------------------- reading
def bag_file(directory):
    """Return the MCAP file of a bag directory (or of a bare .mcap path)."""
    if os.path.isfile(directory) and directory.endswith('.mcap'):
        return directory
    path = os.path.join(directory, METADATA_FILE)
    if not os.path.isfile(path):
        raise BagError(f'{directory} is not a bag: no {METADATA_FILE}')
    with open(path, encoding='utf-8') as stream:
        information = (yaml.safe_load(stream) or {}).get('rosbag2_bagfile_information', {})
    if information.get('storage_identifier') != 'mcap':
        raise BagError(f'{directory}: storage {information.get("storage_identifier")!r} is '
                       'not mcap')
    files = information.get('relative_file_paths') or []
    if len(files) != 1:
        raise BagError(f'{directory}: expected one storage file, metadata names {files}')
    return os.path.join(directory, os.path.basename(files[0]))


def is_complete(path):
    """Return whether an MCAP file ends with its footer magic (was closed properly)."""
    with open(path, 'rb') as stream:
        stream.seek(0, os.SEEK_END)
        if stream.tell() < 16:
            return False
        stream.seek(-8, os.SEEK_END)
        return stream.read(8) == b'\x89MCAP0\r\n'


def read_topics(directory):
    """Return {topic: TopicInfo} of a complete bag (from its MCAP summary)."""
    path = bag_file(directory)
    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    if summary is None:
        raise BagError(f'{path} has no summary (recover it first: helio record --recover)')
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    topics = {}
    for channel_id, channel in summary.channels.items():
        schema = summary.schemas[channel.schema_id]
        qos = yaml.safe_load(channel.metadata.get('offered_qos_profiles') or '[]') or []
        topics[channel.topic] = TopicInfo(channel.topic, schema.name, qos,
                                          channel.metadata.get('topic_type_hash', ''),
                                          counts.get(channel_id, 0))
    return topics


def changed_types(topics):
    """
    Return the recorded types whose definition differs from the installed one.

    ``{type_name: (recorded hash, installed hash)}`` for each of `topics` (TopicInfo) whose
    recorded RIHS01 type hash is not the installed interface's: their CDR bytes cannot be
    read with the installed message classes (a field was added or changed since).
    """
    changed = {}
    for topic in topics:
        installed = type_hash(topic.type_name)
        if topic.type_hash and installed and topic.type_hash != installed:
            changed[topic.type_name] = (topic.type_hash, installed)
    return changed


def describe_changed_types(changed):
    """One line naming the changed types of ``changed_types``, and what to do."""
    return (f"recorded with an older definition of {', '.join(sorted(changed))} (type hash "
            'differs from the installed one): the messages cannot be decoded; re-record the '
            'bag with this workspace')


def read_messages(directory, topics=None):
    """Yield (topic, type, log_time_ns, cdr bytes) of a complete bag in log-time order."""
    with open(bag_file(directory), 'rb') as stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages(topics=topics,
                                                             log_time_order=True):
            yield channel.topic, schema.name, message.log_time, message.data


def decode_messages(directory, topics=None):
    """Yield (topic, log_time_ns, message object) of a complete bag, decoded by rclpy."""
    from rclpy.serialization import deserialize_message
    recorded = read_topics(directory)
    changed = changed_types(info for name, info in recorded.items()
                            if topics is None or name in topics)
    if changed:
        raise BagError(f'{directory}: {describe_changed_types(changed)}')
    classes = {}
    for topic, type_name, log_time, data in read_messages(directory, topics):
        if type_name not in classes:
            classes[type_name] = message_class(type_name)
        yield topic, log_time, deserialize_message(data, classes[type_name])


def salvage_records(path):
    """
    Read an MCAP file as far as it is intact; return (schemas, channels, messages, complete).

    Uses ``mcap``'s streaming reader (no summary needed); stops at the first record that is
    cut off or corrupt, which after a crash is the chunk being written.
    """
    from mcap.records import Channel, Footer, Message, Schema
    schemas, channels, messages = {}, {}, []
    complete = False
    with open(path, 'rb') as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
                elif isinstance(record, Footer):
                    complete = True
        except Exception:   # noqa: B902 - a cut-off record raises whatever the parser meets
            pass
    return schemas, channels, messages, complete


def recover_bag(directory):
    """
    Make a bag that a crash left without summary and footer complete again.

    The intact records are rewritten into a new complete MCAP file (same schemas, channels,
    messages and chunking), which replaces the old one; metadata.yaml is rewritten from it.
    Return the number of messages kept (a complete bag is left as it is: None).
    """
    path = bag_file(directory)
    if is_complete(path):
        return None
    schemas, channels, messages, _ = salvage_records(path)
    temporary = path + '.recovering'
    with open(temporary, 'wb') as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD, index_types=IndexType.ALL)
        writer.start(profile='ros2', library='helio_control.bag_files recover (mcap)')
        schema_ids = {old: writer.register_schema(s.name, s.encoding, s.data)
                      for old, s in schemas.items()}
        channel_ids = {old: writer.register_channel(c.topic, c.message_encoding,
                                                    schema_ids[c.schema_id], dict(c.metadata))
                       for old, c in channels.items() if c.schema_id in schema_ids}
        for message in sorted(messages, key=lambda m: m.log_time):
            if message.channel_id in channel_ids:
                writer.add_message(channel_ids[message.channel_id], message.log_time,
                                   message.data, message.publish_time, message.sequence)
        writer.finish()
    os.replace(temporary, path)
    topics = list(read_topics(directory).values())
    times = [m.log_time for m in messages]
    write_metadata(directory, metadata_dict(topics, os.path.basename(path),
                                            min(times, default=0), max(times, default=0),
                                            'zstd'))
    return len(messages)


# ---------------------------------------------------------------------------- JSON beside
VIEW_FILE = 'view.mcap'


class JsonMcapWriter:
    """
    An MCAP file of JSON messages with JSON schemas (Foxglove's own schemas), beside a bag.

    MCAP allows other encodings than ROS 2's, but rosbags refuses a file that holds a
    ``jsonschema`` schema (KeyError 'jsonschema' in its MCAP index reader, rosbags 0.11.9),
    so these channels go into a second file of the bag directory (``VIEW_FILE``), which
    metadata.yaml does not name: rosbag2 and rosbags read the bag, Foxglove opens both files
    together, ``mcap`` reads either. Chunked like the bag: a chunk is closed after
    `chunk_period` seconds.
    """

    def __init__(self, path, chunk_size=1 << 20, chunk_period=2.0, compression='zstd',
                 clock=time.monotonic):
        """Create the file."""
        self.path = path
        self.chunk_period = chunk_period
        self._clock = clock
        self._stream = open(path, 'wb')
        self._writer = Writer(self._stream, chunk_size=chunk_size,
                              compression=COMPRESSIONS[compression], index_types=IndexType.ALL,
                              use_statistics=True, use_summary_offsets=True)
        self._writer.start(profile='', library='helio_control.bag_files (mcap)')
        self._schemas, self._channels = {}, {}
        self.counts = {}
        self._chunk_opened = None
        self.closed = False

    def add_topic(self, name, schema_name, json_schema):
        """Register a topic of JSON messages with its schema (bytes of a JSON schema)."""
        if name in self._channels:
            return
        if schema_name not in self._schemas:
            self._schemas[schema_name] = self._writer.register_schema(
                name=schema_name, encoding='jsonschema', data=bytes(json_schema))
        self._channels[name] = self._writer.register_channel(
            topic=name, message_encoding='json', schema_id=self._schemas[schema_name])
        self.counts[name] = 0

    def write(self, topic, log_time_ns, data):
        """Append one message (JSON bytes) of a registered topic."""
        self._writer.add_message(channel_id=self._channels[topic], log_time=int(log_time_ns),
                                 publish_time=int(log_time_ns), data=bytes(data),
                                 sequence=sum(self.counts.values()))
        self.counts[topic] += 1
        if self._chunk_opened is None:
            self._chunk_opened = self._clock()
        if self._clock() - self._chunk_opened >= self.chunk_period:
            self._writer.flush()         # close the chunk (as BagWriter.flush)
            self._stream.flush()
            self._chunk_opened = None

    def close(self):
        """Finish the file (summary, indexes, footer)."""
        if not self.closed:
            self.closed = True
            self._writer.finish()
            self._stream.close()
