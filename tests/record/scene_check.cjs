// The scene channels of a Reflex MCAP recording read by the reference MCAP reader
// (@mcap/core through mcap_check.cjs: index, CRCs, the JSON messages, the CDR joint states decoded by
// Foxglove's OMG IDL decoder) and checked against answers that do not come from Reflex's scene code:
//   - the channels /tf and /reflex/scene: message encoding json, schema encoding jsonschema, schema
//     names foxglove.FrameTransforms / foxglove.SceneUpdate; every message parses and validates
//     against the schema its channel carries (tests/view/scene_check_lib.js);
//   - every scene has the URDF's capsules (cylinders) and 2 x capsules + spheres spheres in its
//     segment/ entities, counted from the URDF text; every /tf has one transform per link but the root,
//     parent -> child as the URDF's joints say;
//   - log times strictly increasing per channel, within the first and last log time of the recorded
//     Reflex (cdr) channels; each /tf message's log time is a recorded joint state's, and its
//     transforms' timestamp that joint state's header.stamp_ns;
//   - every SAMPLE-th /tf: each transform = the URDF joint's origin and motion at the joint state's
//     position, computed here (scene_check_lib.js jointTransform), not by Reflex.
// Usage: node scene_check.cjs FILE URDF OUT.json [SAMPLE]. Exit 0 with the results in OUT.json (the
// C++ test asserts on them), 1 with the reason on stderr.
"use strict";
const fs = require("fs");
const path = require("path");
const { indexed } = require("./mcap_check.cjs");
const { urdfFacts, validate, validateOfficial, jointTransform } = require(path.join(__dirname, "..", "view", "scene_check_lib.js"));

async function main() {
  const [file, urdfPath, outPath, sampleText] = process.argv.slice(2);
  if (!file || !urdfPath || !outPath) throw new Error("usage: scene_check.cjs FILE URDF OUT.json [SAMPLE]");
  const sample = Number(sampleText || 10);
  const facts = urdfFacts(fs.readFileSync(urdfPath, "utf8"));
  const jointByChild = new Map(facts.joints.map((j) => [j.child, j]));
  const rec = await indexed(file);
  const result = {
    expected: { capsules: facts.capsules, spheres: 2 * facts.capsules + facts.spheres, transforms: facts.links.length - 1 },
    channels: rec.channels.filter((c) => c.encoding === "json").map((c) => ({
      topic: c.topic, encoding: c.encoding, schema: c.schema, schema_encoding: c.schema_encoding, metadata: c.metadata })),
    counts: {}, schemaErrors: [], officialChecked: 0, capsules: [], spheres: [], transforms: [], wrongFrames: [],
    monotonic: true, within: true, tfWithoutJointState: 0, tfStampMismatch: 0,
    fk: { compared: 0, transforms: 0, maxTranslationError: 0, maxRotationError: 0, missingJoint: [] },
    first_log_ns: null, last_log_ns: null, scene_first_ns: null, scene_last_ns: null,
  };
  const schemas = new Map(), schemaNames = new Map();
  for (const c of rec.channels) if (c.schema_data) {
    schemas.set(c.topic, JSON.parse(c.schema_data));
    schemaNames.set(c.topic, c.schema);
  }
  // The recorded Reflex samples: time range, and the joint states by log time.
  const jointStates = new Map();
  for (const m of rec.messages) {
    if (schemas.has(m.topic)) continue;
    const t = BigInt(m.log_time);
    if (result.first_log_ns === null || t < BigInt(result.first_log_ns)) result.first_log_ns = t.toString();
    if (result.last_log_ns === null || t > BigInt(result.last_log_ns)) result.last_log_ns = t.toString();
    if (m.topic === "reflex/joint_state") jointStates.set(m.log_time, m.msg);
  }
  const last = new Map();
  let tfIndex = 0;
  for (const m of rec.messages) {
    if (!schemas.has(m.topic)) continue;
    result.counts[m.topic] = (result.counts[m.topic] || 0) + 1;
    validate(m.msg, schemas.get(m.topic), m.topic, result.schemaErrors);
    const schemaName = schemaNames.get(m.topic);
    if (schemaName.startsWith("foxglove.")) {
      validateOfficial(m.msg, schemaName, m.topic, result.schemaErrors);
      result.officialChecked += 1;
    }
    const t = BigInt(m.log_time);
    if (last.has(m.topic) && t <= last.get(m.topic)) result.monotonic = false;
    last.set(m.topic, t);
    if (t < BigInt(result.first_log_ns) || t > BigInt(result.last_log_ns)) result.within = false;
    if (result.scene_first_ns === null) result.scene_first_ns = m.log_time;
    result.scene_last_ns = m.log_time;
    if (m.topic === "/reflex/scene") {
      let capsules = 0, spheres = 0;
      for (const e of m.msg.entities) {
        if (!e.id.startsWith("segment/")) continue;
        capsules += e.cylinders.length;
        spheres += e.spheres.length;
      }
      result.capsules.push(capsules);
      result.spheres.push(spheres);
    } else if (m.topic === "/tf") {
      const tfs = m.msg.transforms;
      result.transforms.push(tfs.length);
      for (const x of tfs) {
        const j = jointByChild.get(x.child_frame_id);
        if (!j || j.parent !== x.parent_frame_id) result.wrongFrames.push(`${x.parent_frame_id} -> ${x.child_frame_id}`);
      }
      const js = jointStates.get(m.log_time);
      if (!js) { result.tfWithoutJointState += 1; continue; }
      const stamp = BigInt(js.header.stamp_ns);
      if (tfs.some((x) => BigInt(x.timestamp.sec) * 1000000000n + BigInt(x.timestamp.nsec) !== stamp)) result.tfStampMismatch += 1;
      if (tfIndex++ % sample !== 0) continue;
      result.fk.compared += 1;
      const q = new Map(js.names.map((n, i) => [n, js.positions[i]]));
      for (const x of tfs) {
        const j = jointByChild.get(x.child_frame_id);
        if (!j) continue;
        if (j.type !== "fixed" && !q.has(j.name) && !result.fk.missingJoint.includes(j.name)) result.fk.missingJoint.push(j.name);
        const want = jointTransform(j, q.get(j.name) || 0);
        const got = x.translation, r = x.rotation;
        const dt = Math.hypot(got.x - want.t[0], got.y - want.t[1], got.z - want.t[2]);
        const dot = Math.abs(r.x * want.q[0] + r.y * want.q[1] + r.z * want.q[2] + r.w * want.q[3]);
        const angle = 2 * Math.acos(Math.min(1, dot));  // rad between the two rotations
        result.fk.maxTranslationError = Math.max(result.fk.maxTranslationError, dt);
        result.fk.maxRotationError = Math.max(result.fk.maxRotationError, angle);
        result.fk.transforms += 1;
      }
    }
  }
  result.schemaErrors = result.schemaErrors.slice(0, 20);
  result.wrongFrames = [...new Set(result.wrongFrames)].slice(0, 20);
  fs.writeFileSync(outPath, JSON.stringify(result));
}

main().catch((e) => {
  process.stderr.write(`scene_check: ${e && e.stack ? e.stack : e}\n`);
  process.exit(1);
});
