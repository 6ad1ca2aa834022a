#!/usr/bin/env python3
"""How fast the `soda view` page plays in headless Chromium (software GL: SwiftShader or Mesa's
llvmpipe, --gl).

Starts `soda view --port 0 ARGS`, opens the page in headless Chromium through ChromeDriver
at a fixed window size, lets it warm up, then for --seconds counts on the page itself:
  page fps   requestAnimationFrame callbacks per second (the page's display rate);
  shown fps  distinct simulation frames drawn per second (window.soda.shown.step changing);
  received   frames that came over the WebSocket per second (window.soda.frames), and how
             many animation frames found none, one or more new frames since the last;
and reads the page's own per-frame costs (window.soda.drawMs: draw(), the vertex writing (decoding happens on arrival),
window.soda.renderMs: three.js render call; exponential averages), its render scale if it
has one (window.sodaStats), Chromium's renderer-process task/script time (CDP
Performance.getMetrics) and the CPU time of soda and of Chromium's processes (/proc).

The counters are installed by this script, not taken from the page, so pages of any version
are measured the same way. Several --runs alternate between the binaries given (A/B/A/B...),
and the medians are printed per binary. Needs python3 (standard library only), Debian's
`chromium` and `chromium-driver` (scripts/install-browser-test-deps.sh).

  scripts/measure-view-fps.py --soda target/release/soda --runs 3
  scripts/measure-view-fps.py --soda /tmp/old/soda --soda target/release/soda --runs 3
  scripts/measure-view-fps.py --query scale=1 --query scale=auto   # the page's render scale
  scripts/measure-view-fps.py --page web   # this checkout's page, without rebuilding soda
  scripts/measure-view-fps.py --floor 'n=0' --floor 'n=8000&mode=points' --runs 2   # three.js alone
  scripts/measure-view-fps.py --gl swiftshader --gl llvmpipe --runs 3   # the software GL

--gl lavapipe (Mesa's Vulkan, `scripts/install-browser-test-deps.sh --lavapipe`) is there to
try: with Mesa 22.3 and Chromium 156 it gives WebGL 1 only, and three.js needs WebGL 2.

Use it on an otherwise idle machine if you can: the page, Chromium's software GL and the
simulation share its cores, and other work moves the numbers by a factor of two.
"""

import argparse
import base64
import collections
import contextlib
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
import urllib.request

CHROME_ARGS = ["--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--ignore-gpu-blocklist"]

# The software GL behind Chromium's WebGL (--gl): Chromium's flags and the environment of
# ChromeDriver (which Chromium inherits). Each run records the renderer the page really got
# (WEBGL_debug_renderer_info) as "gl".
GL = {
    # SwiftShader (bundled with Chromium): ANGLE over SwiftShader's Vulkan, JIT-compiled.
    "swiftshader": (["--use-angle=swiftshader", "--enable-unsafe-swiftshader"], {}),
    # Mesa's llvmpipe (Debian's libgl1-mesa-dri, libegl-mesa0): ANGLE over desktop GL
    # through EGL, headless, no display needed.
    "llvmpipe": (["--use-gl=angle", "--use-angle=gl-egl", "--ozone-platform=headless"],
                 {"LIBGL_ALWAYS_SOFTWARE": "1", "GALLIUM_DRIVER": "llvmpipe"}),
    # Mesa's lavapipe (Debian's mesa-vulkan-drivers): ANGLE over Vulkan, lavapipe's ICD only.
    "lavapipe": (["--use-angle=vulkan", "--enable-features=Vulkan", "--ozone-platform=headless"],
                 {"VK_ICD_FILENAMES": "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json"}),
}

# Installed in the page: counts animation frames and distinct frames shown.
COUNTERS = """
const c = window.__measure = { raf: 0, shown: 0, last: null, t0: performance.now(), gaps: [],
  frames0: window.soda.frames, arrived: [0, 0, 0],
  unchanged0: window.soda.unchanged, renders0: window.soda.renders };
let prev = performance.now(), frames = window.soda.frames;
function tick(now) {
  c.raf++;
  c.gaps.push(now - prev); prev = now;
  // Frames that came over the WebSocket since the last animation frame: none, one, more.
  c.arrived[Math.min(2, window.soda.frames - frames)]++; frames = window.soda.frames;
  const s = window.soda && window.soda.shown ? window.soda.shown.step : null;
  if (s !== null && s !== c.last) { c.shown++; c.last = s; }
  requestAnimationFrame(tick);
}
requestAnimationFrame(tick);
return true;
"""

READ = """
const c = window.__measure, s = window.soda, now = performance.now();
const gaps = c.gaps.slice().sort((a, b) => a - b);
return { seconds: (now - c.t0) / 1000, raf: c.raf, shown: c.shown,
         gap_p50: gaps[Math.floor(gaps.length * 0.5)] || 0,
         gap_p95: gaps[Math.floor(gaps.length * 0.95)] || 0,
         draw_ms: s.drawMs, render_ms: s.renderMs, received: s.frames - c.frames0, arrived: c.arrived,
         // Pages from 2026-11-26 20:00 on: frames shown with their bodies unchanged (not placed
         // again), and render calls.
         unchanged: s.unchanged === undefined ? null : s.unchanged - c.unchanged0,
         renders: s.renders === undefined ? null : s.renders - c.renders0,
         in_sight: s.drawn === undefined ? null : s.drawn, triangles: s.triangles === undefined ? null : s.triangles,
         step: s.shown ? s.shown.step : null, buffered: s.shown ? s.shown.buffered : null,
         stats: window.sodaStats ? JSON.parse(JSON.stringify(window.sodaStats)) : null,
         canvas: [document.querySelector('canvas').width, document.querySelector('canvas').height],
         dpr: window.devicePixelRatio, gl: renderer() };
function renderer() {
  const gl = document.createElement('canvas').getContext('webgl2');
  const e = gl && gl.getExtension('WEBGL_debug_renderer_info');
  return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : null;
}
"""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def request(method, url, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method,
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=120) as r:
            return json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        raise RuntimeError(f"WebDriver {method} {url}: {e.read().decode()}") from None


def descendants(pid):
    """pid and all its descendants (from /proc)."""
    children = {}
    for p in os.listdir("/proc"):
        if not p.isdigit():
            continue
        try:
            with open(f"/proc/{p}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except OSError:
            continue
        children.setdefault(ppid, []).append(int(p))
    out, todo = [], [pid]
    while todo:
        q = todo.pop()
        out.append(q)
        todo.extend(children.get(q, []))
    return out


def cpu_seconds(pids):
    """User + system CPU seconds of each process, by its command name."""
    tick = os.sysconf("SC_CLK_TCK")
    by = {}
    for p in pids:
        try:
            with open(f"/proc/{p}/stat") as f:
                stat = f.read()
            with open(f"/proc/{p}/cmdline") as f:
                cmd = f.read().split("\0")
            if len(cmd) <= 2:   # Chromium rewrites its command line as one string
                cmd = cmd[0].split()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        t = (int(fields[11]) + int(fields[12])) / tick
        kind = next((a.split("=", 1)[1] for a in cmd if a.startswith("--type=")), None)
        name = os.path.basename(cmd[0]) + (f":{kind}" if kind else "")
        by[name] = by.get(name, 0.0) + t
    return by


Browser = collections.namedtuple("Browser", "base s js cdp driver")


@contextlib.contextmanager
def browser_session(size, gl="swiftshader"):
    """Headless Chromium through a ChromeDriver of its own, at window SIZE ("W,H"), WebGL
    drawn by GL (a key of GL).

    Yields a Browser: base (ChromeDriver's address), s (the session's address),
    js(script, *args) (runs script in the page, returns its value), cdp(cmd, params)
    (a DevTools command) and driver (the ChromeDriver process, for the CPU times of it
    and its browser). The session is deleted when the block ends normally; ChromeDriver
    is stopped either way."""
    port = free_port()
    gl_args, gl_env = GL[gl]
    driver = subprocess.Popen(["chromedriver", f"--port={port}"], env={**os.environ, **gl_env},
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        base = f"http://127.0.0.1:{port}"
        deadline = time.time() + 20
        while True:
            try:
                request("GET", base + "/status")
                break
            except OSError:
                if time.time() > deadline:
                    raise
                time.sleep(0.1)
        caps = {"capabilities": {"alwaysMatch": {"browserName": "chrome", "goog:chromeOptions": {
            "binary": "/usr/bin/chromium",
            "args": CHROME_ARGS + gl_args + [f"--window-size={size}"]}}}}
        session = request("POST", base + "/session", caps)["value"]["sessionId"]
        s = f"{base}/session/{session}"
        js = lambda script, *args: request(
            "POST", s + "/execute/sync", {"script": script, "args": list(args)})["value"]
        cdp = lambda cmd, params: request("POST", s + "/goog/cdp/execute", {"cmd": cmd, "params": params})["value"]
        # The viewport exactly SIZE, one device pixel per CSS pixel.
        w, h = (int(x) for x in size.split(","))
        cdp("Emulation.setDeviceMetricsOverride",
            {"width": w, "height": h, "deviceScaleFactor": 1, "mobile": False})
        yield Browser(base, s, js, cdp, driver)
        request("DELETE", s)
    finally:
        driver.kill()
        driver.wait()


def stop(static, viewer):
    """Stops the static file server (if any) and soda view (if any: SIGINT, then kill after 10 s)."""
    if static:
        static.kill()
        static.wait()
    if viewer:
        viewer.send_signal(signal.SIGINT)
        try:
            viewer.wait(10)
        except subprocess.TimeoutExpired:
            viewer.kill()
            viewer.wait()


def measure(soda, view_args, seconds, warmup, size, page, screenshot=None, query="", gl="swiftshader"):
    viewer = subprocess.Popen([soda, "view", "--port", "0", *view_args],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    static = None
    try:
        first = viewer.stdout.readline()
        if "http://" not in first:
            raise RuntimeError(f"soda view printed no address: {first!r}")
        url = "http://" + first.split("http://", 1)[1].split("/", 1)[0] + "/"
        if page:
            # The page's files from a directory, connected to this viewer's WebSocket.
            ws = url[len("http://"):-1]
            pport = free_port()
            static = subprocess.Popen([sys.executable, "-m", "http.server", "--bind", "127.0.0.1",
                                       str(pport), "--directory", page],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(0.5)
            url = f"http://127.0.0.1:{pport}/?ws={ws}"
        if query:
            url += ("&" if "?" in url else "?") + query
        with browser_session(size, gl) as b:
            js, cdp = b.js, b.cdp
            request("POST", b.s + "/url", {"url": url})
            deadline = time.time() + 60
            while not js("return !!(window.soda && window.soda.frames > 10)"):
                if time.time() > deadline:
                    raise RuntimeError("no frames on the page within 60 s")
                time.sleep(0.2)
            time.sleep(warmup)
            cdp("Performance.enable", {})
            m0 = {m["name"]: m["value"] for m in cdp("Performance.getMetrics", {})["metrics"]}
            pids = [viewer.pid] + descendants(b.driver.pid)
            c0 = cpu_seconds(pids)
            load0 = os.getloadavg()[0]
            js(COUNTERS)
            time.sleep(seconds)
            r = js(READ)
            load1 = os.getloadavg()[0]
            c1 = cpu_seconds(pids)
            m1 = {m["name"]: m["value"] for m in cdp("Performance.getMetrics", {})["metrics"]}
            if screenshot:
                png = request("GET", b.s + "/screenshot")["value"]
                with open(screenshot, "wb") as f:
                    f.write(base64.b64decode(png))
    finally:
        stop(static, viewer)
    wall = r["seconds"]
    cpu = {k: round((c1.get(k, 0) - c0.get(k, 0)) / wall, 2) for k in c1}
    return {
        "page_fps": round(r["raf"] / wall, 1),
        "shown_fps": round(r["shown"] / wall, 1),
        # Frames received per second, and animation frames that found 0, 1, 2+ new frames.
        "received_fps": round(r["received"] / wall, 1),
        "arrived_per_tick": r["arrived"],
        # Frames shown whose bodies were those of the frame before (the page neither placed
        # nor, without flashes, rendered them), and render calls, per second.
        "unchanged_fps": None if r["unchanged"] is None else round(r["unchanged"] / wall, 1),
        "renders_per_s": None if r["renders"] is None else round(r["renders"] / wall, 1),
        "gap_ms_p50": round(r["gap_p50"], 1),
        "gap_ms_p95": round(r["gap_p95"], 1),
        "draw_ms": round(r["draw_ms"], 2),
        "render_ms": round(r["render_ms"], 2),
        "renderer_task_s_per_s": round((m1["TaskDuration"] - m0["TaskDuration"]) / wall, 2),
        "renderer_script_s_per_s": round((m1["ScriptDuration"] - m0["ScriptDuration"]) / wall, 2),
        "cpu_per_process": {k: v for k, v in sorted(cpu.items()) if v >= 0.01},
        "loadavg": [round(load0, 1), round(load1, 1)],   # 1-minute load, this run's own included
        "canvas": r["canvas"],
        "scale": (r["stats"] or {}).get("scale", 1),
        "stats": r["stats"],
        "buffered": r["buffered"],
        "in_sight": r["in_sight"],
        "triangles": r["triangles"],
        "renderer": r["gl"],
    }


def floor(query, seconds, warmup, size, gl="swiftshader"):
    """scripts/view-floor.html?QUERY (three.js alone) in the same browser set-up: page fps."""
    import shutil
    import tempfile
    here = os.path.dirname(os.path.abspath(__file__))
    with tempfile.TemporaryDirectory() as d:
        shutil.copy(os.path.join(here, "view-floor.html"), os.path.join(d, "index.html"))
        os.symlink(os.path.join(here, "..", "web", "vendor"), os.path.join(d, "vendor"))
        pport = free_port()
        static = subprocess.Popen([sys.executable, "-m", "http.server", "--bind", "127.0.0.1",
                                   str(pport), "--directory", d],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            with browser_session(size, gl) as b:
                request("POST", b.s + "/url", {"url": f"http://127.0.0.1:{pport}/index.html?{query}"})
                time.sleep(warmup)
                b.js(COUNTERS)
                time.sleep(seconds)
                r = b.js(READ)
        finally:
            stop(static, None)
    return {"page_fps": round(r["raf"] / r["seconds"], 1),
            "gap_ms_p50": round(r["gap_p50"], 1), "gap_ms_p95": round(r["gap_p95"], 1),
            "update_ms": round(r["draw_ms"], 2), "render_ms": round(r["render_ms"], 2),
            "loadavg": round(os.getloadavg()[0], 1), "renderer": r["gl"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--soda", action="append", help="soda binary (repeat to compare; runs alternate)")
    ap.add_argument("--page", action="append",
                    help="serve the page from this directory instead of the binary's own "
                         "(the page must take ?ws=HOST:PORT); repeat to compare pages")
    ap.add_argument("--runs", type=int, default=3, help="runs per binary")
    ap.add_argument("--seconds", type=float, default=20)
    ap.add_argument("--warmup", type=float, default=5)
    ap.add_argument("--window-size", default="1280,720")
    ap.add_argument("--query", action="append",
                    help="add this query to the page's address (e.g. scale=1); repeat to compare")
    ap.add_argument("--floor", action="append",
                    help="instead of soda view, measure scripts/view-floor.html?FLOOR (three.js "
                         "alone: e.g. n=8000&mode=points); repeat to compare")
    ap.add_argument("--gl", action="append", choices=sorted(GL),
                    help="the software GL Chromium draws WebGL with (default swiftshader); "
                         "repeat to compare")
    ap.add_argument("--screenshot", help="save a screenshot of each run's page as PREFIX-N.png")
    ap.add_argument("view_args", nargs="*",
                    default=["--objects", "8000", "--threads", "2", "--worlds", "8"],
                    help="soda view options (after --)")
    a = ap.parse_args()
    gls = a.gl or ["swiftshader"]
    if a.floor:
        print(f"# scripts/view-floor.html, {a.seconds:g} s after {a.warmup:g} s, window {a.window_size}; "
              f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", flush=True)
        results = {(q, g): [] for q in a.floor for g in gls}
        for run in range(a.runs):
            for q in a.floor:
                for g in gls:
                    r = floor(q, a.seconds, a.warmup, a.window_size, g)
                    results[(q, g)].append(r)
                    print(json.dumps({"floor": q, "gl": g, "run": run + 1, **r}), flush=True)
        print("# medians: page_fps, gap_ms_p50, gap_ms_p95")
        for (q, g), rs in results.items():
            print(f"floor {q} gl {g}: " + ", ".join(
                f"{k} {statistics.median(r[k] for r in rs):g}" for k in ["page_fps", "gap_ms_p50", "gap_ms_p95"]))
        return 0
    binaries = a.soda or ["target/release/soda"]
    pages = a.page or [None]
    queries = a.query or [""]
    variants = [(b, p, q, g) for b in binaries for p in pages for q in queries for g in gls]
    print(f"# soda view {' '.join(a.view_args)}; {a.seconds:g} s measured after {a.warmup:g} s, "
          f"window {a.window_size}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", flush=True)
    results = {v: [] for v in variants}
    for run in range(a.runs):
        for i, (b, p, q, g) in enumerate(variants):
            shot = f"{a.screenshot}-{run + 1}-{i}.png" if a.screenshot else None
            r = measure(b, a.view_args, a.seconds, a.warmup, a.window_size, p, shot, q, g)
            results[(b, p, q, g)].append(r)
            print(json.dumps({"soda": b, "page": p, "query": q, "gl": g, "run": run + 1, **r}), flush=True)
    keys = ["page_fps", "shown_fps", "received_fps", "gap_ms_p50", "gap_ms_p95", "draw_ms", "render_ms",
            "renderer_task_s_per_s", "scale", "unchanged_fps", "renders_per_s"]
    print("# medians: " + ", ".join(keys))
    for (b, p, q, g), rs in results.items():
        def median(k):
            xs = [r[k] for r in rs if r[k] is not None]
            return f"{statistics.median(xs):g}" if xs else "-"
        print(f"{b}{' page ' + p if p else ''}{' ?' + q if q else ''} gl {g}: "
              + ", ".join(f"{k} {median(k)}" for k in keys))

if __name__ == "__main__":
    sys.exit(main())
