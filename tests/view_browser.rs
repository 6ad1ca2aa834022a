//! `soda view` in a real headless Chromium driven over WebDriver (Debian's `chromium` and
//! `chromium-driver`; `scripts/install-browser-test-deps.sh` installs them and `.ci/run`
//! runs this test with `--ignored`): the page draws the bodies, a click on a body becomes
//! an input the server stamps, and replaying the saved run gives the hash the page shows.

mod view_support;

use base64::Engine;
use serde_json::{json, Value};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use view_support::{run_hash, Viewer};

/// A ChromeDriver process and one headless Chromium session.
struct Browser {
    driver: Child,
    base: String,
    session: String,
}

impl Browser {
    fn start() -> Browser {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let driver = Command::new("chromedriver")
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver runs: scripts/install-browser-test-deps.sh installs it");
        let base = format!("http://127.0.0.1:{port}");
        let deadline = Instant::now() + Duration::from_secs(20);
        while ureq::get(&format!("{base}/status")).call().is_err() {
            assert!(
                Instant::now() < deadline,
                "chromedriver did not answer in 20 s"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": "/usr/bin/chromium",
                "args": ["--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                         "--window-size=1280,860", "--use-angle=swiftshader",
                         "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"]
            }
        }}});
        let mut b = Browser {
            driver,
            base,
            session: String::new(),
        };
        let r = b.post("/session", caps);
        b.session = r["sessionId"].as_str().expect("a session").to_string();
        b
    }

    fn post(&self, path: &str, body: Value) -> Value {
        let url = if path == "/session" {
            format!("{}{path}", self.base)
        } else {
            format!("{}/session/{}{path}", self.base, self.session)
        };
        let text = ureq::post(&url)
            .config()
            .http_status_as_error(false)
            .build()
            .send_json(body)
            .expect("WebDriver answers")
            .into_body()
            .read_to_string()
            .unwrap();
        let v: Value = serde_json::from_str(&text).unwrap();
        assert!(v["value"]["error"].is_null(), "WebDriver {path}: {text}");
        v.get("sessionId")
            .cloned()
            .map_or(v["value"].clone(), |_| v)
    }

    fn js(&self, script: &str) -> Value {
        self.post("/execute/sync", json!({"script": script, "args": []}))
    }

    fn wait_for(&self, what: &str, script: &str) -> Value {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let v = self.js(script);
            if !v.is_null() && v != json!(false) {
                return v;
            }
            assert!(Instant::now() < deadline, "no {what} within 60 s");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn click_at(&self, x: f64, y: f64) {
        self.post(
            "/actions",
            json!({"actions": [{"type": "pointer", "id": "mouse",
                "parameters": {"pointerType": "mouse"},
                "actions": [
                    {"type": "pointerMove", "duration": 0, "x": x.round() as i64, "y": y.round() as i64, "origin": "viewport"},
                    {"type": "pointerDown", "button": 0},
                    {"type": "pointerUp", "button": 0}]}]}),
        );
    }

    fn click_element(&self, css: &str) {
        let e = self.post("/element", json!({"using": "css selector", "value": css}));
        let id = e
            .as_object()
            .and_then(|o| o.values().next())
            .and_then(Value::as_str)
            .expect("the element")
            .to_string();
        self.post(&format!("/element/{id}/click"), json!({}));
    }

    fn screenshot(&self) -> Vec<u8> {
        let url = format!("{}/session/{}/screenshot", self.base, self.session);
        let text = ureq::get(&url)
            .call()
            .unwrap()
            .into_body()
            .read_to_string()
            .unwrap();
        let v: Value = serde_json::from_str(&text).unwrap();
        base64::engine::general_purpose::STANDARD
            .decode(v["value"].as_str().unwrap())
            .unwrap()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = ureq::delete(&format!("{}/session/{}", self.base, self.session)).call();
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// Pixels, and those of a saturated colour (bodies are tinted by world; the background,
/// ground and walls are grey).
fn pixel_census(png_bytes: &[u8]) -> (usize, usize, usize) {
    let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let mut saturated = 0;
    let mut colours = std::collections::BTreeSet::new();
    let px = buf[..info.buffer_size()].chunks(channels);
    let total = px.len();
    for p in px {
        let (r, g, b) = (p[0] as i32, p[1] as i32, p[2] as i32);
        if r.max(g).max(b) - r.min(g).min(b) > 60 {
            saturated += 1;
        }
        colours.insert((r >> 3, g >> 3, b >> 3));
    }
    (total, saturated, colours.len())
}

#[test]
#[ignore = "needs Chromium and ChromeDriver: scripts/install-browser-test-deps.sh, then --ignored (.ci/run does both)"]
fn the_page_draws_bodies_stamps_a_click_and_its_saved_run_replays_to_the_shown_hash() {
    let dir = tempfile::tempdir().unwrap();
    let prefix = dir.path().join("clicked");
    let mut viewer = Viewer::start(&[
        "--scene",
        "falling-cubes",
        "--objects",
        "300",
        "--threads",
        "2",
        "--worlds",
        "4",
        "--save",
        prefix.to_str().unwrap(),
    ]);
    let browser = Browser::start();
    browser.post("/url", json!({"url": viewer.url()}));
    browser.wait_for(
        "frames on the page",
        "return window.soda && window.soda.frames > 20",
    );
    // Let the cubes land, then look.
    browser.wait_for(
        "step 150 on show",
        "return window.soda.shown && window.soda.shown.step >= 150",
    );
    let shot = browser.screenshot();
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("view.png");
    std::fs::write(&out, &shot).unwrap();
    let (total, saturated, colours) = pixel_census(&shot);
    assert!(
        colours > 30,
        "a nearly blank page: {colours} colours ({})",
        out.display()
    );
    assert!(
        saturated > total / 400,
        "too few body-coloured pixels: {saturated} of {total} ({})",
        out.display()
    );

    // Pause, click a body where the page draws it.
    browser.click_element("#pause");
    browser.wait_for("a paused display", "return window.soda.shown.paused");
    let point = browser.wait_for(
        "a body on screen",
        "const s = window.soda; const r = document.querySelector('canvas').getBoundingClientRect();
         for (const id of s.ids) { const p = s.screenPointOf(id);
           if (p && p.depth < 1 && p.x > r.left + 20 && p.x < r.right - 20 && p.y > r.top + 200 && p.y < r.bottom - 20) return p; }
         return null;",
    );
    browser.click_at(point["x"].as_f64().unwrap(), point["y"].as_f64().unwrap());
    let stamped = browser.wait_for(
        "the push stamped",
        "return window.soda.outcomes.find(o => o.type === 'stamped') || null",
    );
    assert_eq!(stamped["action"], "push");
    let id = stamped["id"].as_u64().unwrap();
    let step = stamped["step"].as_u64().unwrap();
    assert_eq!(browser.js("return window.soda.selected"), json!(id));
    let deadline = Instant::now() + Duration::from_secs(10);
    let line = format!("input push body {id} stamped at step {step}");
    while !viewer.stderr.lock().unwrap().contains(&line) {
        assert!(Instant::now() < deadline, "the server did not log `{line}`");
        std::thread::sleep(Duration::from_millis(50));
    }

    // Play past the push, pause, save; the replay gives the hash on the page.
    browser.click_element("#pause");
    browser.wait_for(
        "the push on show",
        &format!(
            "return window.soda.shown.step > {} && !window.soda.shown.paused",
            step + 10
        ),
    );
    browser.click_element("#pause");
    browser.wait_for("a paused display", "return window.soda.shown.paused");
    browser.click_element("#save");
    let saved = browser.wait_for("the saved run", "return window.soda.saved");
    let shown_hash = browser.js("return document.getElementById('hash').textContent");
    let shown_step = browser.js("return Number(document.getElementById('step').textContent)");
    assert_eq!(saved["hash"], shown_hash);
    assert_eq!(saved["step"], shown_step);
    assert_eq!(saved["inputs_logged"], 1);
    let hash = run_hash(
        saved["scene"].as_str().unwrap(),
        saved["inputs"].as_str().unwrap(),
        saved["step"].as_u64().unwrap(),
        &["--executor", "reference"],
    );
    assert_eq!(json!(hash), shown_hash);
    drop(browser);
    assert_eq!(viewer.interrupt().code(), Some(130));
}

/// A rectangle of the page in CSS pixels (= screenshot pixels in headless Chromium).
#[derive(Clone, Copy, Debug)]
struct Rect {
    x: usize,
    y: usize,
    w: usize,
    h: usize,
}

impl Rect {
    /// The element's bounding rectangle, shrunk to whole pixels inside it.
    fn of(browser: &Browser, css: &str) -> Rect {
        let v = browser.js(&format!(
            "const r = document.querySelector('{css}').getBoundingClientRect();
             return [Math.ceil(r.left), Math.ceil(r.top), Math.floor(r.right), Math.floor(r.bottom)];"
        ));
        let n: Vec<usize> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap().max(0.0) as usize)
            .collect();
        Rect {
            x: n[0],
            y: n[1],
            w: n[2].saturating_sub(n[0]),
            h: n[3].saturating_sub(n[1]),
        }
    }

    fn contains(&self, col: usize, row: usize) -> bool {
        (self.x..self.x + self.w).contains(&col) && (self.y..self.y + self.h).contains(&row)
    }
}

/// The RGB pixels of a PNG inside `area` and outside every rectangle of `except`, row by row.
fn pixels_in(png_bytes: &[u8], area: Rect, except: &[Rect]) -> Vec<[u8; 3]> {
    let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let width = info.width as usize;
    assert!(area.x + area.w <= width && area.y + area.h <= info.height as usize);
    let mut out = Vec::with_capacity(area.w * area.h);
    for row in area.y..area.y + area.h {
        for col in area.x..area.x + area.w {
            if except.iter().any(|r| r.contains(col, row)) {
                continue;
            }
            let p = &buf[(row * width + col) * channels..];
            out.push([p[0], p[1], p[2]]);
        }
    }
    out
}

#[test]
#[ignore = "needs Chromium and ChromeDriver: scripts/install-browser-test-deps.sh, then --ignored (.ci/run does both)"]
fn frames_with_unchanged_bodies_are_shown_without_a_redraw_and_look_like_a_full_redraw() {
    let mut viewer = Viewer::start(&[
        "--scene",
        "falling-cubes",
        "--objects",
        "300",
        "--threads",
        "2",
        "--worlds",
        "4",
    ]);
    let browser = Browser::start();
    // A fixed render scale: the automatic one would resize (and redraw) as the page speeds up.
    browser.post(
        "/url",
        json!({"url": format!("{}?scale=0.5", viewer.url())}),
    );
    // The pile comes to rest: frames keep coming and are shown, their bodies unchanged.
    browser.wait_for(
        "frames shown without a redraw",
        "return window.soda && window.soda.unchanged > 60",
    );
    let step = browser
        .js("return window.soda.shown.step")
        .as_f64()
        .unwrap();
    browser.wait_for(
        "more unchanged frames shown",
        &format!("return window.soda.shown.step > {step} + 30 && window.soda.unchanged > 90"),
    );
    // Still: no flash fading, the display paused.
    browser.click_element("#pause");
    browser.wait_for("a paused display", "return window.soda.shown.paused");
    std::thread::sleep(Duration::from_millis(1500));
    // The canvas, less the panels drawn over it.
    let canvas = Rect::of(&browser, "#view canvas");
    let over = [Rect::of(&browser, "#panel"), Rect::of(&browser, "#help")];
    let kept = pixels_in(&browser.screenshot(), canvas, &over);
    // Place every body again and render, as for a changed frame.
    browser.js("window.soda.renderNow(); return true;");
    let redrawn = pixels_in(&browser.screenshot(), canvas, &over);
    let differing = kept.iter().zip(&redrawn).filter(|(a, b)| a != b).count();
    let coloured = kept
        .iter()
        .filter(|p| p.iter().max().unwrap() - p.iter().min().unwrap() > 60)
        .count();
    assert!(
        coloured > kept.len() / 400,
        "the kept picture shows no bodies ({coloured} of {} pixels coloured)",
        kept.len()
    );
    assert_eq!(
        differing,
        0,
        "{differing} of {} canvas pixels differ from a full redraw",
        kept.len()
    );
    drop(browser);
    assert_eq!(viewer.interrupt().code(), Some(130));
}
