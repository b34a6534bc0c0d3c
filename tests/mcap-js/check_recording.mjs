// An independent reader for idms recordings: @mcap/core (the MCAP project's own TypeScript
// library) reads the file twice, as a stream of records (every CRC and record checked) and through
// its index; every message is decoded with protobufjs from the FileDescriptorSet stored in the file
// itself (no .proto from this repository). Prints a JSON summary; exits 1 on any failure.
//   node check_recording.mjs FILE.mcap [--expect-ticks N]
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { readFile } from "node:fs/promises";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import { decompress } from "fzstd";

const [, , file, flag, value] = process.argv;
const expectTicks = flag === "--expect-ticks" ? Number(value) : undefined;
const fail = (message) => {
  console.error(`check_recording: ${file}: ${message}`);
  process.exit(1);
};
const bytes = new Uint8Array(await readFile(file));
const decompressHandlers = {
  zstd: (buffer, decompressedSize) => decompress(buffer, new Uint8Array(Number(decompressedSize))),
};

// 1. A stream of records: magic, CRCs, every record's framing.
const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(bytes);
let streamed = 0;
let footer = false;
for (let record; (record = stream.nextRecord()); ) {
  if (record.type === "Message") streamed++;
  if (record.type === "Footer") footer = true;
}
if (!stream.done()) fail("the stream reader did not reach the end magic");
if (!footer) fail("no footer");

// 2. Through the index; each schema a FileDescriptorSet that protobufjs turns into types.
const readable = {
  size: async () => BigInt(bytes.length),
  read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
};
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
const types = new Map();
for (const [id, schema] of reader.schemasById) {
  if (schema.encoding !== "protobuf") fail(`schema ${schema.name}: encoding ${schema.encoding}`);
  const set = descriptor.FileDescriptorSet.decode(schema.data);
  const root = protobuf.Root.fromDescriptor(set);
  types.set(id, root.lookupType(schema.name));
}
const counts = {};
const ticks = [];
let decoded = 0;
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  const type = types.get(channel.schemaId);
  const object = type.toObject(type.decode(message.data), { longs: Number });
  counts[channel.topic] = (counts[channel.topic] ?? 0) + 1;
  decoded++;
  if (channel.topic === "/device") for (const s of object.samples ?? []) ticks.push(s.tick ?? 0);
  if (channel.topic === "/mesh" && !object.mesh_keyframe && !object.mesh_delta) fail("a /mesh message that is no mesh frame");
}
if (decoded !== streamed) fail(`${decoded} messages through the index, ${streamed} in the stream`);
const statistics = reader.statistics ? Number(reader.statistics.messageCount) : undefined;
if (statistics !== undefined && statistics !== decoded) fail(`statistics say ${statistics} messages, read ${decoded}`);
for (let i = 1; i < ticks.length; i++) {
  if (ticks[i] <= ticks[i - 1]) fail(`tick ${ticks[i]} after ${ticks[i - 1]}: device ticks not strictly increasing`);
}
if (expectTicks !== undefined) {
  if (ticks.length !== expectTicks) fail(`${ticks.length} ticks, expected ${expectTicks}`);
  ticks.forEach((t, i) => {
    if (t !== i) fail(`tick ${i} is ${t}: not every tick once, in order`);
  });
}
const metadata = {};
for (const m of reader.metadataIndexes) metadata[m.name] = true;
console.log(JSON.stringify({ file, messages: decoded, counts, ticks: ticks.length, schemas: [...reader.schemasById.values()].map((s) => s.name), metadata: Object.keys(metadata) }));
