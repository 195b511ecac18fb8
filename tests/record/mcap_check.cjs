// The independent reader of Reflex MCAP files for the tests: the reference MCAP
// implementation (@mcap/core) and the OMG IDL parser and CDR decoder of Foxglove
// (@foxglove/omgidl-parser, @foxglove/omgidl-serialization), installed in bringup/web/node_modules
// by bringup/setup.sh (npm ci). Nothing of Reflex's own reader is used here.
//
//   node mcap_check.cjs indexed FILE OUT.json   McapIndexedReader: footer, summary, chunk index, statistics;
//                                               every message decoded; the byte ranges it read
//   node mcap_check.cjs stream FILE OUT.json    McapStreamReader over the whole file; every message decoded;
//                                               the chunks in file order with their message counts
//   node mcap_check.cjs torn FILE OUT.json STEP McapStreamReader on every prefix of FILE whose length is a
//                                               multiple of STEP or within 1 byte of a top-level record
//                                               boundary: messages read before the data ran out
// Exit status 0 and the JSON in OUT.json, else 1 with the reason on stderr (a missing package is an
// error, never a skip). 64-bit integers (BigInt) are written as decimal strings, byte arrays as arrays.
"use strict";
const fs = require("fs");
const path = require("path");

function need(name) {
  const dirs = [process.env.REFLEX_WEB_MODULES, path.join(__dirname, "..", "..", "bringup", "web", "node_modules")];
  for (const d of dirs) {
    if (!d) continue;
    try {
      return require(require.resolve(name, { paths: [d] }));
    } catch (e) {
      /* try the next folder */
    }
  }
  throw new Error(`package ${name} not found in ${dirs.filter(Boolean).join(" or ")} (run npm ci in bringup/web)`);
}

const { McapIndexedReader, McapStreamReader } = need("@mcap/core");
const { parseIDL } = need("@foxglove/omgidl-parser");
const { MessageReader } = need("@foxglove/omgidl-serialization");
const fzstd = need("fzstd");
const lz4js = need("lz4js");

const decompressHandlers = {
  zstd: (buffer, size) => fzstd.decompress(buffer, new Uint8Array(Number(size))),
  lz4: (buffer) => Uint8Array.from(lz4js.decompress(buffer)),
};

function plain(value) {
  if (typeof value === "bigint") return value.toString();
  if (value instanceof Uint8Array || ArrayBuffer.isView(value)) return Array.from(value, plain);
  if (Array.isArray(value)) return value.map(plain);
  if (value instanceof Map) return Object.fromEntries([...value].map(([k, v]) => [String(k), plain(v)]));
  if (value && typeof value === "object") {
    const out = {};
    for (const [k, v] of Object.entries(value)) out[k] = plain(v);
    return out;
  }
  return value;
}

/** Decoder of the messages of one channel, from its schema (omgidl) and message encoding (cdr); the
 *  scene channels (message encoding json, schema encoding jsonschema) are parsed as JSON. */
function makeDecoder(schema, channel) {
  if (channel.messageEncoding === "json") {
    if (!schema || schema.encoding !== "jsonschema") throw new Error(`channel ${channel.topic}: json without a jsonschema`);
    return (data) => JSON.parse(new TextDecoder().decode(data));
  }
  if (channel.messageEncoding !== "cdr") throw new Error(`channel ${channel.topic}: encoding ${channel.messageEncoding}`);
  if (!schema || schema.encoding !== "omgidl") throw new Error(`channel ${channel.topic}: no omgidl schema`);
  const reader = new MessageReader(schema.name, parseIDL(new TextDecoder().decode(schema.data)));
  return (data) => reader.readMessage(data);
}

function messageJson(message, channel, schema, decode) {
  return {
    topic: channel.topic,
    schema: schema.name,
    sequence: message.sequence,
    log_time: message.logTime.toString(),
    publish_time: message.publishTime.toString(),
    msg: plain(decode(message.data)),
  };
}

async function indexed(file) {
  const bytes = fs.readFileSync(file);
  const reads = [];
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, size) => {
      reads.push([offset.toString(), size.toString()]);
      return bytes.subarray(Number(offset), Number(offset + size));
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const readsBeforeMessages = reads.length;
  const decoders = new Map();
  const messages = [];
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(m.channelId);
    const schema = reader.schemasById.get(channel.schemaId);
    if (!decoders.has(m.channelId)) decoders.set(m.channelId, makeDecoder(schema, channel));
    messages.push(messageJson(m, channel, schema, decoders.get(m.channelId)));
  }
  const st = reader.statistics;
  return {
    file_size: bytes.length,
    library: reader.header.library,
    profile: reader.header.profile,
    statistics: st && plain({
      message_count: st.messageCount,
      chunk_count: st.chunkCount,
      channel_count: st.channelCount,
      schema_count: st.schemaCount,
      message_start_time: st.messageStartTime,
      message_end_time: st.messageEndTime,
      channel_message_counts: st.channelMessageCounts,
    }),
    chunk_indexes: reader.chunkIndexes.map((c) =>
      plain({ offset: c.chunkStartOffset, length: c.chunkLength, compression: c.compression,
              start: c.messageStartTime, end: c.messageEndTime })),
    channels: [...reader.channelsById.values()].map((c) => {
      const schema = reader.schemasById.get(c.schemaId);
      const out = { id: c.id, topic: c.topic, encoding: c.messageEncoding, schema: schema.name,
                    schema_encoding: schema.encoding, metadata: Object.fromEntries(c.metadata) };
      if (schema.encoding === "jsonschema") out.schema_data = new TextDecoder().decode(schema.data);
      return out;
    }),
    reads_before_messages: reads.slice(0, readsBeforeMessages),
    reads,
    messages,
  };
}

/** Streams `bytes` through McapStreamReader; stops where the data runs out. */
function stream(bytes, decode) {
  const reader = new McapStreamReader({ includeChunks: true, decompressHandlers, validateCrcs: true });
  reader.append(bytes);
  const schemas = new Map();
  const channels = new Map();
  const decoders = new Map();
  const chunks = [];
  const messages = [];
  let count = 0;
  for (let r; (r = reader.nextRecord()); ) {
    if (r.type === "Schema") schemas.set(r.id, r);
    else if (r.type === "Channel") channels.set(r.id, r);
    else if (r.type === "Chunk") chunks.push({ messages: 0, compression: r.compression });
    else if (r.type === "Message") {
      ++count;
      if (chunks.length) chunks[chunks.length - 1].messages++;
      if (decode) {
        const channel = channels.get(r.channelId);
        const schema = schemas.get(channel.schemaId);
        if (!decoders.has(r.channelId)) decoders.set(r.channelId, makeDecoder(schema, channel));
        messages.push(messageJson(r, channel, schema, decoders.get(r.channelId)));
      }
    }
  }
  return { done: reader.done(), count, chunks, messages };
}

/** Offsets of the top-level records of a complete file (after the magic), read from their length fields. */
function recordBoundaries(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const out = [8];
  for (let at = 8; at + 9 <= bytes.length - 8; ) {
    at += 9 + Number(view.getBigUint64(at + 1, true));
    out.push(at);
  }
  return out;
}

async function main() {
  const [mode, file, outPath, stepText] = process.argv.slice(2);
  if (!mode || !file || !outPath) throw new Error("usage: mcap_check.cjs indexed|stream|torn FILE OUT.json [STEP]");
  let result;
  if (mode === "indexed") result = await indexed(file);
  else if (mode === "stream") {
    const bytes = fs.readFileSync(file);
    result = stream(bytes, true);
  } else if (mode === "torn") {
    const bytes = fs.readFileSync(file);
    const step = Number(stepText || 1);
    if (!(step >= 1)) throw new Error(`torn: bad STEP '${stepText}'`);
    const cuts = new Set();
    for (let n = 0; n <= bytes.length; n += step) cuts.add(n);
    for (const b of recordBoundaries(bytes)) for (const n of [b - 1, b, b + 1]) if (n >= 0 && n <= bytes.length) cuts.add(n);
    const counts = [];
    for (const n of [...cuts].sort((a, b) => a - b)) {
      try {
        counts.push([n, stream(bytes.subarray(0, n), false).count]);
      } catch (e) {
        counts.push([n, -1, String(e.message)]);  // a prefix must never make the reference reader fail
      }
    }
    result = { file_size: bytes.length, counts };
  } else throw new Error(`unknown mode '${mode}'`);
  fs.writeFileSync(outPath, JSON.stringify(result));
}

module.exports = { need, indexed };

if (require.main === module) {
  main().catch((e) => {
    process.stderr.write(`mcap_check: ${e && e.stack ? e.stack : e}\n`);
    process.exit(1);
  });
}
