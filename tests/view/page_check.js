// The live view's page in a real browser: starts Debian's Chromium headless with
// software WebGL (SwiftShader), opens reflex_view's page, and drives it through the Chrome DevTools
// protocol over the `ws` package (Runtime.evaluate reads window.reflexView; Page.captureScreenshot
// keeps a PNG). Independent answers, counted here:
//   - expected capsules / spheres from the URDF text (as ws_client_check.js);
//   - "robot pixels": the 3D canvas read back through a 2D canvas, pixels far from the background
//     colour, so a page that claims to draw but renders nothing fails;
//   - page errors (exceptions, console errors) collected from the DevTools events.
// Prints one JSON line (the C++ test asserts on it). Exit 1 if the browser cannot be driven.
// Usage: node page_check.js --url http://127.0.0.1:PORT/ --urdf FILE --modules DIR --chromium PATH
//        --screenshot FILE.png [--seconds S]
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
const giveUp = setTimeout(() => fail("timed out (60 s)"), 60000);

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
      let view = null;
      const t0 = Date.now();
      for (;;) {  // until the page has drawn a few scenes (or 30 s)
        view = await evaluate("window.reflexView ? JSON.parse(JSON.stringify(window.reflexView)) : null");
        if (view && view.framesReceived >= 10 && view.statusReceived > 0 && view.rendered > 5) break;
        if (Date.now() - t0 > 30000) break;
        await sleep(250);
      }
      const framesBefore = view ? view.framesReceived : 0;
      await sleep(seconds * 1000);
      view = await evaluate("JSON.parse(JSON.stringify(window.reflexView))");
      const pixels = await evaluate(`(() => {
        const src = document.querySelector('#scene3d canvas');
        const c = document.createElement('canvas'); c.width = src.width; c.height = src.height;
        const g = c.getContext('2d'); g.drawImage(src, 0, 0);
        const d = g.getImageData(0, 0, c.width, c.height).data;
        let robot = 0;
        for (let i = 0; i < d.length; i += 4) {
          const dr = d[i] - 0x16, dg = d[i + 1] - 0x18, db = d[i + 2] - 0x1d;
          if (dr * dr + dg * dg + db * db > 80 * 80 && (d[i] > 120 || d[i + 1] > 120)) robot++;
        }
        return { robot, width: c.width, height: c.height };
      })()`);
      const camera = await evaluate("document.getElementById('camera').textContent");
      const shot = await call("Page.captureScreenshot", { format: "png" });
      fs.mkdirSync(path.dirname(path.resolve(args.screenshot)), { recursive: true });
      fs.writeFileSync(args.screenshot, Buffer.from(shot.data, "base64"));
      console.log(JSON.stringify({
        expectedCapsules, expectedSpheres, view, framesDuringWait: view.framesReceived - framesBefore,
        waitSeconds: seconds, robotPixels: pixels.robot, canvas: [pixels.width, pixels.height], cameraPanel: camera,
        pageErrors, screenshot: path.resolve(args.screenshot),
      }));
      clearTimeout(giveUp);
      ws.close();
      cleanup();
      process.exit(0);
    } catch (e) {
      fail(e.message);
    }
  });
}
