#!/usr/bin/python3
"""Draws the robot at chosen rows of a controller time series with the live view's own renderer.

reflex_scene (this folder's C++ tool) turns the rows into the foxglove.SceneUpdate that reflex_view
sends live; the view's page (modules/view/web, static mode: index.html?render=FILE.js) draws them
with three.js in Debian's Chromium, headless with software WebGL (SwiftShader). Driven through the
DevTools protocol over --remote-debugging-pipe (no Node, no WebSocket): it waits for the page's own
signal that it has drawn (window.reflexView.staticDrawn; `chromium --screenshot` alone was tried and
often captured the page before it drew), then captures the canvas. No second drawing code: the same
view.js draws the live view.

Writes into OUT (made if missing):
  scenes.png      every tile side by side (the canvas of the page, cropped from the screenshot)
  scene_<i>.png   tile i alone (the row nearest to the i-th --at time)
  render.js       the module reflex_scene made (scenes, camera, tile size)
  screenshot.png  what Chromium captured (the canvas; kept also when the robot-pixel check fails)
  render.json     {"tiles": [{"time", "row", "png", "robot_pixels", "page"}], "tile": [w, h], "camera": {...}};
                  "page": what the page says it drew in that tile (view.js state.tiles: capsulesDrawn,
                  spheresDrawn, closestLines, targetsDrawn, zoneColours)

Exit codes: 0 drawn; 2 bad arguments; 3 Chromium, three.js or reflex_scene missing (the message says
what to install); 4 the picture was not drawn (Chromium failed, timed out, or a tile shows no robot:
fewer than --min-pixels pixels of robot colour). Every failure prints one line naming the cause: a
caller (report.py) falls back to its 2D drawing and says so, never a silent different picture.

Usage: render_scenes.py --log controller.csv --at 5.4,17.3 --out DIR [--tile 360x420]
                        [--camera AZ,EL,RADIUS,TX,TY,TZ] [--build DIR] [--chromium PATH] [--three DIR]
                        [--urdf F] [--collision F] [--controller F] [--timeout S] [--min-pixels N]
"""
import argparse
import base64
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(HERE)))
WEB = os.path.join(ROOT, "modules", "view", "web")
BACKGROUND = (0x16, 0x18, 0x1d)  # view.js scene background


def fail(code, message):
    print("render_scenes: error: " + message, file=sys.stderr)
    sys.exit(code)


def robot_pixels(tile):
    """Pixels of robot colour in an RGB(A) float image [0, 1]: far from the background and bright in red
    or green (the floor grid is dark; capsules are grey, green, yellow, orange or red)."""
    rgb = tile[:, :, :3] * 255.0
    d2 = sum((rgb[:, :, k] - BACKGROUND[k]) ** 2 for k in range(3))
    return int(((d2 > 80 * 80) & ((rgb[:, :, 0] > 120) | (rgb[:, :, 1] > 120))).sum())


class DevToolsPipe:
    """The Chrome DevTools protocol over --remote-debugging-pipe (Chromium reads JSON messages ending in
    a NUL byte from its fd 3 and writes them to its fd 4): no WebSocket, no Node needed."""

    def __init__(self, argv, deadline):
        self.deadline = deadline
        to_r, self.to_w = os.pipe()
        self.from_r, from_w = os.pipe()

        def child_fds():  # runs in the child before exec: the pipe ends become its fds 3 and 4
            os.dup2(to_r, 3)
            os.dup2(from_w, 4)
        self.proc = subprocess.Popen(argv + ["--remote-debugging-pipe"], preexec_fn=child_fds, pass_fds=(3, 4),
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        os.close(to_r)
        os.close(from_w)
        self.buf = b""
        self.next_id = 0

    def call(self, method, params=None, session=None):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.to_w, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" in self.buf:
                raw, self.buf = self.buf.split(b"\0", 1)
                m = json.loads(raw)
                if m.get("id") == self.next_id:
                    if "error" in m:
                        raise RuntimeError("%s: %s" % (method, m["error"].get("message", m["error"])))
                    return m["result"]
            ready, _, _ = select.select([self.from_r], [], [], max(0.0, self.deadline - time.time()))
            if not ready:
                raise TimeoutError("no answer to %s before the --timeout" % method)
            chunk = os.read(self.from_r, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed the DevTools pipe (exit %s): %s"
                                   % (self.proc.poll(), self.proc.stderr.read().decode(errors="replace")[-300:]))
            self.buf += chunk

    def close(self):
        try:
            self.proc.kill()
            self.proc.wait(10)
        except OSError:
            pass
        for fd in (self.to_w, self.from_r):
            os.close(fd)


def capture(chromium, url, profile, width, height, png, timeout):
    """Opens `url` in headless Chromium (software WebGL), waits until the page in static mode says it
    has drawn (window.reflexView.staticDrawn) or reports an error, and writes the top-left width x height
    CSS px of the page to `png`. Returns {"drawn", "errors", "title"} as the page reported them."""
    argv = [chromium, "--headless=new", "--use-gl=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox",
            "--no-first-run", "--no-default-browser-check", "--disable-extensions", "--allow-file-access-from-files",
            "--force-device-scale-factor=1", "--hide-scrollbars", "--window-size=%d,%d" % (width + 40, height + 200),
            "--user-data-dir=" + profile, url]
    cdp = DevToolsPipe(argv, time.time() + timeout)
    try:
        page = next((t for t in cdp.call("Target.getTargets")["targetInfos"] if t["type"] == "page"), None)
        if page is None:
            raise RuntimeError("no page target")
        session = cdp.call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})["sessionId"]
        probe = ("JSON.stringify({drawn: window.reflexView ? window.reflexView.staticDrawn : 0, "
                 "errors: window.reflexView ? window.reflexView.errors : [], "
                 "tiles: window.reflexView ? window.reflexView.tiles : [], title: document.title})")
        while True:
            state = json.loads(cdp.call("Runtime.evaluate", {"expression": probe, "returnByValue": True},
                                        session)["result"]["value"])
            if state["drawn"] or state["errors"]:
                break
            time.sleep(0.2)
        if state["drawn"]:
            shot = cdp.call("Page.captureScreenshot", {"format": "png", "clip": {"x": 0, "y": 0, "width": width,
                                                                               "height": height, "scale": 1}}, session)
            with open(png, "wb") as fh:
                fh.write(base64.b64decode(shot["data"]))
        return state
    finally:
        cdp.close()


def main():
    # SIGTERM (a test's clean-up, a user's kill) unwinds like an error, so Chromium is stopped too.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log", required=True, help="time series CSV (reflex_controller --log)")
    ap.add_argument("--at", required=True, help="times [s], comma-separated (the nearest row each)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--tile", default="360x420", help="WIDTHxHEIGHT of each scene's picture [px]")
    ap.add_argument("--camera", help="AZ,EL,RADIUS,TX,TY,TZ (reflex_scene --help; default: reflex_scene's)")
    ap.add_argument("--build", default=os.environ.get("REFLEX_BUILD_DIR", os.path.join(ROOT, "build")))
    ap.add_argument("--chromium", default=os.environ.get("REFLEX_CHROMIUM") or shutil.which("chromium")
                    or shutil.which("chromium-browser"), help="the browser (default: $REFLEX_CHROMIUM, else "
                    "chromium on PATH)")
    ap.add_argument("--three", default=os.path.join(ROOT, "bringup", "web", "node_modules", "three", "build"))
    ap.add_argument("--urdf")
    ap.add_argument("--collision")
    ap.add_argument("--controller")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds Chromium may take (loaded machine)")
    ap.add_argument("--min-pixels", type=int, default=300, help="robot pixels a tile must show")
    args = ap.parse_args()
    try:
        width, height = (int(v) for v in args.tile.split("x"))
    except ValueError:
        fail(2, "--tile '%s' is not WIDTHxHEIGHT" % args.tile)
    if not (16 <= width <= 4096 and 16 <= height <= 4096):
        fail(2, "--tile '%s': each size must be in 16..4096" % args.tile)
    scene_tool = os.path.join(args.build, "bin", "reflex_scene")
    if not os.access(scene_tool, os.X_OK):
        fail(3, "%s not found (build the target reflex_scene_tool, or give --build DIR)" % scene_tool)
    if not args.chromium or not os.access(args.chromium, os.X_OK):
        fail(3, "Chromium not found (%s): install Debian's chromium (bringup/setup.sh) or give --chromium PATH"
             % (args.chromium or "not on PATH"))
    if not os.path.isfile(os.path.join(args.three, "three.module.js")):
        fail(3, "three.js not found in %s: run npm ci in bringup/web (bringup/setup.sh), or give --three DIR"
             % args.three)
    try:
        import matplotlib.image as mpimg
    except ImportError:
        fail(3, "python3-matplotlib is needed to cut the screenshot into tiles (bringup/setup.sh)")
    os.makedirs(args.out, exist_ok=True)

    with tempfile.TemporaryDirectory(prefix="reflex-render-") as page:
        # The page's folder: the view's own files and three.js, linked, and the scenes module.
        for name in ("index.html", "view.js", "view.css"):
            os.symlink(os.path.join(WEB, name), os.path.join(page, name))
        os.symlink(os.path.abspath(args.three), os.path.join(page, "three"))
        module = os.path.join(page, "render.js")
        cmd = [scene_tool, "--log", args.log, "--at", args.at, "--out", module, "--tile", args.tile]
        for opt in ("camera", "urdf", "collision", "controller"):
            if getattr(args, opt):
                cmd += ["--" + opt, getattr(args, opt)]
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if r.returncode != 0:
            fail(2, r.stdout.strip().splitlines()[-1] if r.stdout.strip() else "reflex_scene failed (%d)" % r.returncode)
        with open(module) as fh:
            text = fh.read()
        spec = json.loads(text[text.index("export default ") + len("export default "):].rstrip().rstrip(";"))
        n = len(spec["scenes"])
        shot = os.path.join(page, "screenshot.png")
        url = "file://%s/index.html?render=render.js" % page
        try:
            drawn = capture(args.chromium, url, os.path.join(page, "profile"), width * n, height, shot, args.timeout)
        except (OSError, RuntimeError, TimeoutError) as e:
            fail(4, "Chromium: %s" % e)
        if drawn.get("errors"):
            fail(4, "the page did not draw the scenes: %s" % "; ".join(drawn["errors"]))
        if drawn.get("drawn") != n:
            fail(4, "the page drew %s of %d scenes (title '%s')" % (drawn.get("drawn"), n, drawn.get("title")))
        shutil.copy(shot, os.path.join(args.out, "screenshot.png"))  # kept: what Chromium saw, drawn or not
        image = mpimg.imread(shot)
        if image.shape[0] < height or image.shape[1] < width * n:
            fail(4, "screenshot %dx%d is smaller than the %d tiles of %dx%d" % (image.shape[1], image.shape[0], n,
                                                                              width, height))
        tiles = []
        for i, s in enumerate(spec["scenes"]):
            tile = image[:height, i * width:(i + 1) * width, :3]
            count = robot_pixels(tile)
            if count < args.min_pixels:
                fail(4, "tile %d (t = %.2f s) shows %d robot pixels (< %d): the robot is not in the picture (see %s)"
                     % (i, s["time"], count, args.min_pixels, os.path.join(args.out, "screenshot.png")))
            png = os.path.join(args.out, "scene_%d.png" % i)
            mpimg.imsave(png, tile)
            tiles.append({"time": s["time"], "row": s["row"], "png": png, "robot_pixels": count,
                          "page": drawn["tiles"][i] if i < len(drawn.get("tiles", [])) else None})
        mpimg.imsave(os.path.join(args.out, "scenes.png"), image[:height, :width * n, :3])
        shutil.copy(module, os.path.join(args.out, "render.js"))
    with open(os.path.join(args.out, "render.json"), "w") as fh:
        json.dump({"tiles": tiles, "tile": [width, height], "camera": spec["camera"]}, fh, indent=2)
    print("render_scenes: drew %d scenes into %s (%s robot pixels)"
          % (n, args.out, ", ".join(str(t["robot_pixels"]) for t in tiles)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
