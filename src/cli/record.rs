//! `--record FILE`: committed frames as CSV (README.md §Recording format).
//!
//! A header line `step,id,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`, then one row per body per
//! recorded step, steps ascending and bodies in ascending id order. Recorded steps: the
//! initial state (step 0 of a fresh run), every step that is a multiple of `every`, and the
//! last step of the run. Numbers are written in the shortest decimal form that reads back
//! to the same `f32` bits.

use anyhow::{Context, Result};
use soda::Body;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// The CSV header line (without the newline).
pub const HEADER: &str = "step,id,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz";

/// Writes selected committed frames to a CSV file.
pub struct Recorder {
    path: PathBuf,
    out: BufWriter<File>,
    every: u64,
    last: u64,
    frames: u64,
    error: Option<std::io::Error>,
}

impl Recorder {
    /// Creates `path` and writes the header. Steps that are multiples of `every` and the
    /// step `last` will be recorded.
    pub fn create(path: &Path, every: u64, last: u64) -> Result<Recorder> {
        let file = File::create(path)
            .with_context(|| format!("cannot create the recording file `{}`", path.display()))?;
        let mut out = BufWriter::new(file);
        writeln!(out, "{HEADER}")
            .with_context(|| format!("cannot write to `{}`", path.display()))?;
        Ok(Recorder {
            path: path.to_path_buf(),
            out,
            every: every.max(1),
            last,
            frames: 0,
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
        self.frames += 1;
        for &b in bodies {
            if let Err(e) = write_row(&mut self.out, step, b) {
                self.error = Some(e);
                return;
            }
        }
    }

    /// Records `step` whether or not it is selected (used for the initial state).
    pub fn frame_always(&mut self, step: u64, bodies: &[&Body]) {
        let every = std::mem::replace(&mut self.every, 1);
        self.frame(step, bodies);
        self.every = every;
    }

    /// Flushes the file; returns its path and the number of frames written.
    pub fn finish(mut self) -> Result<(PathBuf, u64)> {
        let result = match self.error.take() {
            Some(e) => Err(e),
            None => self.out.flush(),
        };
        result.with_context(|| format!("cannot write to `{}`", self.path.display()))?;
        Ok((self.path, self.frames))
    }
}

fn write_row(out: &mut impl Write, step: u64, b: &Body) -> std::io::Result<()> {
    let (p, q, v, w) = (b.position, b.rotation, b.linvel, b.angvel);
    writeln!(
        out,
        "{step},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        b.id, p.x, p.y, p.z, q.w, q.i, q.j, q.k, v.x, v.y, v.z, w.x, w.y, w.z
    )
}
