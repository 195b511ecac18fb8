// Foxglove WebSocket client check of reflex_view: the protocol's reference client
// (@foxglove/ws-protocol FoxgloveClient, over the `ws` package: Node has no global WebSocket before 22)
// connects to a running reflex_view, subscribes to every channel and measures, over --seconds:
//   - messages per second per channel (from its first message on);
//   - the capsules and spheres of the robot in each /reflex/scene message, against counts taken from
//     the URDF text here (each <collision> element: <cylinder> or <box> = one capsule = 1 cylinder and 2
//     spheres, <sphere> = 1 sphere), independent of the C++ scene builder;
//   - the transforms of each /tf message against the URDF's <link> count - 1;
//   - every message against its channel's advertised JSON schema (scene_check_lib.js: every key must be
//     a schema property with the schema's type, enums/consts respected);
//   - protocol behaviour: a subscription to an unknown channel gets a status error; after unsubscribe
//     no more messages arrive on that subscription.
//   - the subprotocol handshake: plain `ws` clients offering several lists (the server must answer
//     with the first one it serves, foxglove.sdk.v1 or foxglove.websocket.v1, or refuse with HTTP 400).
// --subprotocols A,B: what the measuring client offers (default: the package's foxglove.websocket.v1).
// Prints one JSON line with the results (the C++ test asserts on it). Exit 1 if it cannot connect.
// Usage: node ws_client_check.js --url ws://127.0.0.1:PORT --urdf FILE --modules DIR [--seconds S]
//        [--subprotocols LIST]
"use strict";
const fs = require("fs");
const path = require("path");

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, "")] = process.argv[i + 1];
for (const k of ["url", "urdf", "modules"]) {
  if (!args[k]) { console.error(`ws_client_check: --${k} is required`); process.exit(2); }
}
const seconds = Number(args.seconds || 3);
const modules = path.resolve(args.modules);
const WebSocket = require(path.join(modules, "ws"));
const { FoxgloveClient } = require(path.join(modules, "@foxglove/ws-protocol"));

// ---- expected counts from the URDF text, and the schema check (scene_check_lib.js) ----
const { urdfFacts, validate, validateOfficial } = require("./scene_check_lib.js");
const facts = urdfFacts(fs.readFileSync(args.urdf, "utf8"));
const expectedCapsules = facts.capsules, expectedSpheres = facts.spheres;
const expectedTransforms = facts.links.length - 1;

// ---- the client ----
const result = {
  expectedCapsules, expectedSpheres, expectedTransforms, channels: [], rates: {}, counts: {},
  capsules: [], spheres: [], transforms: [], schemaErrors: [], officialChecked: 0, statusErrors: [], afterUnsubscribe: null,
  serverInfo: null, subprotocol: null, handshakes: [],
};
const offered = args.subprotocols ? args.subprotocols.split(",") : [FoxgloveClient.SUPPORTED_SUBPROTOCOL];

// One handshake offering `list`: the subprotocol answered, or the HTTP status of a refusal.
function handshake(list) {
  return new Promise((resolve) => {
    const probe = new WebSocket(args.url, list);
    probe.on("open", () => { resolve({ offered: list, protocol: probe.protocol }); probe.close(); });
    probe.on("unexpected-response", (req, res) => { resolve({ offered: list, status: res.statusCode }); req.destroy(); });
    probe.on("error", (e) => resolve({ offered: list, error: e.message }));
  });
}

async function main() {
  for (const list of [["foxglove.sdk.v1"], ["foxglove.sdk.v1", "foxglove.websocket.v1"],
                      ["foxglove.websocket.v1", "foxglove.sdk.v1"], ["x.unknown", "foxglove.sdk.v1"], ["x.unknown"]])
    result.handshakes.push(await handshake(list));
  measure();
}

function measure() {
  const ws = new WebSocket(args.url, offered);
  const client = new FoxgloveClient({ ws });
  const channelsById = new Map(), subs = new Map(), firstAt = {};
  let measuring = false, tfSubscription = null, unsubscribedAt = null;
  const decoder = new TextDecoder();

  client.on("error", (e) => { console.error("ws_client_check: " + (e && e.message)); process.exit(1); });
  client.on("serverInfo", (info) => { result.serverInfo = info; result.subprotocol = ws.protocol; });
  client.on("status", (s) => { result.statusErrors.push({ level: s.level, message: s.message }); });
  client.on("advertise", (channels) => {
    for (const c of channels) {
      channelsById.set(c.id, c);
      result.channels.push({ topic: c.topic, encoding: c.encoding, schemaName: c.schemaName, schemaEncoding: c.schemaEncoding });
      const id = client.subscribe(c.id);
      subs.set(id, { channel: c, schema: JSON.parse(c.schema) });
      result.counts[c.topic] = 0;
      if (c.topic === "/tf") tfSubscription = id;
    }
    ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: 9999, channelId: 4242 }] }));  // unknown channel
    setTimeout(() => { measuring = true; result.start = Date.now(); }, 500);
    setTimeout(() => {
      result.seconds = (Date.now() - result.start) / 1000;
      // Each topic's rate over the span from its first message on (as `ros2 topic hz`): a view that is
      // still discovering the controller when the window opens is not a slow view.
      const now = Date.now();
      for (const [topic, n] of Object.entries(result.counts))
        result.rates[topic] = n >= 2 && now > firstAt[topic] ? (n - 1) / ((now - firstAt[topic]) / 1000) : n / result.seconds;
      client.unsubscribe(tfSubscription);
      unsubscribedAt = Date.now();
      result.afterUnsubscribe = 0;
    }, 500 + seconds * 1000);
    setTimeout(() => {
      console.log(JSON.stringify(result));
      client.close();
      process.exit(0);
    }, 500 + seconds * 1000 + 800);
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    const sub = subs.get(subscriptionId);
    if (!sub) return;
    if (unsubscribedAt !== null) {
      // Frames already queued when the unsubscribe was sent may still come within a round trip.
      if (subscriptionId === tfSubscription && Date.now() - unsubscribedAt > 300) result.afterUnsubscribe += 1;
      return;
    }
    if (!measuring) return;
    const msg = JSON.parse(decoder.decode(data));
    if (result.counts[sub.channel.topic]++ === 0) firstAt[sub.channel.topic] = Date.now();
    if (result.schemaErrors.length < 20) validate(msg, sub.schema, sub.channel.topic, result.schemaErrors);
    if (sub.channel.schemaName.startsWith("foxglove.")) {
      validateOfficial(msg, sub.channel.schemaName, sub.channel.topic, result.schemaErrors);
      result.officialChecked += 1;
    }
    if (typeof timestamp !== "bigint" || timestamp <= 0n) result.schemaErrors.push("messageData timestamp " + timestamp);
    if (sub.channel.topic === "/reflex/scene") {
      let capsules = 0, spheres = 0;
      for (const e of msg.entities) {
        if (!e.id.startsWith("segment/")) continue;
        capsules += e.cylinders.length;
        spheres += e.spheres.length;
      }
      if (result.capsules.length < 1000) { result.capsules.push(capsules); result.spheres.push(spheres); }
    } else if (sub.channel.topic === "/tf") {
      if (result.transforms.length < 1000) result.transforms.push(msg.transforms.length);
    }
  });
}

main();
