//! `soda view` over its WebSocket, as a page would use it (no browser: tests/view_browser.rs
//! drives a real one): frames arrive in order, acts are stamped at steps not yet committed,
//! hostile messages are refused while the run goes on, and a saved interactive run replays
//! to the hash the viewer showed, on every executor.

mod view_support;

use std::net::TcpStream;
use std::time::{Duration, Instant};
use tungstenite::{stream::MaybeTlsStream, Message, WebSocket};
use view_support::{header, run_hash, Header, Viewer};

type Socket = WebSocket<MaybeTlsStream<TcpStream>>;

fn connect(v: &Viewer) -> (Socket, serde_json::Value) {
    let (mut ws, _) =
        tungstenite::connect(format!("ws://127.0.0.1:{}/ws", v.port)).expect("the WebSocket opens");
    if let MaybeTlsStream::Plain(s) = ws.get_mut() {
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    }
    let scene = match ws.read().expect("the scene message") {
        Message::Text(t) => serde_json::from_str(t.as_str()).expect("JSON"),
        other => panic!("the first message is the scene, got {other:?}"),
    };
    (ws, scene)
}

/// Reads messages until `want` accepts one; frames seen meanwhile go to `frames`.
fn until<T>(
    ws: &mut Socket,
    frames: &mut Vec<Header>,
    what: &str,
    mut want: impl FnMut(&Message, &[Header]) -> Option<T>,
) -> T {
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline {
        let m = ws
            .read()
            .unwrap_or_else(|e| panic!("waiting for {what}: {e}"));
        if let Message::Binary(b) = &m {
            frames.push(header(b));
        }
        if let Some(t) = want(&m, frames) {
            return t;
        }
    }
    panic!("no {what} within 60 s");
}

/// The outcome of an act: `stamped`, or a failure showing why it was refused.
fn stamped(m: &Message) -> Option<serde_json::Value> {
    let j = text(m)?;
    assert_ne!(j["type"], "rejected", "an act was refused: {j}");
    (j["type"] == "stamped").then_some(j)
}

fn text(m: &Message) -> Option<serde_json::Value> {
    match m {
        Message::Text(t) => serde_json::from_str(t.as_str()).ok(),
        _ => None,
    }
}

#[test]
fn an_interactive_threaded_run_replays_to_the_shown_hash_on_every_executor() {
    let dir = tempfile::tempdir().unwrap();
    let prefix = dir.path().join("run");
    let mut v = Viewer::start(&[
        "--scene",
        "falling-cubes",
        "--objects",
        "150",
        "--executor",
        "threaded",
        "--threads",
        "2",
        "--worlds",
        "4",
        "--fps",
        "240",
        "--buffer",
        "30",
        "--save",
        prefix.to_str().unwrap(),
    ]);
    let (mut ws, scene) = connect(&v);
    assert_eq!(scene["type"], "scene");
    assert_eq!(scene["worlds"], 4);
    let mut frames = Vec::new();
    let first = until(&mut ws, &mut frames, "a frame", |m, f| {
        matches!(m, Message::Binary(_)).then(|| *f.last().unwrap())
    });
    assert_eq!(first.worlds, 4);
    assert_eq!(first.bodies, 150);

    // Hostile or malformed messages are refused with a reason; the run goes on.
    ws.send(Message::Text("{\"type\":\"launch-missiles\"}".into()))
        .unwrap();
    let reason = until(&mut ws, &mut frames, "a refusal", |m, _| {
        text(m).filter(|j| j["type"] == "rejected")
    });
    assert!(reason["reason"]
        .as_str()
        .unwrap()
        .contains("not a viewer message"));
    ws.send(Message::Binary(vec![0u8; 64].into())).unwrap();
    until(&mut ws, &mut frames, "a refusal of binary", |m, _| {
        text(m).filter(|j| j["type"] == "rejected")
    });
    ws.send(Message::Text(
        "{\"type\":\"push\",\"id\":999999,\"direction\":[1,0,0],\"speed\":2}".into(),
    ))
    .unwrap();
    let unknown = until(&mut ws, &mut frames, "a refused push", |m, _| {
        text(m).filter(|j| j["type"] == "rejected")
    });
    assert!(unknown["reason"].as_str().unwrap().contains("999999"));

    // A push and a dropped cube, stamped after the step shown.
    let id = first.first_id.unwrap();
    let shown_before = frames.last().unwrap().step;
    ws.send(Message::Text(
        format!("{{\"type\":\"push\",\"id\":{id},\"direction\":[0,1,0.5],\"speed\":5}}").into(),
    ))
    .unwrap();
    let pushed = until(&mut ws, &mut frames, "the stamped push", |m, _| stamped(m));
    assert_eq!(pushed["action"], "push");
    assert_eq!(pushed["id"], id);
    let push_step = pushed["step"].as_u64().unwrap();
    assert!(
        push_step > shown_before,
        "stamped at {push_step}, not after the step shown {shown_before}"
    );
    let top = scene["domain"]["max"][1].as_f64().unwrap() - 1.5;
    ws.send(Message::Text(
        format!("{{\"type\":\"spawn\",\"position\":[0.5,{top},0.5]}}").into(),
    ))
    .unwrap();
    let spawned = until(&mut ws, &mut frames, "the stamped spawn", |m, _| stamped(m));
    assert_eq!(spawned["action"], "spawn");
    assert_eq!(spawned["id"], 150, "a new body takes the next free id");
    let spawn_step = spawned["step"].as_u64().unwrap();

    // Wait until the acts are on show, pause, save.
    until(&mut ws, &mut frames, "the acts on show", |_, f| {
        f.last()
            .filter(|h| h.step > spawn_step + 5 && h.bodies == 151)
            .copied()
    });
    ws.send(Message::Text("{\"type\":\"pause\"}".into()))
        .unwrap();
    until(&mut ws, &mut frames, "a paused frame", |_, f| {
        f.last().filter(|h| h.paused).copied()
    });
    ws.send(Message::Text("{\"type\":\"save\"}".into()))
        .unwrap();
    let saved = until(&mut ws, &mut frames, "the saved run", |m, _| {
        text(m).filter(|j| j["type"] == "saved")
    });
    let step = saved["step"].as_u64().unwrap();
    let hash = saved["hash"].as_str().unwrap().to_string();
    assert!(step > spawn_step);
    assert_eq!(saved["inputs_logged"], 2);
    let shown = frames
        .iter()
        .rev()
        .find(|h| h.step == step)
        .expect("the frame saved");
    assert_eq!(
        format!("{:016x}", shown.hash),
        hash,
        "the hash saved is the one shown"
    );
    let scene_file = saved["scene"].as_str().unwrap();
    let inputs_file = saved["inputs"].as_str().unwrap();
    for args in [
        &["--executor", "reference"][..],
        &["--executor", "virtual", "--worlds", "3", "--mode", "cell"][..],
        &["--executor", "threaded", "--threads", "2", "--worlds", "5"][..],
    ] {
        assert_eq!(
            run_hash(scene_file, inputs_file, step, args),
            hash,
            "replaying with {args:?}"
        );
    }
    drop(ws);
    let status = v.interrupt();
    assert_eq!(status.code(), Some(130));
    let out = v.stdout.lock().unwrap().clone();
    assert!(
        out.contains("soda view: stopped; committed up to step"),
        "{out}"
    );
    let err = v.stderr.lock().unwrap().clone();
    assert!(
        err.contains(&format!("input push body {id} stamped at step {push_step}")),
        "{err}"
    );
}

#[test]
fn the_server_listens_on_loopback_only_and_serves_the_pinned_three_js() {
    let v = Viewer::start(&[
        "--objects",
        "20",
        "--steps",
        "50",
        "--executor",
        "reference",
    ]);
    let page = ureq::get(&v.url())
        .call()
        .unwrap()
        .into_body()
        .read_to_string()
        .unwrap();
    assert!(page.contains("/vendor/three-0.170.0/three.module.min.js"));
    let three = ureq::get(&format!(
        "{}vendor/three-0.170.0/three.module.min.js",
        v.url()
    ))
    .call()
    .unwrap()
    .into_body()
    .read_to_string()
    .unwrap();
    assert!(three.contains("Copyright 2010-2024 Three.js Authors"));
    // Not on the machine's other addresses.
    let others: Vec<std::net::IpAddr> = local_addresses();
    for ip in others {
        assert!(
            TcpStream::connect_timeout(&(ip, v.port).into(), Duration::from_millis(300)).is_err(),
            "the viewer answers on {ip}"
        );
    }
}

/// The machine's non-loopback IPv4 addresses (from `hostname -I`, if available).
fn local_addresses() -> Vec<std::net::IpAddr> {
    std::process::Command::new("hostname")
        .arg("-I")
        .output()
        .map(|o| {
            String::from_utf8_lossy(&o.stdout)
                .split_whitespace()
                .filter_map(|s| s.parse().ok())
                .filter(|ip: &std::net::IpAddr| ip.is_ipv4() && !ip.is_loopback())
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_taken_port_and_an_unwritable_save_prefix_are_refused_before_the_run() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(["view", "--port", &port, "--objects", "10"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!("--port {port}")) && err.contains("--port 0"),
        "{err}"
    );
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(["view", "--port", "0", "--save", "/nonexistent-dir/run"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--save") && err.contains("does not exist"),
        "{err}"
    );
}
