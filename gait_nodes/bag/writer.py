"""A rosbag2 directory writer: ``metadata.yaml`` (version 9) plus one MCAP file.

The MCAP file follows rosbag2's Jazzy MCAP storage: profile ``ros2``, schemas in ``ros2msg``
encoding (the definition and its dependencies separated by lines of 80 ``=``), messages in
``cdr``, channel metadata ``offered_qos_profiles`` and ``topic_type_hash``. The open chunk is
finished at least every ``flush_period_s`` of wall time, so a SIGKILL loses at most that much; a
clean ``close()`` writes the summary and ``metadata.yaml``.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import yaml
from mcap.writer import CompressionType, Writer

from gait_nodes.errors import ConfigError

ROS_DISTRO = 'jazzy'


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
        self._schemas: dict[str, int] = {}
        self.topics: dict[str, _Topic] = {}
        self.flush_period_s = flush_period_s
        self._last_flush = time.monotonic()
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
        self._writer.add_message(channel_id=entry.channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns or log_time_ns,
                                 sequence=entry.count)
        entry.count += 1
        self.message_count += 1
        if self.start_ns is None or log_time_ns < self.start_ns:
            self.start_ns = log_time_ns
        self.end_ns = max(self.end_ns, log_time_ns)
        now = time.monotonic()
        if now - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush_if_due(self) -> None:
        """Flush when the open chunk is older than ``flush_period_s`` (call it from a timer)."""
        if not self._closed and time.monotonic() - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Finish the open chunk and push it to the file."""
        self._writer.flush()
        self._last_flush = time.monotonic()

    def metadata(self) -> dict:
        """``metadata.yaml`` contents (rosbag2 version 9)."""
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
