"""rosbag2 bags in MCAP storage, read and written without rosbag2 (which has no wheel).

A bag is either a rosbag2 directory (metadata.yaml + one or more .mcap files) or a
bare .mcap file. Messages stay CDR bytes end to end: nothing here decodes them.
What is written follows rosbag2 for Jazzy (metadata version 9) and the MCAP `ros2`
profile: schema encoding `ros2msg` (definition plus dependencies), message encoding
`cdr`, offered QoS profiles in each channel's metadata, and the bag metadata also
stored in the file as an MCAP metadata record named `rosbag2`, as rosbag2 does.
Writing is durable: BagWriter.flush puts every message so far on the disk in complete chunks and keeps
metadata.yaml current, so a writer killed at any moment leaves a bag whose messages up to its last flush
BagReader reads back: a file that ends in an unfinished record (no summary, no footer) is read as far as
its records are complete, as the MCAP tools' `recover` does, and `BagReader.unfinished` says what was cut.
No rclpy here; the ROS side (QoS objects, publishing) is in tools/bag.py.
"""
import copy
import heapq
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from mvpose_nodes.io.interfaces import full_type_name, schema_text, type_hash


class BagError(ValueError):
    """A bag that is missing, damaged or not rosbag2 MCAP, or an output that exists; the message names the path."""


METADATA_FILE = 'metadata.yaml'
METADATA_VERSION = 9  # rosbag2 in Jazzy
ROS_DISTRO = 'jazzy'
SERIALIZATION_FORMAT = 'cdr'
CHUNK_SIZE = 4 * 1024 * 1024  # [bytes] large enough for a few 1080p JPEGs per chunk
MCAP_MAGIC = b'\x89MCAP0\r\n'

# A QoS profile as rosbag2 stores it (metadata version 9 spelling). Durations are {sec, nsec};
# 0/0 means "the middleware's default", as in rclpy.
DEFAULT_QOS_PROFILE = {
    'history': 'keep_last', 'depth': 10, 'reliability': 'reliable', 'durability': 'volatile',
    'deadline': {'sec': 0, 'nsec': 0}, 'lifespan': {'sec': 0, 'nsec': 0},
    'liveliness': 'automatic', 'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
    'avoid_ros_namespace_conventions': False,
}


@dataclass
class TopicInfo:
    """One topic of a bag: its type, message count and the QoS its publishers offered."""
    name: str
    type: str
    message_count: int = 0
    offered_qos_profiles: list = field(default_factory=list)
    serialization_format: str = SERIALIZATION_FORMAT


@dataclass
class Recovery:
    """What was read of an unfinished MCAP file (its writer killed before it closed the file)."""
    messages: int       # messages read back: those of every complete chunk
    cut_bytes: int      # bytes after the last complete record (an unfinished chunk or index), unreadable


class UnfinishedScan:
    """An MCAP file read record by record from its start for as long as its records are complete:
    `for schema, channel, message in scan` yields every message of its complete chunks, in file order;
    then `recovery` says how many and what was cut. Any failure of the parser is where the file stops
    (an unfinished record, or the end of the file where the footer should be)."""

    def __init__(self, stream, size):
        self.stream, self.size = stream, size
        self.schemas, self.channels = {}, {}
        self.recovery = None

    def __iter__(self):
        self.stream.seek(0)
        complete_end, count = 0, 0
        try:
            for record in StreamReader(self.stream).records:
                if isinstance(record, Schema):
                    self.schemas[record.id] = record
                elif isinstance(record, Channel):
                    self.channels[record.id] = record
                elif isinstance(record, Message):
                    count += 1
                    yield self.schemas.get(self.channels[record.channel_id].schema_id), \
                        self.channels[record.channel_id], record
                complete_end = self.stream.tell()
        except Exception:  # noqa: BLE001, S110 (see the class docstring)
            pass
        self.recovery = Recovery(count, max(self.size - complete_end, 0))


@dataclass
class RecoveredStatistics:
    """The part of an MCAP Statistics record BagReader reads, counted from an unfinished file's messages."""
    message_count: int
    channel_message_counts: dict
    message_start_time: int
    message_end_time: int


@dataclass
class RecoveredSummary:
    """The part of an MCAP Summary BagReader reads, for an unfinished file."""
    schemas: dict
    channels: dict
    statistics: RecoveredStatistics


def dump_qos_profiles(profiles):
    return yaml.safe_dump(list(profiles), default_flow_style=False, sort_keys=False)


def parse_qos_profiles(text):
    """The offered QoS profiles of a channel's metadata; [] when absent or unreadable."""
    try:
        profiles = yaml.safe_load(text) if isinstance(text, str) else text
    except yaml.YAMLError:
        return []
    return [p for p in profiles if isinstance(p, dict)] if isinstance(profiles, list) else []


class BagWriter:
    """Write a rosbag2 directory: `<dir>/metadata.yaml` and `<dir>/<dir name>_0.mcap`.

    Usage: `with BagWriter(path) as bag: bag.add_topic(...); bag.write(topic, cdr, t_ns)`.
    The directory must not exist yet (as with `ros2 bag record -o`).
    """

    def __init__(self, directory, compression=CompressionType.ZSTD, file_name=None):
        self.directory = Path(directory)
        if self.directory.exists():
            raise BagError(f"output bag '{self.directory}' already exists; choose another -o or remove it")
        self.directory.mkdir(parents=True)
        self.file_name = file_name or f'{self.directory.name}_0.mcap'
        self._stream = open(self.directory / self.file_name, 'wb')
        self._writer = Writer(self._stream, chunk_size=CHUNK_SIZE, compression=compression)
        self._writer.start(profile='ros2', library='mvpose')
        self._schemas = {}
        self._topics = {}
        self._channels = {}
        self._sequence = 0
        self._start_ns = None
        self._end_ns = None
        self.flush()

    def add_topic(self, topic, type_name, offered_qos_profiles=(DEFAULT_QOS_PROFILE,)):
        """Register a topic before writing its messages; a second call for it is a no-op. Missing keys
        of the offered QoS profiles (dicts as in DEFAULT_QOS_PROFILE) take their default values."""
        if topic in self._topics:
            return
        type_name = full_type_name(type_name)
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding='ros2msg', data=schema_text(type_name).encode())
        # Complete profiles (readers such as rosbags require every key); no shared dicts (YAML would alias them).
        profiles = [copy.deepcopy({**DEFAULT_QOS_PROFILE, **profile}) for profile in offered_qos_profiles]
        self._channels[topic] = self._writer.register_channel(
            topic=topic, message_encoding=SERIALIZATION_FORMAT, schema_id=self._schemas[type_name],
            metadata={'offered_qos_profiles': dump_qos_profiles(profiles)})
        self._topics[topic] = TopicInfo(topic, type_name, 0, profiles)

    def write(self, topic, data, log_time_ns, publish_time_ns=None):
        """Store one message's CDR bytes; `log_time_ns` is when it was received [ns since epoch]."""
        self._writer.add_message(channel_id=self._channels[topic], log_time=log_time_ns, data=bytes(data),
                                 publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
                                 sequence=self._sequence)
        self._sequence += 1
        self._topics[topic].message_count += 1
        self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns, log_time_ns)
        self._end_ns = log_time_ns if self._end_ns is None else max(self._end_ns, log_time_ns)

    def flush(self):
        """Finish the chunk in progress, put everything written so far on the disk (fsync) and rewrite
        metadata.yaml (atomically): a writer killed after this leaves every message so far readable."""
        self._writer.flush()
        os.fsync(self._stream.fileno())
        self._write_metadata()

    def _write_metadata(self):
        temporary = self.directory / f'.{METADATA_FILE}.tmp'
        temporary.write_text(yaml.safe_dump(self.metadata(), default_flow_style=False, sort_keys=False))
        os.replace(temporary, self.directory / METADATA_FILE)

    def metadata(self):
        start = self._start_ns or 0
        duration = (self._end_ns or 0) - start
        count = sum(t.message_count for t in self._topics.values())
        return {'rosbag2_bagfile_information': {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': t.name, 'type': t.type, 'serialization_format': t.serialization_format,
                                    'offered_qos_profiles': t.offered_qos_profiles,
                                    'type_description_hash': type_hash(t.type)},
                 'message_count': t.message_count}
                for t in self._topics.values()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.file_name],
            'files': [{'path': self.file_name, 'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration}, 'message_count': count}],
            'custom_data': None,
            'ros_distro': ROS_DISTRO,
        }}

    def close(self):
        """Finish the MCAP file (summary, indexes) and write metadata.yaml. Safe to call twice."""
        if self._stream.closed:
            return
        metadata = self.metadata()
        self._writer.add_metadata('rosbag2', {'serialized_metadata': yaml.safe_dump(
            metadata['rosbag2_bagfile_information'], default_flow_style=False, sort_keys=False),
            'ros_distro': ROS_DISTRO})
        self._writer.finish()
        self._stream.close()
        self._write_metadata()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class BagReader:
    """Read a rosbag2 MCAP directory or a bare .mcap file.

    Every problem with the input is a BagError with a one-line message naming the path.
    Attributes after opening: `topics` {name: TopicInfo}, `start_ns`, `end_ns`,
    `message_count`, `files` (the .mcap paths), `metadata` (metadata.yaml content or {}),
    `unfinished` {mcap path: Recovery} of the files read only as far as their records are complete.
    """

    def __init__(self, path):
        self.path = Path(path)
        self.metadata = {}
        self.unfinished = {}
        self.files = self._find_files()
        self.topics = {}
        self.start_ns = None
        self.end_ns = None
        for mcap_path in self.files:
            self._add_summary(mcap_path)
        self.message_count = sum(t.message_count for t in self.topics.values())
        self.start_ns = self.start_ns or 0
        self.end_ns = self.end_ns or self.start_ns

    @property
    def duration_ns(self):
        return self.end_ns - self.start_ns

    def metadata_disagreements(self):
        """Where metadata.yaml says other than the MCAP files (which the reader follows): ['<topic>: ...'],
        empty when they agree, when there is no metadata.yaml, or for an unfinished bag (whose metadata is
        behind its messages by design)."""
        if not self.metadata or self.unfinished:
            return []
        listed = {}
        for entry in self.metadata.get('topics_with_message_count') or []:
            try:
                listed[entry['topic_metadata']['name']] = (entry['topic_metadata']['type'], entry['message_count'])
            except (KeyError, TypeError):
                return [f'{METADATA_FILE} has a malformed topics_with_message_count entry']
        found = {name: (topic.type, topic.message_count) for name, topic in self.topics.items()}
        problems = [f'{name}: listed, not in the MCAP' for name in sorted(listed.keys() - found.keys())]
        problems += [f'{name}: in the MCAP, not listed' for name in sorted(found.keys() - listed.keys())]
        problems += [f'{name}: {listed[name][0]} × {listed[name][1]} listed, {found[name][0]} × {found[name][1]} in the MCAP'
                     for name in sorted(listed.keys() & found.keys()) if listed[name] != found[name]]
        if self.metadata.get('message_count') not in (None, self.message_count):
            problems.append(f"message_count {self.metadata['message_count']} listed, {self.message_count} in the MCAP")
        return problems

    def _find_files(self):
        if not self.path.exists():
            raise BagError(f"bag '{self.path}': no such file or directory")
        if self.path.is_file():
            return [self.path]
        metadata_path = self.path / METADATA_FILE
        if metadata_path.is_file():
            try:
                self.metadata = yaml.safe_load(metadata_path.read_text())['rosbag2_bagfile_information']
                names = self.metadata['relative_file_paths']
            except (yaml.YAMLError, KeyError, TypeError):
                raise BagError(f"bag '{self.path}': {METADATA_FILE} is not rosbag2 metadata") from None
            storage = self.metadata.get('storage_identifier', 'mcap')
            if storage != 'mcap':
                raise BagError(f"bag '{self.path}': storage '{storage}' is not supported (only mcap)")
            files = [self.path / name for name in names]
            missing = [str(f) for f in files if not f.is_file()]
            if missing:
                raise BagError(f"bag '{self.path}': {METADATA_FILE} lists missing file(s): {', '.join(missing)}")
            return files
        files = sorted(self.path.glob('*.mcap'))
        if not files:
            raise BagError(f"bag '{self.path}': not a rosbag2 bag (no {METADATA_FILE} and no .mcap file)")
        return files

    def _summary(self, mcap_path, stream):
        """The file's summary; scanning the whole file when it has none, and reading it as far as its
        records are complete when it ends unfinished (_recovered_summary)."""
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagError(f"'{mcap_path}' is not an MCAP file (it does not start with the MCAP magic bytes)")
        stream.seek(0)
        try:
            reader = make_reader(stream)
            profile = reader.get_header().profile
            if profile not in ('ros2', ''):
                raise BagError(f"'{mcap_path}': MCAP profile '{profile}' is not ros2")
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                stream.seek(0)
                scanning = NonSeekingReader(stream)
                for _ in scanning.iter_messages():
                    pass
                summary = scanning.get_summary()
            return summary
        except BagError:
            raise
        except Exception:  # noqa: BLE001: no footer or a damaged end; read what is complete
            return self._recovered_summary(mcap_path, stream)

    def _recovered_summary(self, mcap_path, stream):
        """The summary of an unfinished file, from its complete records (UnfinishedScan); BagError when
        not even its header is complete."""
        try:
            stream.seek(0)
            reader = make_reader(stream)
            reader.get_header()
        except Exception as error:  # noqa: BLE001 (as _summary)
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise BagError(f"'{mcap_path}' is truncated or damaged ({reason})") from None
        scan = UnfinishedScan(stream, os.fstat(stream.fileno()).st_size)
        counts, start, end = {}, None, None
        for _, channel, message in scan:
            counts[channel.id] = counts.get(channel.id, 0) + 1
            start = message.log_time if start is None else min(start, message.log_time)
            end = message.log_time if end is None else max(end, message.log_time)
        self.unfinished[mcap_path] = scan.recovery
        return RecoveredSummary(scan.schemas, scan.channels,
                                RecoveredStatistics(sum(counts.values()), counts, start or 0, end or 0))

    def _add_summary(self, mcap_path):
        with open(mcap_path, 'rb') as stream:
            summary = self._summary(mcap_path, stream)
        if summary is None or summary.statistics is None:
            raise BagError(f"'{mcap_path}' is not a readable MCAP file (no summary or statistics)")
        counts = summary.statistics.channel_message_counts
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            if channel.message_encoding != SERIALIZATION_FORMAT or schema is None:
                raise BagError(f"'{mcap_path}': topic '{channel.topic}' is not CDR with a ros2msg schema")
            info = self.topics.setdefault(channel.topic, TopicInfo(
                channel.topic, full_type_name(schema.name), 0,
                parse_qos_profiles(channel.metadata.get('offered_qos_profiles', ''))))
            info.message_count += counts.get(channel_id, 0)
        if summary.statistics.message_count:
            stats = summary.statistics
            self.start_ns = stats.message_start_time if self.start_ns is None else min(self.start_ns, stats.message_start_time)
            self.end_ns = stats.message_end_time if self.end_ns is None else max(self.end_ns, stats.message_end_time)

    def messages(self, topics=None, start_ns=None):
        """Yield (TopicInfo, log_time_ns, cdr_bytes) in log-time order, optionally filtered."""
        wanted = None if topics is None else list(topics)
        streams = [open(path, 'rb') for path in self.files]
        try:
            per_file = [self._file_messages(path, stream, wanted, start_ns)
                        for path, stream in zip(self.files, streams)]
            yield from heapq.merge(*per_file, key=lambda item: item[1])
        finally:
            for stream in streams:
                stream.close()

    def _file_messages(self, path, stream, topics, start_ns):
        if path in self.unfinished:   # file order (the order they were written), as far as complete
            for _, channel, message in UnfinishedScan(stream, os.fstat(stream.fileno()).st_size):
                if (topics is None or channel.topic in topics) and (start_ns is None or message.log_time >= start_ns):
                    yield self.topics[channel.topic], message.log_time, message.data
            return
        try:
            for _, channel, message in make_reader(stream).iter_messages(
                    topics=topics, start_time=start_ns, log_time_order=True):
                yield self.topics[channel.topic], message.log_time, message.data
        except Exception as error:  # noqa: BLE001: any parser failure here means a damaged file
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise BagError(f"'{path}' is damaged: reading messages failed ({reason})") from None


def reindex(directory):
    """Rewrite a bag directory's .mcap file complete (its summary and indexes) from the messages a
    BagReader reads in it (all of a finished file; those of the complete chunks of an unfinished one),
    and its metadata.yaml from that file, as `ros2 bag reindex` does. Returns the file's Recovery
    (None when the file was finished). Bags of one .mcap file, as BagWriter writes them."""
    directory = Path(directory)
    if not directory.is_dir():
        raise BagError(f"bag '{directory}': reindex needs a bag directory")
    files = sorted(directory.glob('*.mcap'))
    if len(files) != 1:
        raise BagError(f"bag '{directory}': reindex handles a bag of one .mcap file (it has {len(files)})")
    reader = BagReader(files[0])
    staging = directory / '.reindex'
    if staging.exists():
        shutil.rmtree(staging)
    with BagWriter(staging, file_name=files[0].name) as writer:
        for topic in reader.topics.values():
            writer.add_topic(topic.name, topic.type, topic.offered_qos_profiles or (DEFAULT_QOS_PROFILE,))
        for topic, log_time, data in reader.messages():
            writer.write(topic.name, data, log_time)
    os.replace(staging / files[0].name, files[0])
    os.replace(staging / METADATA_FILE, directory / METADATA_FILE)
    staging.rmdir()
    return reader.unfinished.get(files[0])


def directory_size(path):
    """[bytes] of a bag directory or file, for `bag info`."""
    path = Path(path)
    if path.is_file():
        return path.stat().st_size
    return sum(os.path.getsize(p) for p in path.rglob('*') if p.is_file())
