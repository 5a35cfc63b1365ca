"""Reading rosbag2 MCAP bags, ours or anyone's, including truncated and damaged ones.

A bag is a rosbag2 directory (``metadata.yaml`` naming one or more ``.mcap`` files) or a lone
``.mcap`` file. :class:`BagReader` walks the MCAP records in file order straight from a memory
map, so a bag whose summary was never written (a SIGKILLed recorder) reads as far as its data
goes. Where the data stops making sense (a record running past the end of the file, a chunk
whose CRC or compression is broken, an unknown opcode length) the reader notes a
:class:`Damage` with the byte offset, the reason and what is lost, and resumes at the next
intact record when the framing allows it.

Only the record framing is parsed here (MCAP specification, "Records"); message payloads stay CDR
bytes for the caller to decode.
"""

from __future__ import annotations

import mmap
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from gait_nodes.errors import GaitNodesError

MAGIC = b'\x89MCAP0\r\n'

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_METADATA = 0x0C
OP_DATA_END = 0x0F
_LAST_KNOWN_OPCODE = 0x0F

_RECORD_HEADER = struct.Struct('<BQ')
_MESSAGE_HEADER = struct.Struct('<HIQQ')
_CHUNK_HEADER = struct.Struct('<QQQI')
_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')


class NotABagError(GaitNodesError):
    """The path is neither a rosbag2 MCAP directory nor an MCAP file."""


@dataclass(frozen=True)
class Channel:
    """One MCAP channel with its schema.

    Attributes:
        id: Channel id in its file.
        topic: Topic name.
        message_encoding: 'cdr' for ROS 2.
        type_name: Schema name, ``pkg/msg/Name`` for ROS 2.
        schema_encoding: 'ros2msg' (or 'ros2idl') for ROS 2.
        schema_text: The schema data as text.
        metadata: Channel metadata (rosbag2: ``offered_qos_profiles``, ``topic_type_hash``).
    """

    id: int
    topic: str
    message_encoding: str
    type_name: str
    schema_encoding: str
    schema_text: str
    metadata: dict[str, str]

    def offered_qos(self) -> list[dict]:
        """The publishers' QoS profiles rosbag2 stored for this channel ([] if none)."""
        text = self.metadata.get('offered_qos_profiles', '')
        try:
            profiles = yaml.safe_load(text) if text else []
        except yaml.YAMLError:
            return []
        return profiles if isinstance(profiles, list) else []


@dataclass(frozen=True)
class Damage:
    """A place where the bag stops making sense.

    Attributes:
        file: The MCAP file.
        offset: Byte offset of the damaged record.
        reason: What is wrong there.
        lost_bytes: Bytes that could not be read because of it.
        lost_start_ns: First log time of what was lost, if known.
        lost_end_ns: Last log time of what was lost, if known.
    """

    file: Path
    offset: int
    reason: str
    lost_bytes: int
    lost_start_ns: int | None = None
    lost_end_ns: int | None = None

    def describe(self) -> str:
        """One line for a person."""
        span = ''
        if self.lost_start_ns is not None and self.lost_end_ns is not None:
            span = (f', messages logged from {self.lost_start_ns * 1e-9:.3f} s to '
                    f'{self.lost_end_ns * 1e-9:.3f} s')
        return (f'{self.file.name} at byte {self.offset}: {self.reason}; {self.lost_bytes} bytes '
                f'unreadable{span}')


@dataclass
class FileState:
    """What reading one MCAP file found besides messages."""

    path: Path
    size: int
    profile: str = ''
    library: str = ''
    complete: bool = False  # footer and closing magic seen: the writer finished cleanly
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)


def _safe_load(text: str):
    """``yaml.safe_load(text)``, parsed by libyaml when PyYAML was built with it.

    The metadata.yaml of a gait graph's bag (13 kB) takes 50 ms to parse in pure Python, a
    large part of inspecting a short bag, and 7 ms with libyaml. The constructor is the same
    (SafeLoader's), hence the same data; text libyaml refuses is parsed again in Python, so that
    an error is PyYAML's own, as before.
    """
    loader = getattr(yaml, 'CSafeLoader', None)
    if loader is not None:
        try:
            return yaml.load(text, Loader=loader)
        except yaml.YAMLError:
            pass
    return yaml.safe_load(text)


def bag_files(path: str | Path) -> tuple[list[Path], dict | None]:
    """The MCAP files of a bag and its parsed ``metadata.yaml`` (None for a lone file).

    Raises:
        NotABagError: With the path and what is missing or wrong.
    """
    path = Path(path)
    if not path.exists():
        raise NotABagError(f'{path}: no such file or directory')
    if path.is_file():
        with open(path, 'rb') as stream:
            head = stream.read(len(MAGIC))
        if head != MAGIC:
            raise NotABagError(f'{path}: not an MCAP file (no MCAP magic at the start)')
        return [path], None
    metadata = None
    metadata_path = path / 'metadata.yaml'
    if metadata_path.is_file():
        try:
            metadata = _safe_load(metadata_path.read_text(encoding='utf-8'))
        except (OSError, yaml.YAMLError) as exc:
            raise NotABagError(f'{metadata_path}: unreadable: {exc}'.splitlines()[0]) from exc
        info = (metadata or {}).get('rosbag2_bagfile_information') if isinstance(
            metadata, dict) else None
        if not isinstance(info, dict):
            raise NotABagError(f'{metadata_path}: no rosbag2_bagfile_information mapping')
        storage = info.get('storage_identifier', 'mcap')
        if storage != 'mcap':
            raise NotABagError(f'{path}: storage {storage!r} is not supported (only mcap)')
        names = info.get('relative_file_paths') or []
        files = [path / name for name in names if (path / name).is_file()]
        if not files:
            files = sorted(path.glob('*.mcap'))
    else:
        files = sorted(path.glob('*.mcap'))
    if not files:
        raise NotABagError(f'{path}: not a bag (no metadata.yaml naming .mcap files, no .mcap '
                           f'file in it)')
    for file in files:
        with open(file, 'rb') as stream:
            if stream.read(len(MAGIC)) != MAGIC:
                raise NotABagError(f'{file}: not an MCAP file (no MCAP magic at the start)')
    return files, metadata


def _string(buffer, offset: int) -> tuple[str, int]:
    (length,) = _U32.unpack_from(buffer, offset)
    start = offset + 4
    return bytes(buffer[start:start + length]).decode('utf-8'), start + length


def _string_map(buffer, offset: int) -> tuple[dict[str, str], int]:
    (length,) = _U32.unpack_from(buffer, offset)
    position, end = offset + 4, offset + 4 + length
    result = {}
    while position < end:
        key, position = _string(buffer, position)
        value, position = _string(buffer, position)
        result[key] = value
    return result, end


def _decompress(compression: str, data, size: int) -> bytes:
    if compression == '':
        return bytes(data)
    if compression == 'zstd':
        import zstandard

        return zstandard.ZstdDecompressor().decompress(bytes(data), max_output_size=size)
    if compression == 'lz4':
        import lz4.frame

        return lz4.frame.decompress(bytes(data))
    raise ValueError(f'unsupported chunk compression {compression!r}')


class BagReader:
    """Iterates the messages of a bag in file order, surviving damage.

    Args:
        path: Bag directory or ``.mcap`` file.

    Raises:
        NotABagError: The path is not a bag.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.files, self.metadata = bag_files(self.path)
        self.channels: dict[tuple[int, int], Channel] = {}
        self.damage: list[Damage] = []
        self.file_states: list[FileState] = []
        self._schemas: dict[tuple[int, int], tuple[str, str, str]] = {}
        self._reported = 0

    @property
    def total_bytes(self) -> int:
        """Size of all MCAP files [bytes]."""
        return sum(f.stat().st_size for f in self.files)

    def messages(self, topics: Iterable[str] | None = None,
                 progress: Callable[[int], None] | None = None,
                 ) -> Iterator[tuple[Channel, int, int, bytes]]:
        """Yield ``(channel, log_time_ns, publish_time_ns, cdr_bytes)`` in file order.

        Args:
            topics: Only these topics (all when None).
            progress: Called with the number of bytes consumed since the last call.

        Damage found on the way is in :attr:`damage` once the iteration ends.
        """
        self.damage = []
        self.file_states = []
        wanted = set(topics) if topics is not None else None
        for index, file in enumerate(self.files):
            yield from self._file_messages(index, file, wanted, progress)

    def _channel(self, file_index: int, channel_id: int) -> Channel | None:
        return self.channels.get((file_index, channel_id))

    def _add_schema(self, file_index: int, buffer, offset: int) -> None:
        (schema_id,) = _U16.unpack_from(buffer, offset)
        name, position = _string(buffer, offset + 2)
        encoding, position = _string(buffer, position)
        (length,) = _U32.unpack_from(buffer, position)
        data = bytes(buffer[position + 4:position + 4 + length]).decode('utf-8', 'replace')
        self._schemas[(file_index, schema_id)] = (name, encoding, data)

    def _add_channel(self, file_index: int, buffer, offset: int) -> None:
        channel_id, schema_id = struct.unpack_from('<HH', buffer, offset)
        topic, position = _string(buffer, offset + 4)
        encoding, position = _string(buffer, position)
        metadata, _ = _string_map(buffer, position)
        name, schema_encoding, schema_text = self._schemas.get(
            (file_index, schema_id), ('', '', ''))
        self.channels[(file_index, channel_id)] = Channel(
            channel_id, topic, encoding, name, schema_encoding, schema_text, metadata)

    def _records(self, file_index: int, buffer, start: int, end: int, wanted, in_chunk: bool):
        """Messages in ``buffer[start:end]``; returns ``(offset reached, problem or None)``."""
        position = start
        try:
            while position < end:
                if position + 9 > end:
                    return position, f'{end - position} trailing bytes too short for a record'
                opcode, length = _RECORD_HEADER.unpack_from(buffer, position)
                body = position + 9
                if body + length > end:
                    return position, (f'record (opcode 0x{opcode:02x}) of {length} bytes runs '
                                      f'past the end of the {"chunk" if in_chunk else "file"}')
                if opcode == OP_MESSAGE:
                    channel_id, _, log_time, publish_time = _MESSAGE_HEADER.unpack_from(
                        buffer, body)
                    channel = self.channels.get((file_index, channel_id))
                    if channel is not None and (wanted is None or channel.topic in wanted):
                        yield (channel, log_time, publish_time,
                               bytes(buffer[body + 22:body + length]))
                elif opcode == OP_SCHEMA:
                    self._add_schema(file_index, buffer, body)
                elif opcode == OP_CHANNEL:
                    self._add_channel(file_index, buffer, body)
                elif not in_chunk:
                    if opcode == OP_CHUNK:
                        yield from self._chunk(file_index, buffer, body, length, wanted)
                    elif opcode == OP_HEADER:
                        state = self.file_states[-1]
                        state.profile, next_position = _string(buffer, body)
                        state.library, _ = _string(buffer, next_position)
                    elif opcode == OP_METADATA:
                        name, next_position = _string(buffer, body)
                        self.file_states[-1].metadata[name], _ = _string_map(buffer,
                                                                             next_position)
                    elif opcode == OP_FOOTER:
                        self.file_states[-1].complete = bytes(
                            buffer[body + length:body + length + 8]) == MAGIC
                        return body + length, None
                    elif opcode == 0 or opcode > 0x7F:
                        return position, f'invalid opcode 0x{opcode:02x}'
                position = body + length
        except (struct.error, UnicodeDecodeError) as exc:
            return position, f'malformed record ({exc})'
        return position, None

    def _chunk(self, file_index: int, buffer, body: int, length: int, wanted):
        start_ns, end_ns, size, crc = _CHUNK_HEADER.unpack_from(buffer, body)
        compression, position = _string(buffer, body + 28)
        (data_length,) = _U64.unpack_from(buffer, position)
        data = buffer[position + 8:position + 8 + data_length]
        try:
            records = _decompress(compression, data, size)
            if crc and zlib.crc32(records) != crc:
                raise ValueError('uncompressed CRC mismatch')
        except Exception as exc:  # noqa: BLE001 - any decoder failure is damage, reported
            self.damage.append(Damage(self.files[file_index], body - 9,
                                      f'chunk unreadable ({exc})', length + 9, start_ns, end_ns))
            return
        inner = self._records(file_index, records, 0, len(records), wanted, in_chunk=True)
        reached, problem = yield from inner
        if problem is not None:
            self.damage.append(Damage(self.files[file_index], body - 9, f'inside a chunk: '
                                      f'{problem}', len(records) - reached, start_ns, end_ns))

    def _file_messages(self, file_index: int, file: Path, wanted, progress):
        size = file.stat().st_size
        state = FileState(file, size)
        self.file_states.append(state)
        if size <= len(MAGIC):
            self.damage.append(Damage(file, 0, 'file holds no records', 0))
            return
        with open(file, 'rb') as stream, mmap.mmap(stream.fileno(), 0,
                                                   access=mmap.ACCESS_READ) as mapped:
            buffer = memoryview(mapped)
            try:
                reached, problem = yield from self._walk(file_index, buffer, size, wanted,
                                                         progress)
            finally:
                buffer.release()
        if progress is not None:
            progress(size - self._reported)
        if problem is not None:
            start_ns = end_ns = None
            if problem.startswith('record (opcode 0x06)') and reached + 9 + 16 <= size:
                with open(file, 'rb') as stream:
                    stream.seek(reached + 9)
                    start_ns, end_ns = struct.unpack('<QQ', stream.read(16))
            self.damage.append(Damage(file, reached, problem, size - reached, start_ns, end_ns))

    def _summary_channels(self, file_index, buffer, size) -> None:
        # A complete file repeats its schemas and channels in the summary section: read them
        # first, so that messages after a damaged chunk still have their channel.
        footer = size - len(MAGIC) - 29
        if footer < len(MAGIC) or bytes(buffer[size - len(MAGIC):]) != MAGIC:
            return
        opcode, length = _RECORD_HEADER.unpack_from(buffer, footer)
        if opcode != OP_FOOTER or length != 20:
            return
        (summary_start,) = _U64.unpack_from(buffer, footer + 9)
        position = summary_start
        while len(MAGIC) <= position < footer:
            opcode, length = _RECORD_HEADER.unpack_from(buffer, position)
            if position + 9 + length > footer:
                return
            if opcode == OP_SCHEMA:
                self._add_schema(file_index, buffer, position + 9)
            elif opcode == OP_CHANNEL:
                self._add_channel(file_index, buffer, position + 9)
            position += 9 + length

    def _walk(self, file_index, buffer, size, wanted, progress):
        # The data section: records until DataEnd (or the footer of a file without one).
        self._summary_channels(file_index, buffer, size)
        position = len(MAGIC)
        self._reported = 0
        while position < size:
            if position + 9 > size:
                return position, 'the file ends inside a record header (truncated)'
            opcode, length = _RECORD_HEADER.unpack_from(buffer, position)
            if position + 9 + length > size:
                return position, (f'record (opcode 0x{opcode:02x}) of {length} bytes runs past '
                                  f'the end of the file (truncated)')
            if opcode == OP_DATA_END:
                # The summary repeats schemas and channels; messages are all before it.
                return (yield from self._summary(file_index, buffer, position, size))
            end = position + 9 + length
            reached, problem = yield from self._records(file_index, buffer, position, end,
                                                        wanted, in_chunk=False)
            if problem is not None:
                return reached, problem
            if self.file_states[-1].complete:
                return reached, None
            position = end
            if progress is not None and position - self._reported > 1 << 20:
                progress(position - self._reported)
                self._reported = position
        return position, 'no footer: the writer did not finish (unclean stop)'

    def _summary(self, file_index, buffer, position, size):
        records = self._records(file_index, buffer, position, size, wanted=set(), in_chunk=False)
        reached, problem = yield from records
        if problem is None and not self.file_states[-1].complete:
            problem = 'the summary section ends without a footer'
        return reached, problem
