// Shared by the scene-channel checks (tests/view/ws_client_check.js: reflex_view over the Foxglove
// WebSocket; tests/record/scene_check.cjs: the scene channels of an MCAP recording). Independent of
// the C++ scene builder: counts and joints come from the URDF text itself, and messages are checked
// against the JSON schema their channel carries.
//   urdfFacts(text)    -> {capsules, spheres, links, root, joints}: each <collision> with a <cylinder> or
//                         <box> is one capsule (drawn as 1 cylinder + 2 spheres), with a <sphere> one
//                         sphere; every <joint> with type, parent, child, origin xyz/rpy and axis
//   validate(v, schema, where, errors)  the JSON-schema subset the advertised schemas use: every key
//                         must be a schema property with the schema's type, every required key present;
//                         enum, const (oneOf), minimum/maximum respected; numbers finite
//   validateOfficial(v, schemaName, where, errors)  a foxglove.* message against Foxglove's own
//                         published JSON schema (npm @foxglove/schemas) with a standard validator (ajv),
//                         not against the schema Reflex advertised
//   jointTransform(joint, q) -> {t: [x,y,z], q: [x,y,z,w]} of child in parent (URDF: origin, then the
//                         joint's motion; rpy = Rz(yaw) Ry(pitch) Rx(roll))
"use strict";

function attr(tag, name) {
  const m = tag && tag.match(new RegExp(`\\s${name}\\s*=\\s*"([^"]*)"`));
  return m ? m[1] : null;
}
function numbers(text, fallback) {
  return text === null ? fallback : text.trim().split(/\s+/).map(Number);
}

function urdfFacts(raw) {
  const urdf = raw.replace(/<!--[\s\S]*?-->/g, "");
  let capsules = 0, spheres = 0;
  for (const block of urdf.match(/<collision[\s>][\s\S]*?<\/collision>/g) || []) {
    if (/<cylinder[\s/>]/.test(block) || /<box[\s/>]/.test(block)) capsules += 1;
    else if (/<sphere[\s/>]/.test(block)) spheres += 1;
  }
  const links = (urdf.match(/<link[\s>][^>]*>/g) || []).map((t) => attr(t, "name"));
  const joints = [];
  for (const block of urdf.match(/<joint[\s>][\s\S]*?<\/joint>/g) || []) {
    const head = block.match(/<joint[^>]*>/)[0];
    const origin = (block.match(/<origin[^>]*>/) || [null])[0];
    joints.push({
      name: attr(head, "name"),
      type: attr(head, "type"),
      parent: attr((block.match(/<parent[^>]*>/) || [null])[0], "link"),
      child: attr((block.match(/<child[^>]*>/) || [null])[0], "link"),
      xyz: numbers(attr(origin, "xyz"), [0, 0, 0]),
      rpy: numbers(attr(origin, "rpy"), [0, 0, 0]),
      axis: numbers(attr((block.match(/<axis[^>]*>/) || [null])[0], "xyz"), [1, 0, 0]),
    });
  }
  const children = new Set(joints.map((j) => j.child));
  const root = links.find((l) => !children.has(l));
  return { capsules, spheres, links, root, joints };
}

// ---- quaternions [x, y, z, w] ----
function qmul(a, b) {
  return [a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
          a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
          a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
          a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2]];
}
function qaxis(axis, angle) {
  const n = Math.hypot(axis[0], axis[1], axis[2]);
  const s = Math.sin(angle / 2) / n;
  return [axis[0] * s, axis[1] * s, axis[2] * s, Math.cos(angle / 2)];
}
function qrotate(q, v) {
  const r = qmul(qmul(q, [v[0], v[1], v[2], 0]), [-q[0], -q[1], -q[2], q[3]]);
  return [r[0], r[1], r[2]];
}

function jointTransform(joint, q) {
  const [roll, pitch, yaw] = joint.rpy;
  const r0 = qmul(qaxis([0, 0, 1], yaw), qmul(qaxis([0, 1, 0], pitch), qaxis([1, 0, 0], roll)));
  if (joint.type === "revolute" || joint.type === "continuous") {
    return { t: joint.xyz.slice(), q: qmul(r0, qaxis(joint.axis, q)) };
  }
  if (joint.type === "prismatic") {
    const n = Math.hypot(...joint.axis);
    const d = qrotate(r0, joint.axis.map((a) => (a / n) * q));
    return { t: joint.xyz.map((x, i) => x + d[i]), q: r0 };
  }
  return { t: joint.xyz.slice(), q: r0 };  // fixed
}

function typeOf(v) {
  if (v === null) return "null";
  if (Array.isArray(v)) return "array";
  if (typeof v === "number") return Number.isInteger(v) ? "integer" : "number";
  return typeof v;
}
function validate(v, schema, where, errors) {
  if (errors.length > 20) return;
  if (schema.oneOf) {
    if (!schema.oneOf.some((o) => o.const === v)) errors.push(`${where}: ${JSON.stringify(v)} is none of the oneOf consts`);
    return;
  }
  const types = schema.type === undefined ? [] : [].concat(schema.type);
  const t = typeOf(v);
  if (types.length && !types.includes(t) && !(t === "integer" && types.includes("number"))) {
    errors.push(`${where}: ${t} where the schema says ${types.join("|")}`);
    return;
  }
  if (schema.enum && !schema.enum.includes(v)) errors.push(`${where}: ${JSON.stringify(v)} not in ${schema.enum}`);
  if (schema.minimum !== undefined && v < schema.minimum) errors.push(`${where}: ${v} < ${schema.minimum}`);
  if (schema.maximum !== undefined && v > schema.maximum) errors.push(`${where}: ${v} > ${schema.maximum}`);
  if (t === "number" && !Number.isFinite(v)) errors.push(`${where}: not finite`);
  if (t === "object" && schema.required) {
    for (const k of schema.required) if (!(k in v)) errors.push(`${where}.${k}: required, missing`);
  }
  if (t === "object" && schema.properties) {
    for (const k of Object.keys(v)) {
      if (!schema.properties[k]) errors.push(`${where}.${k}: not in the schema`);
      else validate(v[k], schema.properties[k], `${where}.${k}`, errors);
    }
  }
  if (t === "array" && schema.items) v.forEach((x, i) => validate(x, schema.items, `${where}[${i}]`, errors));
}

// ---- Foxglove's official schemas (bringup/web/node_modules: @foxglove/schemas, ajv) ----
let official = null;
function officialValidator(schemaName) {
  if (official === null) {
    const path = require("path");
    const modules = process.env.REFLEX_WEB_MODULES || path.join(__dirname, "..", "..", "bringup", "web", "node_modules");
    const Ajv = require(path.join(modules, "ajv"));
    official = { ajv: new Ajv({ allErrors: true, strict: false }), schemas: require(path.join(modules, "@foxglove/schemas/jsonschema")), compiled: new Map() };
  }
  if (!official.compiled.has(schemaName)) {
    const schema = official.schemas[schemaName.replace(/^foxglove\./, "")];
    official.compiled.set(schemaName, schema ? official.ajv.compile(schema) : null);
  }
  return official.compiled.get(schemaName);
}
function validateOfficial(v, schemaName, where, errors) {
  if (errors.length > 20) return;
  const check = officialValidator(schemaName);
  if (check === null) {
    errors.push(`${where}: ${schemaName} is not one of Foxglove's published schemas`);
    return;
  }
  if (!check(v)) errors.push(`${where}: not a valid ${schemaName} by Foxglove's own schema: ${official.ajv.errorsText(check.errors, { separator: "; " })}`);
}

module.exports = { urdfFacts, validate, validateOfficial, jointTransform };
