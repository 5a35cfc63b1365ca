"""A rosbag2 directory writer: ``metadata.yaml`` (version 9) plus one MCAP file.

The MCAP file follows rosbag2's Jazzy MCAP storage: profile ``ros2``, schemas in ``ros2msg``
encoding (the definition and its dependencies separated by lines of 80 ``=``), messages in
``cdr``, channel metadata ``offered_qos_profiles`` and ``topic_type_hash``. The open chunk is
finished at least every ``flush_period_s`` of wall time, so a SIGKILL loses at most that much
(and the few milliseconds a finished chunk takes to be compressed and written, on a thread of
its own, see :class:`ChunkThread`); a clean ``close()`` writes every chunk, the summary and
``metadata.yaml``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import itertools
import os
import queue
import shutil
import struct
import threading
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import yaml
from mcap import writer as mcap_writer
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import Chunk, ChunkIndex, DataEnd, Footer, MessageIndex
from mcap.writer import MCAP0_MAGIC, CompressionType, IndexType, Writer

from gait_nodes.errors import ConfigError, os_error_text

ROS_DISTRO = 'jazzy'
#: An MCAP Message record up to its data: opcode, record length, channel id, sequence, log time
#: and publish time (little endian, as mcap's RecordBuilder writes them).
_MESSAGE_RECORD = struct.Struct('<BQHIQQ')
#: Messages a BagWriter keeps before appending them to the MCAP chunk in one batch.
_PENDING_MAX = 256
#: Finished chunks waiting for the ChunkThread at most (then the writer waits for it).
_CHUNKS_QUEUED_MAX = 4


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


class ChunkThread:
    """Compresses and writes a Writer's finished chunks on a thread, in order.

    Compressing a chunk (zstd, ~1 MB) and its CRC take milliseconds of a recorder's thread,
    most of the bag's cost under the inproc runtime, where the recorder shares the thread of
    every node. Both release the GIL, so on a thread of their own they run on another core
    meanwhile. :meth:`attach` makes the Writer hand its chunks here: what the Writer's own
    chunk finishing (``Writer.__finalize_chunk``) did at once is split in two, the same steps
    in the same order, so the file has the same bytes (test_bags checks it against mcap's
    ``add_message``). On the caller's thread: the chunk's statistics, its records and message
    indexes taken from the ChunkBuilder, which starts the next chunk. On this thread:
    compression, CRC, the Chunk and MessageIndex records written to the stream and the
    ChunkIndex kept for the summary. Chunks are written in the order they were finished.

    :meth:`flush` asks for the stream to be flushed after the chunks finished before it;
    once it is, :attr:`flushed` holds the file offset reached and the flush's ``marker``.
    :meth:`stop` waits until all are written, after which chunks are written at once again
    (the summary the Writer's ``finish`` writes comes after every chunk). An error of the
    thread (a full disk) is raised by the next call made here; the jobs after it are dropped.
    """

    def __init__(self, writer: Writer, stream, compression: CompressionType,
                 message_indexes: bool):
        self._writer = writer
        self._stream = stream
        self._chunks = writer._Writer__chunk_builder
        self._statistics = writer._Writer__statistics
        self._chunk_indices = writer._Writer__chunk_indices
        self._records = writer._Writer__record_builder
        self._message_indexes = message_indexes
        if compression == CompressionType.ZSTD:
            # mcap compresses with zstandard.compress, which is this with a new context per call.
            self._compression, self._compress = 'zstd', mcap_writer.zstandard.ZstdCompressor(
                level=3).compress
        elif compression == CompressionType.LZ4:
            self._compression, self._compress = 'lz4', mcap_writer.lz4.frame.compress
        else:
            self._compression, self._compress = '', bytes
        self._queue: queue.Queue = queue.Queue(maxsize=_CHUNKS_QUEUED_MAX)
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._stopped = False
        #: ``(file offset, marker)`` of the last flush done: every byte before it was handed
        #: to the operating system.
        self.flushed: tuple[int, object] | None = None
        writer._Writer__finalize_chunk = self.finish_chunk

    @classmethod
    def attach(cls, writer: Writer, stream) -> ChunkThread | None:
        """A ChunkThread finishing ``writer``'s chunks (written to ``stream``), or None.

        None when ``writer`` does not have the private state of the mcap version this was
        written for (its chunks are then finished by the Writer itself, at once).
        """
        try:
            usable = (writer._Writer__chunk_builder is not None
                      and not writer._Writer__enable_data_crcs
                      and writer._Writer__enable_crcs
                      and writer._Writer__stream is stream
                      and hasattr(writer, '_Writer__finalize_chunk')
                      and isinstance(writer._Writer__chunk_indices, list)
                      and isinstance(writer._Writer__record_builder, RecordBuilder))
            compression = writer._Writer__compression
            index_types = writer._Writer__index_types
        except AttributeError:
            return None
        if not usable:
            return None
        return cls(writer, stream, compression, bool(index_types & IndexType.MESSAGE))

    def finish_chunk(self) -> None:
        """Take the open chunk from the Writer and have it written (the Writer calls this)."""
        self._raise_error()
        chunks = self._chunks
        if chunks.num_messages == 0:
            return
        self._statistics.chunk_count += 1
        job = (chunks.end(), chunks.message_start_time, chunks.message_end_time,
               list(chunks.message_indices.items()))
        chunks.reset()
        # Records the Writer buffered outside chunks go to the file before this chunk, as the
        # Writer's own chunk finishing writes them (there are none while messages are added).
        records = self._records.end()
        if records:
            self._submit(records)
        self._submit(job)

    def flush(self, marker: object = None) -> None:
        """Flush the stream once the chunks finished so far are written (see :attr:`flushed`)."""
        self._raise_error()
        self._submit(_Flush(marker))

    def stop(self) -> None:
        """Wait until every chunk is written; later chunks are written at once."""
        if self._thread is not None:
            self._queue.put(StopIteration)
            self._thread.join()
            self._thread = None
        self._stopped = True
        self._raise_error()

    def _submit(self, job) -> None:
        if self._stopped:
            self._do(job)
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name='mcap-chunks', daemon=True)
            self._thread.start()
        self._queue.put(job)

    def _run(self) -> None:
        while True:
            job = self._queue.get()
            if job is StopIteration:
                return
            if self._error is None:
                try:
                    self._do(job)
                except BaseException as exc:  # noqa: BLE001 - raised on the caller's thread
                    self._error = exc

    def _raise_error(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _do(self, job) -> None:
        stream = self._stream
        if isinstance(job, _Flush):
            stream.flush()
            self.flushed = (stream.tell(), job.marker)
            return
        if isinstance(job, bytes):
            stream.write(job)
            return
        data, start_time, end_time, message_indexes = job
        compressed = self._compress(data)
        builder = RecordBuilder()
        Chunk(compression=self._compression, data=compressed, message_start_time=start_time,
              message_end_time=end_time, uncompressed_crc=zlib.crc32(data),
              uncompressed_size=len(data)).write(builder)
        chunk_start = stream.tell()
        chunk_length = builder.count
        offsets = {}
        if self._message_indexes:
            for channel_id, index in message_indexes:
                offsets[channel_id] = chunk_start + builder.count
                index.write(builder)
        index_length = builder.count - chunk_length
        stream.write(builder.end())
        self._chunk_indices.append(ChunkIndex(
            message_start_time=start_time, message_end_time=end_time,
            chunk_start_offset=chunk_start, chunk_length=chunk_length,
            message_index_offsets=offsets, message_index_length=index_length,
            compression=self._compression, compressed_size=len(compressed),
            uncompressed_size=len(data)))


@dataclasses.dataclass(frozen=True)
class _Flush:
    """A ChunkThread job: flush the stream, then remember ``marker`` as flushed."""

    marker: object


@dataclasses.dataclass
class _Topic:
    channel_id: int
    name: str
    type_name: str
    qos_yaml: list[dict]
    type_hash: str
    count: int = 0


@dataclasses.dataclass(frozen=True)
class _Extent:
    """What a bag holds up to some point: message counts (per topic) and log-time span."""

    message_count: int
    start_ns: int | None
    end_ns: int
    counts: dict[str, int]


def _records_bytes(*records) -> bytes:
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return builder.end()


#: An MCAP ending without a summary section (DataEnd, a Footer with no summary, the magic):
#: what a bag whose writing failed gets after its last intact record, so that it is a
#: complete, unindexed MCAP file (readers scan it) rather than a cut-off one.
_UNINDEXED_END = b''.join([_records_bytes(DataEnd(data_section_crc=0),
                                          Footer(summary_start=0, summary_offset_start=0,
                                                 summary_crc=0)), MCAP0_MAGIC])


class BagWriter:
    """Writes one rosbag2 bag; a context manager whose ``close()`` is safe to call twice.

    A write that fails (a full disk, a directory made read-only or unwritable: any OSError)
    does not escape: the writer closes the bag at the last point it had flushed (at most
    ``flush_period_s`` back), so that the directory holds a complete MCAP file with every
    message written until then and a ``metadata.yaml`` that agrees with it; later messages
    are dropped. :attr:`error` and :attr:`failure` say what happened, and ``on_error`` is
    called once.

    Args:
        path: Bag directory to create (must not exist).
        flush_period_s: Longest wall time [s] a message may stay in memory.
        chunk_size: Target uncompressed chunk size [bytes].
        compression: 'zstd', 'lz4' or 'none' (per chunk, as rosbag2's MCAP storage does).
        background: Compress and write finished chunks on a thread (:class:`ChunkThread`);
            the file is the same.
        on_error: ``on_error(writer)``, called once when writing fails, after the bag was
            closed.
        open_file: ``open_file(path) -> binary file`` opening the MCAP file for writing
            (default ``open(path, 'wb')``).

    Raises:
        ConfigError: The directory exists, cannot be created, or the MCAP file cannot be
            started in it (nothing is left behind then).
    """

    def __init__(self, path: str | Path, flush_period_s: float = 0.5,
                 chunk_size: int = 1 << 20, compression: str = 'zstd', background: bool = True,
                 on_error: Callable[[BagWriter], None] | None = None,
                 open_file: Callable[[Path], BinaryIO] | None = None):
        self.path = Path(path)
        kinds = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                 'none': CompressionType.NONE}
        if compression not in kinds:
            raise ConfigError(f'compression must be one of {", ".join(kinds)}, got '
                              f'{compression!r}')
        if self.path.exists():
            raise ConfigError(f'bag directory {self.path} exists already; not overwriting')
        created = self.path  # the outermost directory made here, removed if the start fails
        while not created.parent.exists() and created.parent != created:
            created = created.parent
        try:
            self.path.mkdir(parents=True)
        except OSError as exc:
            raise ConfigError(f'cannot create bag directory {self.path}: '
                              f'{os_error_text(exc)}') from exc
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'
        self._stream = None
        try:
            self._stream = (open_file or _open_new)(self.mcap_path)
            self._writer = Writer(self._stream, chunk_size=chunk_size,
                                  compression=kinds[compression])
            self._writer.start(profile='ros2', library=f'gait_nodes, {ROS_DISTRO}')
            self._stream.flush()
        except OSError as exc:
            if self._stream is not None:
                with contextlib.suppress(OSError):
                    self._stream.close()
            shutil.rmtree(created, ignore_errors=True)
            raise ConfigError(f'cannot write bag file {self.mcap_path}: '
                              f'{os_error_text(exc)}') from exc
        self._append = message_appender(self._writer) or self._add_messages
        self._chunk_thread = ChunkThread.attach(self._writer, self._stream) \
            if background else None
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
        #: ``(file offset, _Extent)`` flushed without a ChunkThread (or before it flushed).
        self._flushed: tuple[int, _Extent] = (self._stream.tell(), self._extent())
        self._on_error = on_error
        #: The OSError that stopped the writing, if one did.
        self.error: OSError | None = None
        #: One line for a person: what failed, where, and what the bag holds.
        self.failure: str | None = None

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
        """Append one serialized message received at ``log_time_ns`` (dropped once closed)."""
        if self._closed:
            return
        entry = self.topics[topic]
        self._pending.append((entry.channel_id, log_time_ns, bytes(data),
                              publish_time_ns or log_time_ns, entry.count))
        entry.count += 1
        if len(self._pending) >= _PENDING_MAX or time.monotonic() >= self._flush_at:
            self._take_pending_or_fail()

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
            if self._closed:
                return
            if data.__class__ is not bytes:
                data = bytes(data)
            log_time = now_ns()
            pending.append((channel_id, log_time, data, log_time, entry.count))
            entry.count += 1
            if len(pending) >= _PENDING_MAX or monotonic() >= self._flush_at:
                self._take_pending_or_fail()

        return write

    def _take_pending_or_fail(self) -> None:
        try:
            self._take_pending(flush_if_due=True)
        except OSError as exc:
            self._fail(exc)

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

    def _extent(self) -> _Extent:
        """What the MCAP chunks hold so far (call after :meth:`_take_pending`)."""
        return _Extent(self.message_count, self.start_ns, self.end_ns,
                       {name: topic.count for name, topic in self.topics.items()})

    def flush_if_due(self) -> None:
        """Flush when the open chunk is older than ``flush_period_s`` (call it from a timer)."""
        if not self._closed and time.monotonic() >= self._flush_at:
            self.flush()

    def flush(self) -> None:
        """Finish the open chunk and push it to the file (with a ChunkThread: have it pushed)."""
        if self._closed:
            return
        try:
            self._take_pending()
            extent = self._extent()
            if self._chunk_thread is not None:
                self._chunk_thread.finish_chunk()
                self._chunk_thread.flush(extent)
            else:
                self._writer.flush()
                self._flushed = (self._stream.tell(), extent)
        except OSError as exc:
            self._fail(exc)
            return
        self._flush_at = time.monotonic() + self.flush_period_s

    def metadata(self, extent: _Extent | None = None) -> dict:
        """``metadata.yaml`` contents (rosbag2 version 9), of ``extent`` (default: everything)."""
        if extent is None:
            self._take_pending()
            extent = self._extent()
        start = extent.start_ns or 0
        duration = max(extent.end_ns - start, 0)
        return {'rosbag2_bagfile_information': {
            'version': 9,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': extent.message_count,
            'topics_with_message_count': [
                {'topic_metadata': {
                    'name': t.name, 'type': t.type_name, 'serialization_format': 'cdr',
                    'offered_qos_profiles': t.qos_yaml, 'type_description_hash': t.type_hash},
                 'message_count': extent.counts.get(t.name, 0)}
                for t in self.topics.values()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.mcap_path.name],
            'files': [{'path': self.mcap_path.name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': extent.message_count}],
            'custom_data': None,
            'ros_distro': ROS_DISTRO,
        }}

    def close(self) -> None:
        """Write the MCAP summary and ``metadata.yaml``; a second call does nothing."""
        if self._closed:
            return
        self.flush()  # every chunk flushed before the summary: a failure after it loses none
        if self._closed:
            return  # the flush failed and closed the bag
        metadata = self.metadata()
        try:
            if self._chunk_thread is not None:
                try:
                    self._chunk_thread.finish_chunk()
                finally:
                    self._chunk_thread.stop()  # every chunk written before the summary
            info = metadata['rosbag2_bagfile_information']
            self._writer.add_metadata('rosbag2', {
                'serialized_metadata': yaml.safe_dump(info, sort_keys=False),
                'ros_distro': ROS_DISTRO})
            self._writer.finish()
            self._stream.close()
        except OSError as exc:
            self._fail(exc)
            return
        except BaseException:
            self._closed = True
            self._stream.close()
            raise
        self._closed = True
        try:
            self._write_metadata(metadata)
        except OSError as exc:
            extent = self._extent()
            self._report_failure(exc, self.path / 'metadata.yaml', extent, extent.message_count,
                                 'the .mcap file is complete')

    def _write_metadata(self, metadata: dict) -> None:
        tmp = self.path / 'metadata.yaml.tmp'
        try:
            tmp.write_text(yaml.safe_dump(metadata, sort_keys=False), encoding='utf-8')
            tmp.replace(self.path / 'metadata.yaml')
        except OSError:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise

    def _durable(self) -> tuple[int, _Extent]:
        """``(offset, extent)`` of the last flush known done: the file holds it intact."""
        flushed = self._chunk_thread.flushed if self._chunk_thread is not None else None
        return flushed or self._flushed

    def _fail(self, error: OSError) -> None:
        """Close the bag after a failed write: its MCAP file and metadata.yaml as last flushed.

        Whatever came after the last flush (a partly written chunk, the summary) is cut off
        and the file ended without a summary (:data:`_UNINDEXED_END`); the truncation gives
        back the space a full disk needs for that and for ``metadata.yaml``. When even that
        cannot be written the file stays cut at the flush, as a killed recorder's would.
        """
        if self.error is not None:
            return
        self._closed = True
        accepted = self.message_count + len(self._pending)
        self._pending.clear()
        if self._chunk_thread is not None:
            with contextlib.suppress(Exception):
                self._chunk_thread.stop()  # its queued jobs are dropped after an error
        with contextlib.suppress(OSError):
            self._stream.close()  # the raw file is closed even when its flush fails
        offset, extent = self._durable()
        try:
            os.truncate(self.mcap_path, offset)
            with open(self.mcap_path, 'ab') as stream:
                stream.write(_UNINDEXED_END)
        except OSError:
            with contextlib.suppress(OSError):
                os.truncate(self.mcap_path, offset)
        note = ''
        try:
            self._write_metadata(self.metadata(extent))
        except OSError as exc:
            note = f'; metadata.yaml not written either: {os_error_text(exc)}'
        self._report_failure(error, self.mcap_path, extent, accepted, f'recording stopped{note}')

    def _report_failure(self, error: OSError, where: Path, extent: _Extent, accepted: int,
                        consequence: str) -> None:
        self.error = error
        self.message_count = extent.message_count
        self.failure = (f'cannot write {error.filename or where}: {os_error_text(error)}; '
                        f'{consequence}: {self.path} holds the {extent.message_count} '
                        f'messages written before it ({accepted - extent.message_count} '
                        f'lost)')
        if self._on_error is not None:
            self._on_error(self)


def _open_new(path: Path) -> BinaryIO:
    return open(path, 'xb')  # noqa: SIM115 - closed by BagWriter.close
