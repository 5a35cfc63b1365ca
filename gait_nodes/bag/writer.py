"""A rosbag2 directory writer: ``metadata.yaml`` (version 9) plus one MCAP file.

The MCAP file follows rosbag2's Jazzy MCAP storage: profile ``ros2``, schemas in ``ros2msg``
encoding (the definition and its dependencies separated by lines of 80 ``=``), messages in
``cdr``, channel metadata ``offered_qos_profiles`` and ``topic_type_hash``. The open chunk is
finished at least every ``flush_period_s`` of wall time, so a SIGKILL loses at most that much; a
clean ``close()`` writes the summary and ``metadata.yaml``.
"""

from __future__ import annotations

import dataclasses
import io
import itertools
import struct
import time
from pathlib import Path

import yaml
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import CompressionType, Writer

from gait_nodes.errors import ConfigError

ROS_DISTRO = 'jazzy'
#: An MCAP Message record up to its data: opcode, record length, channel id, sequence, log time
#: and publish time (little endian, as mcap's RecordBuilder writes them).
_MESSAGE_RECORD = struct.Struct('<BQHIQQ')
#: Messages a BagWriter keeps before appending them to the MCAP chunk in one batch.
_PENDING_MAX = 256


class _MessageIndex(MessageIndex):
    """A MessageIndex record written with one ``pack`` (the bytes of ``MessageIndex.write``).

    mcap writes an index entry with two calls per message when it finishes a chunk.
    """

    def write(self, stream) -> None:
        records = self.records
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(records) * 16)
        stream.write(struct.pack(f'<{2 * len(records)}Q', *itertools.chain.from_iterable(records)))
        stream.finish_record()


def message_appender(writer: Writer):
    """A function doing what ``writer.add_message`` does, for many messages at once, or None.

    ``add_message`` builds a Message record object and writes it field by field, which is most
    of a recorder's cost per message. The function returned appends the same bytes to the open
    chunk, finishes chunks at the same messages and updates the same statistics and indexes
    (test_bags checks the files are the same byte for byte). It works on the Writer's private
    state, so with a mcap version laid out otherwise there is none and ``add_message`` is used.

    Returns:
        ``append(messages)`` taking a list of ``(channel_id, log_time, data, publish_time,
        sequence)``, or None.
    """
    try:
        statistics = writer._Writer__statistics
        chunks = writer._Writer__chunk_builder
        finish_chunk_if_full = writer._Writer__maybe_finalize_chunk
        chunk_size = writer._Writer__chunk_size
        counts, indexes = statistics.channel_message_counts, chunks.message_indices
        usable = isinstance(chunks.record_writer._buffer, io.BytesIO) and all(
            hasattr(statistics, name) for name in (
                'message_count', 'message_start_time', 'message_end_time')) and all(
            hasattr(chunks, name) for name in (
                'num_messages', 'message_start_time', 'message_end_time'))
    except AttributeError:
        return None
    if not usable:
        return None
    opcode = int(Opcode.MESSAGE)
    header = _MESSAGE_RECORD.pack

    def append(messages: list) -> None:
        # The statistics and chunk times, as Writer.add_message and ChunkBuilder.add_message
        # keep them, are updated per run of messages that goes into one chunk.
        end = len(messages)
        first = 0
        while first < end:
            buffer = chunks.record_writer._buffer  # replaced whenever a chunk is finished
            offset = buffer.tell()
            records = []
            count = statistics.message_count
            file_start, file_end = statistics.message_start_time, statistics.message_end_time
            chunk_count = chunks.num_messages
            chunk_start, chunk_end = chunks.message_start_time, chunks.message_end_time
            index = first
            while index < end:
                channel_id, log_time, data, publish_time, sequence = messages[index]
                index += 1
                if count == 0 or log_time < file_start:
                    file_start = log_time
                if log_time > file_end:
                    file_end = log_time
                if chunk_count == 0 or log_time < chunk_start:
                    chunk_start = log_time
                if log_time > chunk_end:
                    chunk_end = log_time
                count += 1
                chunk_count += 1
                counts[channel_id] += 1
                channel_index = indexes.get(channel_id)
                if channel_index is None:
                    channel_index = indexes[channel_id] = _MessageIndex(channel_id=channel_id,
                                                                        records=[])
                channel_index.records.append((log_time, offset))
                records.append(header(opcode, 22 + len(data), channel_id, sequence, log_time,
                                      publish_time))
                records.append(data)
                offset += _MESSAGE_RECORD.size + len(data)
                if offset > chunk_size:
                    break
            statistics.message_count = count
            statistics.message_start_time, statistics.message_end_time = file_start, file_end
            chunks.num_messages = chunk_count
            chunks.message_start_time, chunks.message_end_time = chunk_start, chunk_end
            buffer.writelines(records)
            if offset > chunk_size:
                finish_chunk_if_full()
            first = index

    return append


@dataclasses.dataclass
class _Topic:
    channel_id: int
    name: str
    type_name: str
    qos_yaml: list[dict]
    type_hash: str
    count: int = 0


class BagWriter:
    """Writes one rosbag2 bag; a context manager whose ``close()`` is safe to call twice.

    Args:
        path: Bag directory to create (must not exist).
        flush_period_s: Longest wall time [s] a message may stay in memory.
        chunk_size: Target uncompressed chunk size [bytes].
        compression: 'zstd', 'lz4' or 'none' (per chunk, as rosbag2's MCAP storage does).
    """

    def __init__(self, path: str | Path, flush_period_s: float = 0.5,
                 chunk_size: int = 1 << 20, compression: str = 'zstd'):
        self.path = Path(path)
        if self.path.exists():
            raise ConfigError(f'bag directory {self.path} exists already; not overwriting')
        try:
            self.path.mkdir(parents=True)
        except OSError as exc:
            raise ConfigError(f'cannot create bag directory {self.path}: {exc}') from exc
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'
        self._stream = open(self.mcap_path, 'wb')  # noqa: SIM115 - closed in close()
        kinds = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                 'none': CompressionType.NONE}
        if compression not in kinds:
            raise ConfigError(f'compression must be one of {", ".join(kinds)}, got '
                              f'{compression!r}')
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=kinds[compression])
        self._writer.start(profile='ros2', library=f'gait_nodes, {ROS_DISTRO}')
        self._append = message_appender(self._writer) or self._add_messages
        #: Messages written but not yet appended to the MCAP chunk, in order:
        #: ``(channel_id, log_time, data, publish_time, sequence)``.
        self._pending: list = []
        self._schemas: dict[str, int] = {}
        self.topics: dict[str, _Topic] = {}
        self.flush_period_s = flush_period_s
        #: Wall time (time.monotonic) at which the open chunk is due to be flushed [s].
        self._flush_at = time.monotonic() + flush_period_s
        self.start_ns: int | None = None
        self.end_ns = 0
        self.message_count = 0
        self._closed = False

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def add_topic(self, name: str, type_name: str, offered_qos: list[dict]) -> None:
        """Declare a topic (once) with its ``pkg/msg/Name`` type and offered QoS profiles."""
        from gait_nodes.interfaces import definition_text, type_hash

        if name in self.topics:
            return
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            schema_id = self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding='ros2msg',
                data=definition_text(type_name).encode())
        digest = type_hash(type_name)
        channel_id = self._writer.register_channel(
            topic=name, message_encoding='cdr', schema_id=schema_id,
            metadata={'offered_qos_profiles': yaml.safe_dump(offered_qos, sort_keys=False),
                      'topic_type_hash': digest})
        self.topics[name] = _Topic(channel_id, name, type_name, offered_qos, digest)

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: int | None = None) -> None:
        """Append one serialized message received at ``log_time_ns``."""
        entry = self.topics[topic]
        self._pending.append((entry.channel_id, log_time_ns, bytes(data),
                              publish_time_ns or log_time_ns, entry.count))
        entry.count += 1
        if len(self._pending) >= _PENDING_MAX or time.monotonic() >= self._flush_at:
            self._take_pending(flush_if_due=True)

    def topic_writer(self, topic: str, now_ns):
        """``write(data)`` doing ``self.write(topic, data, now_ns())``, for a recorder's callback.

        The recorder calls it for every message it receives, so it does the least: queue the
        message (the MCAP records are made for many messages at once, :meth:`_take_pending`)
        and check the flush period.
        """
        entry = self.topics[topic]
        channel_id = entry.channel_id
        pending = self._pending
        monotonic = time.monotonic

        def write(data: bytes) -> None:
            if data.__class__ is not bytes:
                data = bytes(data)
            log_time = now_ns()
            pending.append((channel_id, log_time, data, log_time, entry.count))
            entry.count += 1
            if len(pending) >= _PENDING_MAX or monotonic() >= self._flush_at:
                self._take_pending(flush_if_due=True)

        return write

    def _take_pending(self, flush_if_due: bool = False) -> None:
        """Append the pending messages to the MCAP chunk; then flush if ``flush_if_due``."""
        pending = self._pending
        if pending:
            self._append(pending)
            self.message_count += len(pending)
            log_times = [message[1] for message in pending]
            earliest = min(log_times)
            if self.start_ns is None or earliest < self.start_ns:
                self.start_ns = earliest
            self.end_ns = max(self.end_ns, max(log_times))
            pending.clear()
        if flush_if_due and time.monotonic() >= self._flush_at:
            self.flush()

    def _add_messages(self, messages: list) -> None:
        for channel_id, log_time, data, publish_time, sequence in messages:
            self._writer.add_message(channel_id=channel_id, log_time=log_time, data=data,
                                     publish_time=publish_time, sequence=sequence)

    def flush_if_due(self) -> None:
        """Flush when the open chunk is older than ``flush_period_s`` (call it from a timer)."""
        if not self._closed and time.monotonic() >= self._flush_at:
            self.flush()

    def flush(self) -> None:
        """Finish the open chunk and push it to the file."""
        self._take_pending()
        self._writer.flush()
        self._flush_at = time.monotonic() + self.flush_period_s

    def metadata(self) -> dict:
        """``metadata.yaml`` contents (rosbag2 version 9)."""
        self._take_pending()
        start = self.start_ns or 0
        duration = max(self.end_ns - start, 0)
        return {'rosbag2_bagfile_information': {
            'version': 9,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self.message_count,
            'topics_with_message_count': [
                {'topic_metadata': {
                    'name': t.name, 'type': t.type_name, 'serialization_format': 'cdr',
                    'offered_qos_profiles': t.qos_yaml, 'type_description_hash': t.type_hash},
                 'message_count': t.count}
                for t in self.topics.values()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.mcap_path.name],
            'files': [{'path': self.mcap_path.name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': self.message_count}],
            'custom_data': None,
            'ros_distro': ROS_DISTRO,
        }}

    def close(self) -> None:
        """Write the MCAP summary and ``metadata.yaml``; a second call does nothing."""
        if self._closed:
            return
        self._closed = True
        metadata = self.metadata()
        info = metadata['rosbag2_bagfile_information']
        self._writer.add_metadata('rosbag2', {
            'serialized_metadata': yaml.safe_dump(info, sort_keys=False),
            'ros_distro': ROS_DISTRO})
        self._writer.finish()
        self._stream.close()
        tmp = self.path / 'metadata.yaml.tmp'
        tmp.write_text(yaml.safe_dump(metadata, sort_keys=False), encoding='utf-8')
        tmp.replace(self.path / 'metadata.yaml')
