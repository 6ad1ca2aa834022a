//! `--record FILE`: committed frames as CSV (docs/formats.md, "Recording format").
//!
//! A header line `step,id,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`, then one row per body per
//! recorded step, steps ascending and bodies in ascending id order. Recorded steps: the
//! initial state (step 0 of a fresh run), every step that is a multiple of `every`, and the
//! last step of the run. Numbers are written in the shortest decimal form that reads back
//! to the same `f32` bits.
//!
//! The rows stream into a temporary file beside the target ([`AtomicFile`]), renamed into
//! place when the run ends or is interrupted (then holding the whole frames recorded so
//! far); on a write error nothing replaces the target.

use anyhow::{Context, Result};
use soda::app::atomic::AtomicFile;
use soda::Body;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The CSV header line (without the newline).
pub const HEADER: &str = "step,id,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz";

/// Bytes of a typical row, rounded up (measured: the default run, 1,000 falling cubes over
/// 600 steps, averages 117 bytes; a resting body's zeros are shorter, a tumbling one's
/// longer).
pub const ROW_BYTES: u64 = 120;

/// The size a recording of `bodies` bodies over `steps` steps, every `every`-th recorded,
/// will have, roughly: [`ROW_BYTES`] per body per recorded step.
pub fn estimated_bytes(bodies: u64, steps: u64, every: u64) -> u64 {
    let frames = steps / every.max(1) + 2;
    bodies.saturating_mul(frames).saturating_mul(ROW_BYTES)
}

/// Writes selected committed frames to a CSV file.
pub struct Recorder {
    path: PathBuf,
    out: AtomicFile,
    every: u64,
    last: u64,
    frames: u64,
    last_recorded: Option<u64>,
    error: Option<std::io::Error>,
}

impl Recorder {
    /// Starts the recording of `path` (in a temporary file) with the header. Steps that are
    /// multiples of `every` and the step `last` will be recorded.
    pub fn create(path: &Path, every: u64, last: u64) -> Result<Recorder> {
        let mut out = AtomicFile::create(path)
            .with_context(|| format!("cannot create the recording file `{}`", path.display()))?;
        writeln!(out, "{HEADER}")
            .with_context(|| format!("cannot write to `{}`", path.display()))?;
        Ok(Recorder {
            path: path.to_path_buf(),
            out,
            every: every.max(1),
            last,
            frames: 0,
            last_recorded: None,
            error: None,
        })
    }

    /// The steps this recorder records (besides the initial state).
    pub fn wanted(&self) -> soda::frame::StatesWanted {
        soda::frame::StatesWanted {
            every: self.every,
            step: Some(self.last),
            unexpected: None,
        }
    }

    /// Records the bodies (sorted by id) of step `step` if `step` is selected. Write errors
    /// are kept and reported by [`Recorder::finish`].
    pub fn frame(&mut self, step: u64, bodies: &[&Body]) {
        if self.error.is_some() || !(step % self.every == 0 || step == self.last) {
            return;
        }
        for &b in bodies {
            if let Err(e) = write_row(&mut self.out, step, b) {
                self.error = Some(e);
                return;
            }
        }
        self.frames += 1;
        self.last_recorded = Some(step);
    }

    /// The last step recorded so far.
    pub fn last_recorded(&self) -> Option<u64> {
        self.last_recorded
    }

    /// Records `step` whether or not it is selected (used for the initial state).
    pub fn frame_always(&mut self, step: u64, bodies: &[&Body]) {
        let every = std::mem::replace(&mut self.every, 1);
        self.frame(step, bodies);
        self.every = every;
    }

    /// Renames the recording into place; returns its path and the number of frames
    /// written. After a write error the target is left as it was.
    pub fn finish(mut self) -> Result<(PathBuf, u64)> {
        if let Some(e) = self.error.take() {
            return Err(e).with_context(|| {
                format!(
                    "cannot write the recording `{}` (left as it was)",
                    self.path.display()
                )
            });
        }
        self.out.commit()?;
        Ok((self.path, self.frames))
    }
}

fn write_row(out: &mut impl Write, step: u64, b: &Body) -> std::io::Result<()> {
    let (p, q, v, w) = (b.position, b.rotation, b.linvel, b.angvel);
    writeln!(
        out,
        "{step},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        b.id(),
        p.x,
        p.y,
        p.z,
        q.w,
        q.i,
        q.j,
        q.k,
        v.x,
        v.y,
        v.z,
        w.x,
        w.y,
        w.z
    )
}

/// Recordings larger than this get a warning before the run (1 GB).
pub const WARN_BYTES: u64 = 1_000_000_000;

/// Warns on stderr before the run if the recording to `path` will take about `estimate`
/// bytes and that is more than [`WARN_BYTES`] or than the free space of its file system.
pub fn warn_if_large(path: &Path, estimate: u64) {
    let free = free_bytes(path);
    let too_big = free.is_some_and(|f| estimate > f);
    if estimate <= WARN_BYTES && !too_big {
        return;
    }
    // In GB with a digit after the point, or in MB below a tenth of a GB (a full small
    // disk read "more than the 0.0 GB free there").
    let gb = |b: u64| {
        if b >= 100_000_000 {
            format!("{:.1} GB", b as f64 / 1e9)
        } else {
            format!("{:.1} MB", b as f64 / 1e6)
        }
    };
    let mut text = format!(
        "warning: --record {} will take about {} (~{ROW_BYTES} bytes per body per recorded \
         step)",
        path.display(),
        gb(estimate)
    );
    if let Some(free) = free.filter(|_| too_big) {
        text += &format!(", more than the {} free there", gb(free));
    }
    text += "; --record-every K records every K-th step only";
    eprintln!("{text}");
}

/// The bytes free for an unprivileged user on the file system holding `path`'s directory.
fn free_bytes(path: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: a zeroed statvfs filled in by the call; `c` is a valid C string.
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut s) } != 0 {
        return None;
    }
    Some((s.f_bavail as u64).saturating_mul(s.f_frsize as u64))
}
