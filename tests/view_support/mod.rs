//! Shared by the viewer's tests (`tests/view.rs`, `tests/view_browser.rs`): start `soda
//! view` on a free port, read its frames' headers, replay a saved run.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A running `soda view`; stopped with SIGINT when dropped.
pub struct Viewer {
    /// The process.
    pub child: Child,
    /// Its port on 127.0.0.1.
    pub port: u16,
    /// What it printed on stderr so far.
    pub stderr: Arc<Mutex<String>>,
    /// What it printed on stdout so far.
    pub stdout: Arc<Mutex<String>>,
}

impl Viewer {
    /// Starts `soda view --port 0 args` and waits for its address.
    pub fn start(args: &[&str]) -> Viewer {
        let mut child = Command::new(env!("CARGO_BIN_EXE_soda"))
            .arg("view")
            .args(["--port", "0"])
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("soda view starts");
        let stderr = Arc::new(Mutex::new(String::new()));
        let err = child.stderr.take().expect("stderr");
        let sink = stderr.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                let mut s = sink.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
        });
        let mut out = BufReader::new(child.stdout.take().expect("stdout"));
        let mut first = String::new();
        out.read_line(&mut first)
            .expect("soda view prints its address");
        let port = first
            .split("http://127.0.0.1:")
            .nth(1)
            .and_then(|rest| rest.split('/').next())
            .and_then(|p| p.parse().ok())
            .unwrap_or_else(|| {
                panic!(
                    "no address in {first:?}; stderr: {}",
                    stderr.lock().unwrap()
                )
            });
        let stdout = Arc::new(Mutex::new(first));
        let sink = stdout.clone();
        std::thread::spawn(move || {
            for line in out.lines().map_while(Result::ok) {
                let mut s = sink.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
        });
        Viewer {
            child,
            port,
            stderr,
            stdout,
        }
    }

    /// The page's address.
    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}/", self.port)
    }

    /// Sends SIGINT and waits for the exit status.
    pub fn interrupt(&mut self) -> std::process::ExitStatus {
        // SAFETY: sends SIGINT to the child this test spawned and has not waited for yet.
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGINT);
        }
        for _ in 0..200 {
            if let Some(status) = self.child.try_wait().expect("wait") {
                return status;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        panic!("soda view did not stop within 10 s of SIGINT");
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The fields of a frame's header the tests look at.
#[derive(Clone, Copy, Debug)]
pub struct Header {
    /// The step.
    pub step: u64,
    /// The state hash, as `soda run` prints it.
    pub hash: u64,
    /// GVT when it was committed.
    pub gvt: u64,
    /// Frames buffered ahead of the display.
    pub buffered: u32,
    /// Bodies.
    pub bodies: u32,
    /// Worlds.
    pub worlds: u32,
    /// Whether playback is paused.
    pub paused: bool,
    /// The id of the first body, if any.
    pub first_id: Option<u64>,
}

/// Reads a frame's header (docs/formats.md "Viewer frames").
pub fn header(b: &[u8]) -> Header {
    assert_eq!(&b[0..4], b"SODF", "a frame starts with its magic");
    let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let f64_at = |at: usize| f64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let worlds = u32_at(52);
    let cells = u32_at(56) as usize;
    let bodies = u32_at(48);
    let first = 64 + worlds as usize * 24 + (cells * 2).div_ceil(4) * 4 + cells * 4;
    Header {
        step: f64_at(8) as u64,
        hash: u64::from(u32_at(16)) | (u64::from(u32_at(20)) << 32),
        gvt: f64_at(24) as u64,
        buffered: u32_at(32),
        bodies,
        worlds,
        paused: u32_at(60) == 1,
        first_id: (bodies > 0)
            .then(|| u64::from(u32_at(first)) | (u64::from(u32_at(first + 4)) << 32)),
    }
}

/// The hash `soda run ... --steps step` prints with `args` added.
pub fn run_hash(scene: &str, inputs: &str, step: u64, args: &[&str]) -> String {
    let steps = step.to_string();
    let out = Command::new(env!("CARGO_BIN_EXE_soda"))
        .args([
            "run", "--scene", scene, "--inputs", inputs, "--steps", &steps,
        ])
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("soda run runs");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "soda run failed: {}\n{}",
        text,
        String::from_utf8_lossy(&out.stderr)
    );
    text.lines()
        .find_map(|l| l.trim().strip_prefix("hash").map(|h| h.trim().to_string()))
        .unwrap_or_else(|| panic!("no hash line in {text}"))
}
