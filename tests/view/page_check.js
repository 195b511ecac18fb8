// The live view's page in a real browser: starts Debian's Chromium headless with
// software WebGL (SwiftShader), opens reflex_view's page, and drives it through the Chrome DevTools
// protocol over the `ws` package (Runtime.evaluate reads window.reflexView; Page.captureScreenshot
// keeps a PNG). Independent answers, counted here:
//   - expected capsules / spheres from the URDF text (as ws_client_check.js);
//   - "robot pixels": the 3D canvas read back through a 2D canvas, pixels far from the background
//     colour, so a page that claims to draw but renders nothing fails;
//   - page errors (exceptions, console errors) collected from the DevTools events;
//   - labels: in the same instant as the render they describe, the pixels of each label's box (as the
//     page reports it) in the label's colour, so a label listed but not drawn counts 0;
//   - the closest-pair bars: pixels near white (the bar's colour, no other colour of the scene) in the
//     box around each bar's ends (a 1-pixel line of the zone's colour counted 0).
// With --phases full the run follows a system the C++ test changes under it, and prints a line
// "PHASE <name>" when it has seen each state (the test then makes the next change):
//   nodata-seen  the page is connected and shows the "no data yet" sign (no controller yet);
//   live-seen    frames and a status arrived (the test then records a few seconds of the live data);
//   live-done    the live checks above are done (the test then stops the data);
//   stale-done   the "stale" sign appeared; renders counted over one idle second, then one wheel event
//                (one render expected); a second screenshot, FILE-stale.png (the test then restarts
//                reflex_view on the same port and plays a recording in a loop);
//   then: the page reconnected (connections 2), data flows again (no sign), time went back at the
//   loop (a new plot trace, no backward step in the plot), each channel listed once.
// Prints one JSON line (the C++ test asserts on it). Exit 1 if the browser cannot be driven.
// Usage: node page_check.js --url http://127.0.0.1:PORT/ --urdf FILE --modules DIR --chromium PATH
//        --screenshot FILE.png [--seconds S] [--phases live|full]
"use strict";
const fs = require("fs");
const os = require("os");
const path = require("path");
const http = require("http");
const { spawn } = require("child_process");

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, "")] = process.argv[i + 1];
for (const k of ["url", "urdf", "modules", "chromium", "screenshot"]) {
  if (!args[k]) { console.error(`page_check: --${k} is required`); process.exit(2); }
}
const seconds = Number(args.seconds || 4);
const fullRun = args.phases === "full";
const WebSocket = require(path.join(path.resolve(args.modules), "ws"));

const urdf = fs.readFileSync(args.urdf, "utf8").replace(/<!--[\s\S]*?-->/g, "");
let expectedCapsules = 0, expectedSpheres = 0;
for (const block of urdf.match(/<collision[\s>][\s\S]*?<\/collision>/g) || []) {
  if (/<cylinder[\s/>]/.test(block) || /<box[\s/>]/.test(block)) expectedCapsules += 1;
  else if (/<sphere[\s/>]/.test(block)) expectedSpheres += 1;
}

function fail(message) {
  console.error("page_check: " + message);
  cleanup();
  process.exit(1);
}
const profile = fs.mkdtempSync(path.join(os.tmpdir(), "reflex-page-check-"));
const browser = spawn(args.chromium, [
  "--headless=new", "--use-gl=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox", "--no-first-run",
  "--no-default-browser-check", "--disable-extensions", "--window-size=1400,800", "--remote-debugging-port=0",
  `--user-data-dir=${profile}`, args.url,
], { stdio: ["ignore", "ignore", "pipe"] });
function cleanup() {
  try { browser.kill("SIGTERM"); } catch (e) { /* already gone */ }
  try { fs.rmSync(profile, { recursive: true, force: true }); } catch (e) { /* best effort */ }
}
browser.on("error", (e) => fail(`cannot start ${args.chromium}: ${e.message}`));
const giveUpSeconds = fullRun ? 150 : 60;
const giveUp = setTimeout(() => fail(`timed out (${giveUpSeconds} s)`), giveUpSeconds * 1000);

let stderr = "";
browser.stderr.on("data", (chunk) => {
  stderr += chunk.toString();
  const m = stderr.match(/DevTools listening on (ws:\/\/[^\s]+)/);
  if (m && !browser.devtools) { browser.devtools = m[1]; findPage(new URL(m[1]).port); }
});

function getJson(port, what, done) {
  http.get({ host: "127.0.0.1", port, path: what }, (res) => {
    let body = "";
    res.on("data", (c) => { body += c; });
    res.on("end", () => done(JSON.parse(body)));
  }).on("error", (e) => fail(`DevTools ${what}: ${e.message}`));
}
function findPage(port, tries = 0) {
  getJson(port, "/json/list", (targets) => {
    const page = targets.find((t) => t.type === "page" && t.url.startsWith(args.url.replace(/\/$/, "")));
    if (page) drive(page.webSocketDebuggerUrl);
    else if (tries < 50) setTimeout(() => findPage(port, tries + 1), 200);
    else fail("no page target for " + args.url + " in " + JSON.stringify(targets.map((t) => t.url)));
  });
}

function drive(url) {
  const ws = new WebSocket(url);
  let nextId = 1;
  const pending = new Map();
  const pageErrors = [];
  const call = (method, params = {}) => new Promise((resolve, reject) => {
    const id = nextId++;
    pending.set(id, { resolve, reject });
    ws.send(JSON.stringify({ id, method, params }));
  });
  const evaluate = async (expression) => {
    const r = await call("Runtime.evaluate", { expression, returnByValue: true, awaitPromise: true });
    if (r.exceptionDetails) throw new Error("evaluate: " + JSON.stringify(r.exceptionDetails).slice(0, 300));
    return r.result.value;
  };
  ws.on("message", (data) => {
    const m = JSON.parse(data.toString());
    if (m.id && pending.has(m.id)) {
      const p = pending.get(m.id);
      pending.delete(m.id);
      m.error ? p.reject(new Error(JSON.stringify(m.error))) : p.resolve(m.result);
    } else if (m.method === "Runtime.exceptionThrown") {
      pageErrors.push(m.params.exceptionDetails.exception ? m.params.exceptionDetails.exception.description : m.params.exceptionDetails.text);
    } else if (m.method === "Runtime.consoleAPICalled" && m.params.type === "error") {
      pageErrors.push(m.params.args.map((a) => a.value || a.description).join(" "));
    }
  });
  ws.on("error", (e) => fail("DevTools WebSocket: " + e.message));
  ws.on("open", async () => {
    try {
      await call("Runtime.enable");
      await call("Page.enable");
      const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
      const snapshot = () => evaluate("window.reflexView ? JSON.parse(JSON.stringify(window.reflexView)) : null");
      // Polls the page's state until `ok(view)` or `ms` pass; the last state.
      const waitFor = async (ok, ms) => {
        const t0 = Date.now();
        for (;;) {
          const v = await snapshot();
          if ((v && ok(v)) || Date.now() - t0 > ms) return v;
          await sleep(100);
        }
      };
      const screenshot = async (file) => {
        const shot = await call("Page.captureScreenshot", { format: "png" });
        fs.mkdirSync(path.dirname(path.resolve(file)), { recursive: true });
        fs.writeFileSync(file, Buffer.from(shot.data, "base64"));
        return path.resolve(file);
      };
      const sign = () => evaluate(`(() => { const e = document.getElementById('stale'); const r = e.getBoundingClientRect();
        return { shown: !e.hidden && r.width > 0 && r.height > 0 && getComputedStyle(e).display !== 'none',
                 text: e.textContent }; })()`);
      const result = { expectedCapsules, expectedSpheres, pageErrors, waitSeconds: seconds };

      if (fullRun) {  // the page before any controller: connected, and the "no data yet" sign
        const v = await waitFor((x) => x.connected && x.stale, 20000);
        result.nodata = { view: v, sign: await sign() };
        console.log("PHASE nodata-seen");
      }

      let view = await waitFor((x) => x.framesReceived >= 10 && x.statusReceived > 0 && x.rendered > 5, 40000);
      console.log("PHASE live-seen");  // data flows: the test records the next seconds of it
      const framesBefore = view ? view.framesReceived : 0;
      await sleep(seconds * 1000);
      result.liveSign = await sign();
      // One task: the state of the last render and the canvas it left (drawing buffer preserved).
      const live = await evaluate(`(() => {
        const view = JSON.parse(JSON.stringify(window.reflexView));
        const src = document.querySelector('#scene3d canvas');
        const c = document.createElement('canvas'); c.width = src.width; c.height = src.height;
        const g = c.getContext('2d'); g.drawImage(src, 0, 0);
        const d = g.getImageData(0, 0, c.width, c.height).data;
        let robot = 0;
        for (let i = 0; i < d.length; i += 4) {
          const dr = d[i] - 0x16, dg = d[i + 1] - 0x18, db = d[i + 2] - 0x1d;
          if (dr * dr + dg * dg + db * db > 80 * 80 && (d[i] > 120 || d[i + 1] > 120)) robot++;
        }
        const k = view.dpr || 1;
        const count = (x0, y0, x1, y1, match) => {
          let n = 0;
          for (let y = Math.max(0, Math.floor(y0 * k)); y < Math.min(c.height, Math.ceil(y1 * k)); ++y)
            for (let x = Math.max(0, Math.floor(x0 * k)); x < Math.min(c.width, Math.ceil(x1 * k)); ++x) {
              const i = 4 * (y * c.width + x);
              if (match(d[i], d[i + 1], d[i + 2])) n++;
            }
          return n;
        };
        const labelPixels = view.labels.map((l) => {
          const r = parseInt(l.colour.slice(1, 3), 16), gg = parseInt(l.colour.slice(3, 5), 16), b = parseInt(l.colour.slice(5, 7), 16);
          return { entity: l.entity, text: l.text, pixels: count(l.x, l.y, l.x + l.w, l.y + l.h,
            (pr, pg, pb) => (pr - r) ** 2 + (pg - gg) ** 2 + (pb - b) ** 2 < 60 * 60) };
        });
        const closestPixels = view.closest.map((cl) => ({ arm: cl.arm, label: cl.label,
          pixels: count(Math.min(cl.a[0], cl.b[0]) - 8, Math.min(cl.a[1], cl.b[1]) - 8,
                        Math.max(cl.a[0], cl.b[0]) + 8, Math.max(cl.a[1], cl.b[1]) + 8,
                        (pr, pg, pb) => pr >= 235 && pg >= 235 && pb >= 235) }));
        return { view, robot, width: c.width, height: c.height, labelPixels, closestPixels };
      })()`);
      view = live.view;
      Object.assign(result, {
        view, framesDuringWait: view.framesReceived - framesBefore, robotPixels: live.robot,
        canvas: [live.width, live.height], labelPixels: live.labelPixels, closestPixels: live.closestPixels,
        cameraPanel: await evaluate("document.getElementById('camera').textContent"),
        // The camera panel's image as the browser shows it: decoded size and the box it fills.
        cameraImg: await evaluate(`(() => { const i = document.querySelector('#camera img');
          if (!i) return null; const b = i.getBoundingClientRect();
          return { complete: i.complete, naturalWidth: i.naturalWidth, naturalHeight: i.naturalHeight,
                   shownWidth: Math.round(b.width), shownHeight: Math.round(b.height) }; })()`),
        screenshot: await screenshot(args.screenshot),
      });
      if (fullRun) {
        console.log("PHASE live-done");
        // The data stops: the sign within a few seconds; then nothing is drawn while nothing changes.
        const t0 = Date.now();
        let v = await waitFor((x) => x.stale, 15000);
        const stale = { view: v, afterMs: Date.now() - t0, sign: await sign() };
        await sleep(300);
        const before = await snapshot();
        await sleep(1000);
        const after = await snapshot();
        stale.idleRenders = after.rendered - before.rendered;
        stale.idlePlots = after.plotsDrawn - before.plotsDrawn;
        stale.idleFrames = after.framesReceived - before.framesReceived;
        // The camera moves (wheel over the 3D view): drawn again.
        const box = await evaluate(`(() => { const r = document.querySelector('#scene3d canvas').getBoundingClientRect();
          return [r.left + r.width / 2, r.top + r.height / 2]; })()`);
        await call("Input.dispatchMouseEvent", { type: "mouseWheel", x: box[0], y: box[1], deltaX: 0, deltaY: 120 });
        await sleep(500);
        stale.wheelRenders = (await snapshot()).rendered - after.rendered;
        stale.signLater = await sign();
        stale.screenshot = await screenshot(args.screenshot.replace(/\.png$/, "") + "-stale.png");
        result.stale = stale;
        console.log("PHASE stale-done");
        // reflex_view restarted, a recording played in a loop: reconnected, data again, a new trace.
        const framesAtStale = after.framesReceived;
        v = await waitFor((x) => x.connections >= 2 && x.connected && x.framesReceived > framesAtStale + 10 && !x.stale,
                          40000);
        const resumed = { view: v, sign: await sign() };
        v = await waitFor((x) => x.plotTraces >= 2, 20000);  // the replay's start, then its first loop
        await sleep(500);
        resumed.final = await snapshot();
        result.resumed = resumed;
      }
      console.log(JSON.stringify(result));
      clearTimeout(giveUp);
      ws.close();
      cleanup();
      process.exit(0);
    } catch (e) {
      fail(e.message);
    }
  });
}
