#!/usr/bin/env python3
"""Does the viewer page's culling change the picture? Renders the same frame with and without.

Starts `soda view --port 0 ARGS` (default: 8,000 falling cubes), opens the page in headless
Chromium at full render scale (?scale=1), lets the run go --warmup seconds, pauses the
display, then for several camera views renders the paused frame twice in one task — with
culling (web/occlusion.js) and with every body sent to the GL (window.soda.cull = false) —
and counts the pixels that differ. Prints, per view, the bodies in sight against the total
and the differing pixels; --screenshot PREFIX saves PREFIX-VIEW-cull.png and -all.png.
--flag lod compares the balls' levels of detail instead (window.soda.lod on and off; these
do change pixels, at the edges of small balls), --scale the render scale (default 1).
Same browser set-up as scripts/measure-view-fps.py (whose helpers it uses).

  scripts/check-view-cull.py
  scripts/check-view-cull.py --page web -- --scene sparse-gas --objects 8000 --threads 2 --worlds 8
"""
import argparse
import base64
import importlib.util
import os
import subprocess
import sys
import time

here = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("measure", os.path.join(here, "measure-view-fps.py"))
measure = importlib.util.module_from_spec(spec)
spec.loader.exec_module(measure)

# Camera views: the page's own, then orbits around its target (azimuth, elevation in
# degrees, distance as a factor of the page's own), one from close by.
VIEWS = [("page", None), ("left", (90, 0, 1)), ("behind", (180, 10, 1)), ("above", (30, 60, 1)),
         ("low", (-60, -15, 1)), ("close", (20, 0, 0.35))]

SET_VIEW = """
const [az, el, k] = arguments[0], c = window.soda.camera, t = window.soda.controls.target;
const o = c.position.clone().sub(t), r = o.length() * k;
const a = Math.atan2(o.x, o.z) + az * Math.PI / 180;
const e = Math.min(1.5, Math.max(-1.5, Math.asin(o.y / o.length()) + el * Math.PI / 180));
c.position.set(t.x + r * Math.cos(e) * Math.sin(a), t.y + r * Math.sin(e), t.z + r * Math.cos(e) * Math.cos(a));
c.lookAt(t);
window.soda.controls.update();
return true;
"""

# Renders with and without culling in one task and compares the pixels.
COMPARE = """
const s = window.soda, flag = arguments[1], gl = s.renderNow(), read = (on) => {
  s[flag] = on;
  const gl = s.renderNow(), c = document.createElement('canvas');
  c.width = gl.width; c.height = gl.height;
  const g = c.getContext('2d');
  g.drawImage(gl, 0, 0);
  return { px: g.getImageData(0, 0, c.width, c.height).data, drawn: s.drawn, triangles: s.triangles };
};
const a = read(true), b = read(false);
let diff = 0;
const where = [], W = gl.width;
for (let i = 0; i < a.px.length; i += 4) {
  if (a.px[i] !== b.px[i] || a.px[i + 1] !== b.px[i + 1] || a.px[i + 2] !== b.px[i + 2]) {
    if (++diff <= 5) where.push([(i / 4) % W, Math.floor(i / 4 / W), Array.from(a.px.slice(i, i + 3)), Array.from(b.px.slice(i, i + 3))]);
  }
}
s[flag] = arguments[0];
s.renderNow();
return { in_sight: a.drawn, bodies: b.drawn, triangles: [a.triangles, b.triangles], pixels: a.px.length / 4, differing: diff, where };
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--soda", default="target/release/soda")
    ap.add_argument("--page", help="serve the page from this directory (takes ?ws=HOST:PORT)")
    ap.add_argument("--warmup", type=float, default=8)
    ap.add_argument("--window-size", default="1280,720")
    ap.add_argument("--screenshot", help="save PREFIX-VIEW-cull.png and PREFIX-VIEW-all.png")
    ap.add_argument("--flag", default="cull", choices=["cull", "lod"], help="what to switch off")
    ap.add_argument("--scale", default="1", help="the page's render scale")
    ap.add_argument("--gl", default="swiftshader", choices=sorted(measure.GL),
                    help="the software GL Chromium draws WebGL with (as in measure-view-fps.py)")
    ap.add_argument("view_args", nargs="*", help="soda view options (after --)")
    a = ap.parse_args()
    view_args = a.view_args or ["--objects", "8000", "--threads", "2", "--worlds", "8"]
    viewer = subprocess.Popen([a.soda, "view", "--port", "0", *view_args],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    static = None
    worst = 0
    try:
        first = viewer.stdout.readline()
        url = "http://" + first.split("http://", 1)[1].split("/", 1)[0] + "/"
        if a.page:
            ws = url[len("http://"):-1]
            pport = measure.free_port()
            static = subprocess.Popen([sys.executable, "-m", "http.server", "--bind", "127.0.0.1",
                                       str(pport), "--directory", a.page],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(0.5)
            url = f"http://127.0.0.1:{pport}/?ws={ws}"
        url += ("&" if "?" in url else "?") + f"scale={a.scale}"
        with measure.browser_session(a.window_size, a.gl) as b:
            js = b.js
            measure.request("POST", b.s + "/url", {"url": url})
            deadline = time.time() + 60
            while not js("return !!(window.soda && window.soda.frames > 10 && window.soda.shown)"):
                if time.time() > deadline:
                    raise RuntimeError("no frames on the page within 60 s")
                time.sleep(0.2)
            time.sleep(a.warmup)
            js("window.soda.pause(); return true")
            while not js("return window.soda.shown.paused"):
                time.sleep(0.1)
            time.sleep(0.5)
            step = js("return window.soda.shown.step")
            print(f"# soda view {' '.join(view_args)}; step {step}; {a.window_size} at render scale {a.scale};"
                  f" {a.flag} on against off; gl {a.gl}")
            home = js("const c = window.soda.camera; return c.position.toArray()")
            for name, view in VIEWS:
                js("window.soda.camera.position.fromArray(arguments[0]); window.soda.controls.update(); return true", home)
                if view:
                    js(SET_VIEW, list(view))
                r = js(COMPARE, True, a.flag)
                worst = max(worst, r["differing"])
                print(f"{name:7} in sight {r['in_sight']:5} of {r['bodies']:5}, triangles {r['triangles'][0]:6} of {r['triangles'][1]:6}; differing pixels {r['differing']} of {r['pixels']}"
                      + (f" (x, y, culled, all: {r['where']})" if r["where"] else ""))
                if a.screenshot:
                    for on, tag in ((False, "all" if a.flag == "cull" else "fine"), (True, a.flag)):
                        js("window.soda[arguments[1]] = arguments[0]; window.soda.renderNow(); return true", on, a.flag)
                        png = measure.request("GET", b.s + "/screenshot")["value"]
                        with open(f"{a.screenshot}-{name}-{tag}.png", "wb") as f:
                            f.write(base64.b64decode(png))
    finally:
        measure.stop(static, viewer)
    sys.exit(1 if worst > 0 else 0)


if __name__ == "__main__":
    main()
