// An MCAP reader from another language: reads a .mcap with the Foxglove TypeScript libraries
// (@mcap/core for records, @foxglove/rosmsg to parse ros2msg schemas,
// @foxglove/rosmsg2-serialization to decode CDR) and prints one JSON summary:
// {"profile", "channels": {topic: {"schema", "encoding", "count", "metadata"}},
//  "decoded": N, "first": {topic: message as JSON}}.
// Usage: node read_mcap.mjs FILE.mcap
import { readFileSync } from 'node:fs';
import { McapStreamReader } from '@mcap/core';
import { parse } from '@foxglove/rosmsg';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { decompress } from 'fzstd';

const reader = new McapStreamReader({
  decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
  validateCrcs: true,
});
reader.append(readFileSync(process.argv[2]));
const schemas = new Map();
const channels = new Map();
const readers = new Map();
const summary = { profile: null, channels: {}, decoded: 0, first: {} };
const plain = (value) => JSON.parse(JSON.stringify(value, (key, v) =>
  typeof v === 'bigint' ? Number(v) : ArrayBuffer.isView(v) ? Array.from(v) : v));
for (let record; (record = reader.nextRecord()) !== undefined;) {
  if (record.type === 'Header') summary.profile = record.profile;
  if (record.type === 'Schema') schemas.set(record.id, record);
  if (record.type === 'Channel' && !channels.has(record.id)) {
    const schema = schemas.get(record.schemaId);
    channels.set(record.id, record);
    readers.set(record.id, new MessageReader(
      parse(new TextDecoder().decode(schema.data), { ros2: true })));
    summary.channels[record.topic] = {
      schema: schema.name, schemaEncoding: schema.encoding, encoding: record.messageEncoding,
      count: 0, metadata: Object.fromEntries(record.metadata),
    };
  }
  if (record.type === 'Message') {
    const channel = channels.get(record.channelId);
    const message = readers.get(record.channelId).readMessage(record.data);
    summary.channels[channel.topic].count += 1;
    summary.decoded += 1;
    if (!(channel.topic in summary.first)) summary.first[channel.topic] = plain(message);
  }
}
if (!reader.done()) throw new Error('the MCAP stream did not end cleanly');
console.log(JSON.stringify(summary));
