// Reflex live view page: a Foxglove WebSocket protocol client (foxglove.websocket.v1, written for the
// browser's own WebSocket) that subscribes to reflex_view's /reflex/scene (foxglove.SceneUpdate),
// /reflex/status (reflex.ViewStatus) and /reflex/camera/left (foxglove.CompressedImage) channels and draws
// them with three.js (served by reflex_view from bringup/web/node_modules/three, never from a CDN) and,
// for the camera, an <img>.
//
// window.reflexView holds the page's state for tests and for the curious:
//   connected, channels (advertised topics), framesReceived (scene updates drawn), statusReceived,
//   capsulesDrawn / spheresDrawn (collision primitives of the robot in the last scene: cylinders of
//   capsules, and sphere primitives), closestLines, targetsDrawn, objectsDrawn, zoneColours ({zone:
//   "#rrggbb"} of the robot segments in the last scene), zonesSeen ({zone: count of scenes}),
//   lastStatus, cameraImage (false until a camera image arrived), cameraImages (images received),
//   cameraDecoded ({width, height} of the last image the browser decoded, null before), errors (status
//   messages of the server),
//   connections (WebSocket connections opened; every reconnect starts the channel list afresh),
//   labels ([{entity, text, colour, x, y, w, h}]: every text label drawn in the last render, its box in
//   CSS px of the 3D canvas, top left origin; dpr = canvas pixels per CSS px), objectColours ({name:
//   "#rrggbb"}), closest ([{arm, label, a: [x, y], b: [x, y]}]: each closest-pair line drawn, its ends
//   in CSS px of the canvas), stale / staleText / sceneAgeMs (the "no data" sign: no scene for more
//   than kStaleMs, or none yet), plotTraces (traces started because time went back), plotPoints,
//   plotBackSteps (points of the plot earlier than the one before them: 0), rendered (3D renders: only
//   when a scene arrived, the camera moved or the window changed) and plotsDrawn.
//
// Static mode (the flagship report and tests draw recorded postures with this same
// renderer): index.html?render=FILE.js, FILE a plain name in the page's folder (no "/", no ":") of an ES
// module made by reflex_scene: `export default {tile: {width, height} [CSS px], camera: {azimuth,
// elevation [rad], radius [m], target: [x, y, z] [m, root frame]}, scenes: [{time, row, update:
// foxglove.SceneUpdate}]}`. The page then opens no WebSocket and shows only the 3D canvas, at the top
// left, of size (tiles x width) x height: scene i drawn in tile i (x from i * width), each with the same
// camera (vertical field of view 40 deg, aspect width / height, z up, looking at the target from
// target + radius (cos el cos az, cos el sin az, sin el)). Once drawn it sets state.staticDrawn (number
// of tiles), state.tiles ([{time, capsulesDrawn, spheresDrawn, closestLines, targetsDrawn, zoneColours}])
// and the title "Reflex view: N scenes drawn": a driver waits for that signal before capturing (the
// load event may come first). A bad module, or anything thrown later (no WebGL context): state.errors,
// the title "Reflex view: error" (bad module) and the message written on the page.
import * as THREE from "three";

const state = {
  connected: false, channels: [], framesReceived: 0, statusReceived: 0, capsulesDrawn: 0, spheresDrawn: 0,
  closestLines: 0, targetsDrawn: 0, objectsDrawn: 0, schemaDrawn: 0, zoneColours: {}, zonesSeen: {}, lastStatus: null,
  cameraImage: false, cameraImages: 0, cameraDecoded: null, errors: [], rendered: 0, staticDrawn: 0, tiles: [], connections: 0, labels: [], dpr: 1,
  objectColours: {}, closest: [], stale: false, staleText: "", sceneAgeMs: null, plotTraces: 0, plotPoints: 0,
  plotBackSteps: 0, plotsDrawn: 0,
};
window.reflexView = state;
// What the next animation frame draws (requestRender, requestPlot; frame() below).
let frameQueued = false, sceneDirty = true, plotDirty = true;

const renderModule = new URLSearchParams(location.search).get("render");
let renderSpec = null;
if (renderModule !== null) {
  document.body.classList.add("static");
  // Anything thrown later (no WebGL context, a malformed scene) is reported too, not only waited for.
  window.addEventListener("error", (e) => { state.errors.push(String(e.message || e)); });
  try {
    if (!/^[A-Za-z0-9_.-]+\.js$/.test(renderModule) || renderModule.startsWith(".")) {
      throw new Error(`render=${renderModule}: not a plain .js file name in the page's folder`);
    }
    renderSpec = (await import(new URL(renderModule, location.href).href)).default;
    const t = renderSpec && renderSpec.tile;
    if (!t || !(t.width >= 16) || !(t.height >= 16) || !Array.isArray(renderSpec.scenes) || !renderSpec.camera) {
      throw new Error(`render=${renderModule}: no tile / camera / scenes (not made by reflex_scene?)`);
    }
  } catch (e) {
    state.errors.push(String(e.message || e));
    document.title = "Reflex view: error";
    const note = document.createElement("pre");  // in the screenshot too: never a silently empty picture
    note.style.color = "#f55";
    note.textContent = "Reflex view (static mode): " + String(e.message || e);
    document.body.prepend(note);
    renderSpec = null;
  }
}

// ---------- three.js scene: z up, the robot's root frame is the world frame -----------------------
const container = document.getElementById("scene3d");
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
container.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x16181d);
const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 50);
camera.up.set(0, 0, 1);
const orbit = { azimuth: 0.6, elevation: 0.25, radius: 2.6, target: new THREE.Vector3(0, 0, 0.85) };
function placeCamera() {
  const c = Math.cos(orbit.elevation);
  camera.position.set(orbit.target.x + orbit.radius * c * Math.cos(orbit.azimuth),
                      orbit.target.y + orbit.radius * c * Math.sin(orbit.azimuth),
                      orbit.target.z + orbit.radius * Math.sin(orbit.elevation));
  camera.lookAt(orbit.target);
}
placeCamera();
scene.add(new THREE.AmbientLight(0xffffff, 0.55));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(2, 1.5, 3);
scene.add(sun);
const grid = new THREE.GridHelper(4, 40, 0x445066, 0x2b313d);
grid.rotation.x = Math.PI / 2;  // GridHelper lies in x-z; the floor here is x-y
scene.add(grid);
scene.add(new THREE.AxesHelper(0.3));

// Drag to orbit, wheel to zoom.
let drag = null;
renderer.domElement.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY }; });
window.addEventListener("pointerup", () => { drag = null; });
window.addEventListener("pointermove", (e) => {
  if (!drag) return;
  orbit.azimuth -= (e.clientX - drag.x) * 0.01;
  orbit.elevation = Math.max(-1.4, Math.min(1.4, orbit.elevation + (e.clientY - drag.y) * 0.01));
  drag = { x: e.clientX, y: e.clientY };
  placeCamera();
  requestRender();
});
renderer.domElement.addEventListener("wheel", (e) => {
  orbit.radius = Math.max(0.5, Math.min(10, orbit.radius * (e.deltaY > 0 ? 1.1 : 0.9)));
  placeCamera();
  requestRender();
  e.preventDefault();
}, { passive: false });

function resize() {
  if (renderModule !== null) return;  // static mode: drawStatic sets the size once
  const w = container.clientWidth || 640, h = container.clientHeight || 480;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  requestRender();
}
window.addEventListener("resize", resize);
resize();

// Unit shapes scaled per primitive: sphere of diameter 1; cylinder of diameter 1 and height 1 along z
// (foxglove.CylinderPrimitive: flat faces perpendicular to its z axis).
const unitSphere = new THREE.SphereGeometry(0.5, 24, 16);
const unitCylinder = new THREE.CylinderGeometry(0.5, 0.5, 1, 24, 1, true);
unitCylinder.rotateX(Math.PI / 2);

function material(c) {
  return new THREE.MeshStandardMaterial({ color: new THREE.Color(c.r, c.g, c.b), transparent: c.a < 1,
                                          opacity: c.a, roughness: 0.6, metalness: 0.05 });
}
function setColour(mat, c) {
  mat.color.setRGB(c.r, c.g, c.b);
  mat.opacity = c.a;
  mat.transparent = c.a < 1;
}
function hex(c) {
  const h = (v) => Math.round(Math.max(0, Math.min(1, v)) * 255).toString(16).padStart(2, "0");
  return "#" + h(c.r) + h(c.g) + h(c.b);
}

// ---------- text labels: a sprite per text, a canvas texture, a constant size on screen ------------------
// Drawn over everything (no depth test), so a name is never hidden inside a translucent capsule.
const kLabelPx = 20;                            // label height on screen [CSS px]
const kLabelCanvasW = 512, kLabelCanvasH = 64;  // texture size; the box is drawn centred in it
function makeLabel() {
  const canvas = document.createElement("canvas");
  canvas.width = kLabelCanvasW;
  canvas.height = kLabelCanvasH;
  const texture = new THREE.CanvasTexture(canvas);
  texture.colorSpace = THREE.SRGBColorSpace;
  texture.generateMipmaps = false;
  texture.minFilter = THREE.LinearFilter;
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({
    map: texture, transparent: true, depthTest: false, depthWrite: false, sizeAttenuation: false }));
  sprite.renderOrder = 30;
  sprite.userData = { canvas, texture, key: "", text: "", colour: "", boxW: 0, lift: 0 };
  return sprite;
}
// Writes `text` in `colour` (CSS colour) on a dark box with a border of `border` (default: colour).
function setLabel(sprite, text, colour, border = colour) {
  const u = sprite.userData, key = `${text}|${colour}|${border}`;
  if (u.key === key) return;
  const g = u.canvas.getContext("2d");
  g.clearRect(0, 0, kLabelCanvasW, kLabelCanvasH);
  let font = 36;
  g.font = `bold ${font}px system-ui, sans-serif`;
  while (font > 14 && g.measureText(text).width > kLabelCanvasW - 28) g.font = `bold ${--font}px system-ui, sans-serif`;
  const w = Math.min(kLabelCanvasW - 4, Math.ceil(g.measureText(text).width) + 24), x0 = (kLabelCanvasW - w) / 2;
  g.fillStyle = "rgba(14, 16, 20, 0.88)";
  g.strokeStyle = border;
  g.lineWidth = 4;
  g.beginPath();
  if (g.roundRect) g.roundRect(x0, 2, w, kLabelCanvasH - 4, 10);  // (browsers before 2023 lack it: square corners)
  else g.rect(x0, 2, w, kLabelCanvasH - 4);
  g.fill();
  g.stroke();
  g.fillStyle = colour;
  g.textAlign = "center";
  g.textBaseline = "middle";
  g.fillText(text, kLabelCanvasW / 2, kLabelCanvasH / 2 + 2);
  u.texture.needsUpdate = true;
  Object.assign(u, { key, text, colour, boxW: w });
}

// The closest pair of an arm: a thick white bar between the witness points with a dot at each end, drawn
// over the capsules (no depth test), and a label with the arm and its distance. Sizes in screen pixels.
const kClosestColour = 0xffffff, kClosestBarPx = 5, kClosestDotPx = 12;
const overlayMaterial = () => new THREE.MeshBasicMaterial({ color: kClosestColour, depthTest: false, depthWrite: false,
                                                             transparent: true, opacity: 1 });
function makeClosest(group) {
  const c = { bar: new THREE.Mesh(unitCylinder, overlayMaterial()), dots: [0, 1].map(() => new THREE.Mesh(unitSphere, overlayMaterial())),
              label: makeLabel(), a: new THREE.Vector3(), b: new THREE.Vector3() };
  c.label.userData.lift = 1.5;  // above the bar, clear of its ends
  for (const m of [c.bar, ...c.dots]) { m.renderOrder = 20; group.add(m); }
  group.add(c.label);
  return c;
}
function setClosestVisible(c, visible) {
  for (const m of [c.bar, ...c.dots, c.label]) m.visible = visible;
}
// World size of `px` screen pixels at `p` (perspective camera, viewport `height` CSS px high).
function worldPerPixel(p, height) {
  const depth = Math.max(0.01, p.clone().applyMatrix4(camera.matrixWorldInverse).negate().z);
  return depth * 2 * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2) / height;
}
const zAxis = new THREE.Vector3(0, 0, 1);
function placeClosest(c, height) {
  const mid = c.a.clone().add(c.b).multiplyScalar(0.5), d = c.b.clone().sub(c.a), len = d.length();
  const k = worldPerPixel(mid, height);
  c.bar.position.copy(mid);
  c.bar.quaternion.setFromUnitVectors(zAxis, len > 1e-9 ? d.clone().divideScalar(len) : zAxis);
  c.bar.scale.set(kClosestBarPx * k, kClosestBarPx * k, Math.max(len, 1e-6));
  c.dots[0].position.copy(c.a);
  c.dots[1].position.copy(c.b);
  for (const [i, p] of [c.a, c.b].entries()) c.dots[i].scale.setScalar(kClosestDotPx * worldPerPixel(p, height));
  c.label.position.copy(mid);
}

// Before each render of a viewport `width` x `height` (CSS px): labels at their constant screen size,
// moved up where they would cover a closest bar or one another, the closest bars at their pixel width; fills
// state.labels and state.closest with what is on screen.
function prepareOverlays(width, height) {
  camera.updateMatrixWorld();
  const p11 = camera.projectionMatrix.elements[5], sy = 2 * kLabelPx / (p11 * height);
  const toScreen = (v) => {
    const n = v.clone().project(camera);
    return { x: (n.x + 1) / 2 * width, y: (1 - n.y) / 2 * height, front: n.z < 1 && n.z > -1 };
  };
  const labels = [];
  for (const [id, g] of entities) {
    if (g.closest) placeClosest(g.closest, height);
    for (const l of [...g.labels, ...(g.closest ? [g.closest.label] : [])]) {
      if (!l.visible) continue;
      l.scale.set(sy * kLabelCanvasW / kLabelCanvasH, sy, 1);
      const s = toScreen(l.getWorldPosition(new THREE.Vector3()));
      if (s.front) labels.push({ sprite: l, id, s });
    }
  }
  // The closest bars first: no label may cover one.
  const placed = [];
  state.closest = [];
  for (const [id, g] of entities) {
    if (!g.closest || !g.closest.bar.visible) continue;
    const a = toScreen(g.closest.a), b = toScreen(g.closest.b), r = kClosestDotPx / 2 + 2;
    placed.push({ x: Math.min(a.x, b.x) - r, y: Math.min(a.y, b.y) - r, w: Math.abs(a.x - b.x) + 2 * r,
                  h: Math.abs(a.y - b.y) + 2 * r });
    state.closest.push({ arm: id.slice("closest/".length), label: g.closest.label.userData.text,
                         a: [a.x, a.y], b: [b.x, b.y] });
  }
  // Bottom-most first; each one goes up (in label heights) until it covers nothing placed before it.
  labels.sort((p, q) => q.s.y - p.s.y);
  state.labels = [];
  for (const { sprite, id, s } of labels) {
    const w = sprite.userData.boxW / kLabelCanvasH * kLabelPx;
    let lift = sprite.userData.lift, box;
    for (let i = 0; i < 12; ++i, lift += 1.1) {
      box = { x: s.x - w / 2, y: s.y - (1 + lift) * kLabelPx, w, h: kLabelPx };
      if (!placed.some((o) => box.x < o.x + o.w && o.x < box.x + box.w && box.y < o.y + o.h && o.y < box.y + box.h)) break;
    }
    sprite.center.set(0.5, -lift);
    placed.push(box);
    state.labels.push({ entity: id, text: sprite.userData.text, colour: sprite.userData.colour,
                        x: box.x, y: box.y, w: box.w, h: box.h });
  }
  state.dpr = renderer.getPixelRatio();
}

// One THREE.Group per entity id; its meshes are reused while the primitive counts stay the same.
const entities = new Map();
function pool(list, group, count, make) {
  while (list.length < count) { const o = make(); list.push(o); group.add(o); }
  for (let i = 0; i < list.length; ++i) list[i].visible = i < count;
}
function drawEntity(e) {
  let g = entities.get(e.id);
  if (!g) {
    g = { group: new THREE.Group(), spheres: [], cylinders: [], lines: [], labels: [], closest: null };
    entities.set(e.id, g);
    scene.add(g.group);
  }
  const spheres = e.spheres || [], cylinders = e.cylinders || [], lines = e.lines || [];
  pool(g.spheres, g.group, spheres.length, () => new THREE.Mesh(unitSphere, material({ r: 1, g: 1, b: 1, a: 1 })));
  spheres.forEach((s, i) => {
    const m = g.spheres[i];
    m.position.set(s.pose.position.x, s.pose.position.y, s.pose.position.z);
    m.scale.set(s.size.x, s.size.y, s.size.z);
    setColour(m.material, s.color);
  });
  pool(g.cylinders, g.group, cylinders.length, () => new THREE.Mesh(unitCylinder, material({ r: 1, g: 1, b: 1, a: 1 })));
  cylinders.forEach((c, i) => {
    const m = g.cylinders[i];
    const o = c.pose.orientation;
    m.position.set(c.pose.position.x, c.pose.position.y, c.pose.position.z);
    m.quaternion.set(o.x, o.y, o.z, o.w);
    m.scale.set(c.size.x, c.size.y, c.size.z);
    setColour(m.material, c.color);
  });
  if (e.id.startsWith("closest/")) {
    // The closest pair (one line a -> b): the overlay above, its label "left 15 mm" in the zone's colour.
    if (!g.closest) g.closest = makeClosest(g.group);
    const l = lines.length && lines[0].points.length >= 2 ? lines[0] : null;
    setClosestVisible(g.closest, l !== null);
    if (l) {
      const [p, q] = l.points;
      g.closest.a.set(p.x, p.y, p.z);
      g.closest.b.set(q.x, q.y, q.z);
      // The controller's distance of the arm (as in the hand table), else the drawn line's length.
      const arm = e.id.slice("closest/".length);
      const st = state.lastStatus && (state.lastStatus.arms || []).find((a) => a.name === arm);
      const mm = (st && typeof st.distance === "number" ? st.distance : g.closest.a.distanceTo(g.closest.b)) * 1000;
      setLabel(g.closest.label, `${arm} ${mm.toFixed(Math.abs(mm) < 10 ? 1 : 0)} mm`, hex(l.color));
    }
  } else {
    pool(g.lines, g.group, lines.length, () => new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial()));
    lines.forEach((l, i) => {
      const m = g.lines[i];
      m.geometry.setFromPoints(l.points.map((p) => new THREE.Vector3(p.x, p.y, p.z)));
      m.material.color.setRGB(l.color.r, l.color.g, l.color.b);
    });
  }
  // Every text of the entity (the targets' and the objects' names) as a label at its position.
  const texts = (e.texts || []).filter((t) => typeof t.text === "string" && t.text.length);
  pool(g.labels, g.group, texts.length, makeLabel);
  texts.forEach((t, i) => {
    const m = g.labels[i];
    m.position.set(t.pose.position.x, t.pose.position.y, t.pose.position.z);
    setLabel(m, t.text, hex(t.color));
  });
  return { spheres: spheres.length, cylinders: cylinders.length, lines: lines.length, texts: texts.length };
}

function removeEntity(id) {
  const g = entities.get(id);
  if (!g) return;
  scene.remove(g.group);
  const labels = [...g.labels, ...(g.closest ? [g.closest.label] : [])];
  for (const m of [...g.spheres, ...g.cylinders, ...g.lines, ...labels]) m.material.dispose();
  for (const l of g.lines) l.geometry.dispose();
  for (const l of labels) l.userData.texture.dispose();
  if (g.closest) for (const m of [g.closest.bar, ...g.closest.dots]) m.material.dispose();
  entities.delete(id);
}
function onSceneUpdate(update) {
  // A delete-all followed by the same entities (reflex_view sends one every time) keeps the meshes:
  // only entities absent from this update are removed.
  const present = new Set((update.entities || []).map((e) => e.id));
  for (const d of update.deletions || []) {
    const ids = d.type === 1 ? [...entities.keys()].filter((id) => !present.has(id)) : [d.id];
    ids.forEach(removeEntity);
  }
  let capsules = 0, primitiveSpheres = 0, lines = 0, targets = 0, objects = 0, schema = 0;
  const colours = {};
  for (const e of update.entities || []) {
    const n = drawEntity(e);
    if (e.id.startsWith("segment/")) {
      capsules += n.cylinders;
      primitiveSpheres += n.spheres - 2 * n.cylinders;  // a capsule is drawn with two end spheres
      const zone = (e.metadata || []).find((kv) => kv.key === "zone");
      if (zone && zone.value !== "none" && e.spheres && e.spheres.length) colours[zone.value] = hex(e.spheres[0].color);
    } else if (e.id.startsWith("closest/")) {
      lines += n.lines;
    } else if (e.id.startsWith("target/")) {
      targets += n.spheres;
    } else if (e.id === "objects") {
      objects += n.spheres;
      const names = {};
      (e.texts || []).forEach((t, i) => { if (e.spheres && e.spheres[i]) names[t.text] = hex(e.spheres[i].color); });
      state.objectColours = names;
    } else if (e.id.startsWith("schema/")) {
      schema += 1;
    }
  }
  state.capsulesDrawn = capsules;
  state.spheresDrawn = primitiveSpheres;
  state.closestLines = lines;
  state.targetsDrawn = targets;
  state.objectsDrawn = objects;
  state.schemaDrawn = schema;
  state.zoneColours = colours;
  for (const z of Object.keys(colours)) state.zonesSeen[z] = (state.zonesSeen[z] || 0) + 1;
  state.framesReceived += 1;
  lastSceneAt = performance.now();
  updateStale();
  requestRender();
}

// ---------- distance plot and hand table ------------------------------------------------------------
const history = [];  // {t [s], d: [left, right] (m or null), f: [left, right]}
const kPlotSeconds = 10, kPlotMaxDistance = 0.10;
const plot = document.getElementById("plot");
const armColours = ["#4c9dff", "#e05ce0"];
function drawPlot() {
  const ctx = plot.getContext("2d"), W = plot.width, H = plot.height, s = state.lastStatus;
  ctx.clearRect(0, 0, W, H);
  state.plotsDrawn += 1;
  state.plotPoints = history.length;
  state.plotBackSteps = history.filter((h, i) => i > 0 && h.t < history[i - 1].t).length;
  if (!s || !history.length) return;
  const t1 = history[history.length - 1].t, x = (t) => W - (t1 - t) / kPlotSeconds * W;
  const y = (d) => H - Math.min(d, kPlotMaxDistance) / kPlotMaxDistance * (H - 10);
  ctx.font = "11px sans-serif";
  for (const [name, d, colour] of [["d_a", s.d_a, "#ddcc22"], ["d_b", s.d_b, "#ff8822"], ["d_r", s.d_r, "#ff3333"]]) {
    ctx.strokeStyle = colour; ctx.setLineDash([4, 4]); ctx.beginPath();
    ctx.moveTo(0, y(d)); ctx.lineTo(W, y(d)); ctx.stroke();
    ctx.fillStyle = colour; ctx.fillText(`${name} ${(d * 1000).toFixed(0)} mm`, 4, y(d) - 2);
  }
  ctx.setLineDash([]);
  for (let arm = 0; arm < 2; ++arm) {
    ctx.strokeStyle = armColours[arm]; ctx.lineWidth = 2; ctx.beginPath();
    let pen = false;
    for (const h of history) {
      if (h.d[arm] === null) { pen = false; continue; }
      pen ? ctx.lineTo(x(h.t), y(h.d[arm])) : ctx.moveTo(x(h.t), y(h.d[arm]));
      pen = true;
    }
    ctx.stroke();
    ctx.setLineDash([2, 3]); ctx.lineWidth = 1; ctx.beginPath();  // f(d) in [0, 1] over the full height
    history.forEach((h, i) => {
      const yy = H - (h.f[arm] ?? 0) * (H - 10);
      i ? ctx.lineTo(x(h.t), yy) : ctx.moveTo(x(h.t), yy);
    });
    ctx.stroke(); ctx.setLineDash([]);
  }
  ctx.fillStyle = "#889";
  ctx.fillText(`0–${kPlotMaxDistance * 1000} mm, last ${kPlotSeconds} s; f(d) 0–1 dotted`, W - 230, 12);
}
function setCells(row, values, zone) {
  const cells = document.querySelectorAll(`#hand-${row} td`);
  values.forEach((v, i) => { cells[i].textContent = v; });
  cells[1].className = "zone-" + zone;
}
function onStatus(s) {
  state.lastStatus = s;
  state.statusReceived += 1;
  const t = s.timestamp.sec + s.timestamp.nsec * 1e-9;
  // Time went back (a looped replay, a restarted recording): a new trace, never a line joining the two.
  if (history.length && t < history[history.length - 1].t) {
    history.length = 0;
    state.plotTraces += 1;
  }
  history.push({ t, d: s.arms.map((a) => a.distance), f: s.arms.map((a) => a.blend_f) });
  while (history.length && history[0].t < t - kPlotSeconds) history.shift();
  s.arms.forEach((a) => {
    const target = a.target_given && a.target
        ? `${a.target_object || "point"} (${a.target.x.toFixed(2)}, ${a.target.y.toFixed(2)}, ${a.target.z.toFixed(2)})`
        : "none";
    setCells(a.name, [target, a.zone + (a.estop_latched ? " E-STOP" : ""),
                      a.distance === null ? "–" : (a.distance * 1000).toFixed(1),
                      a.blend_f === null ? "–" : a.blend_f.toFixed(2),
                      a.closest_a ? `${a.closest_a} – ${a.closest_b}` : ""], a.zone);
  });
  document.getElementById("protection").textContent = s.protection ? "protection: " + s.protection : "";
  requestPlot();
}

// ---------- the "no data" sign: no scene for more than kStaleMs, or none yet ------------------------
const kStaleMs = 1000;
const staleSign = document.getElementById("stale");
let lastSceneAt = null, connectedAt = null;
function updateStale() {
  if (renderModule !== null) return;
  const now = performance.now();
  const age = lastSceneAt === null ? null : now - lastSceneAt;
  let text = "";
  if (lastSceneAt === null) {
    text = state.connected ? `no data yet: connected ${((now - connectedAt) / 1000).toFixed(1)} s, no scene received`
                           : "no data yet: not connected";
  } else if (age > kStaleMs) {
    text = `stale: last scene ${(age / 1000).toFixed(1)} s ago` + (state.connected ? "" : " (disconnected)");
  }
  state.sceneAgeMs = age === null ? null : Math.round(age);
  state.stale = text !== "";
  state.staleText = text;
  if (staleSign.textContent !== text) staleSign.textContent = text;
  staleSign.hidden = !state.stale;
}

// ---------- Foxglove WebSocket protocol client ------------------------------------------------------
const kSubprotocol = "foxglove.websocket.v1";
const decoder = new TextDecoder();
// The left camera's image (foxglove.CompressedImage, base64 bytes): shown as it comes, with its capture
// time; the browser decodes it (state.cameraDecoded says it could).
const cameraImg = document.createElement("img");
cameraImg.onload = () => { state.cameraDecoded = { width: cameraImg.naturalWidth, height: cameraImg.naturalHeight }; };
function onCameraImage(m) {
  const box = document.getElementById("camera");
  if (!state.cameraImage) { box.textContent = ""; box.appendChild(cameraImg); box.classList.add("image"); }
  state.cameraImage = true;
  state.cameraImages += 1;
  cameraImg.src = `data:image/${m.format === "png" ? "png" : "jpeg"};base64,${m.data}`;
  const t = m.timestamp ? new Date(m.timestamp.sec * 1000 + m.timestamp.nsec / 1e6) : null;
  cameraImg.title = `${m.frame_id}, captured ${t ? t.toISOString().substring(11, 23) : "?"}`;
}
const handlers = { "/reflex/scene": onSceneUpdate, "/reflex/status": onStatus, "/reflex/camera/left": onCameraImage };
function connect() {
  const ws = new WebSocket(`ws://${location.host}/`, [kSubprotocol]);
  ws.binaryType = "arraybuffer";
  const bySubscription = new Map();
  let nextId = 0;
  const label = document.getElementById("connection");
  // This connection's channels ({id: topic}): a new connection (a reconnect) starts from none, so a
  // server that advertises again is listed once.
  const channels = new Map();
  const listChannels = () => { state.channels = [...channels.values()]; };
  ws.onopen = () => {
    state.connected = true; state.connections += 1; connectedAt = performance.now();
    channels.clear(); listChannels();
    label.textContent = "connected"; label.className = "ok";
    updateStale();
  };
  ws.onclose = () => {
    state.connected = false; label.textContent = "disconnected, retrying…"; label.className = "bad";
    channels.clear(); listChannels();
    updateStale();
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => {
    if (typeof event.data === "string") {
      const m = JSON.parse(event.data);
      if (m.op === "serverInfo") {
        document.getElementById("robot").textContent = m.metadata && m.metadata.robot ? "robot: " + m.metadata.robot : "";
      } else if (m.op === "advertise") {
        const subscriptions = [];
        for (const c of m.channels) {
          if (channels.has(c.id)) continue;  // advertised again on this connection: already subscribed
          channels.set(c.id, c.topic);
          if (handlers[c.topic]) { const id = nextId++; bySubscription.set(id, handlers[c.topic]); subscriptions.push({ id, channelId: c.id }); }
        }
        listChannels();
        if (subscriptions.length) ws.send(JSON.stringify({ op: "subscribe", subscriptions }));
      } else if (m.op === "unadvertise") {
        for (const id of m.channelIds || []) channels.delete(id);
        listChannels();
      } else if (m.op === "status") {
        state.errors.push(m.message);
      }
      return;
    }
    const view = new DataView(event.data);
    if (view.getUint8(0) !== 1) return;  // only messageData (opcode 0x01) is expected
    const handler = bySubscription.get(view.getUint32(1, true));
    // bytes 5..12: uint64 timestamp [ns]; the payload (JSON) follows.
    if (handler) handler(JSON.parse(decoder.decode(new Uint8Array(event.data, 13))));
  };
}
// Drawn on demand only: one animation frame after something new (a scene, a status, the camera moved,
// the window resized), nothing while the page is idle.
function queueFrame() {
  if (renderModule !== null) return;  // static mode draws once (drawStatic)
  if (!frameQueued) { frameQueued = true; requestAnimationFrame(frame); }
}
function requestRender() { sceneDirty = true; queueFrame(); }
function requestPlot() { plotDirty = true; queueFrame(); }
function frame() {
  frameQueued = false;
  if (plotDirty) { plotDirty = false; drawPlot(); }
  if (sceneDirty) {
    sceneDirty = false;
    prepareOverlays(renderer.domElement.clientWidth || 640, renderer.domElement.clientHeight || 480);
    renderer.render(scene, camera);
    state.rendered += 1;
  }
}

// Static mode: every scene of the module in its own tile, drawn once (see the top of this file).
function drawStatic(spec) {
  const w = spec.tile.width, h = spec.tile.height, n = spec.scenes.length;
  container.style.width = `${w * n}px`;
  container.style.height = `${h}px`;
  renderer.setSize(w * n, h);
  orbit.azimuth = spec.camera.azimuth;
  orbit.elevation = spec.camera.elevation;
  orbit.radius = spec.camera.radius;
  orbit.target.set(...spec.camera.target);
  placeCamera();
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  renderer.setScissorTest(true);
  spec.scenes.forEach((s, i) => {
    onSceneUpdate(s.update);
    renderer.setViewport(i * w, 0, w, h);  // CSS px from the bottom left; one row, so y = 0
    renderer.setScissor(i * w, 0, w, h);
    prepareOverlays(w, h);
    renderer.render(scene, camera);
    state.tiles.push({ time: s.time, capsulesDrawn: state.capsulesDrawn, spheresDrawn: state.spheresDrawn,
                       closestLines: state.closestLines, targetsDrawn: state.targetsDrawn,
                       zoneColours: { ...state.zoneColours } });
  });
  state.rendered = n;
  state.staticDrawn = n;
  document.title = `Reflex view: ${n} scenes drawn`;
}

if (renderModule === null) {
  connect();
  setInterval(updateStale, 250);  // the sign's age text; touches the page's text only, never the 3D view
  updateStale();
  requestRender();
} else if (renderSpec) {
  drawStatic(renderSpec);
}
