//! `soda run --checkpoint FILE`: what a rigid-body checkpoint holds besides the bodies (the
//! scene's source, the run options, the target step), and writing one atomically at
//! committed steps. The file format itself is the library's (`soda::checkpoint`,
//! docs/formats.md, "Checkpoint format").

use super::source::Origin;
use anyhow::{bail, Context, Result};
use clap::Args;
use serde::{Deserialize, Serialize};
use soda::checkpoint::Checkpoint;
use soda::scene::builtin::builtin;
use soda::scene::{parse_scene, SceneFormat};
use soda::sim::RunOptions;
use soda::{Body, EventKind, Frame, RigidBodyModel, Scene};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The model name rigid-body checkpoints carry.
pub const MODEL: &str = super::RIGID_BODIES;

/// Options of `soda run` about checkpoints.
#[derive(Debug, Clone, Args)]
#[command(next_help_heading = "Checkpoint")]
pub struct CheckpointArgs {
    /// Write a checkpoint to FILE every --checkpoint-every committed steps and at the last
    /// step: the committed bodies (exact bits), the scene, the run options and the step.
    /// `soda resume FILE` continues the run from it, on any executor, to the same hash.
    /// Each write goes to a temporary file that is synced and renamed into place, so FILE is
    /// always a whole checkpoint (a kill during a write leaves the previous one).
    #[arg(long, value_name = "FILE")]
    pub checkpoint: Option<PathBuf>,

    /// With --checkpoint: steps between checkpoints.
    #[arg(long, value_name = "N", default_value_t = 100, requires = "checkpoint",
          value_parser = super::numbers::whole(1, u64::MAX))]
    pub checkpoint_every: u64,
}

/// Where the scene of a checkpointed run comes from: enough to rebuild its model and grid
/// exactly (the bodies come from the checkpoint).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SceneSource {
    /// A built-in scene, as `--scene NAME --objects N --seed S` built it.
    Builtin {
        /// Its name.
        name: String,
        /// `--objects`, if given.
        objects: Option<usize>,
        /// The seed.
        seed: u64,
    },
    /// A scene file: its text as it was read (the file may have changed since).
    File {
        /// The path it was read from (its extension names the syntax).
        path: String,
        /// The whole text.
        text: String,
        /// `--seed`, if given (replaces the file's `seed`).
        seed: Option<u64>,
    },
}

impl SceneSource {
    /// Rebuilds the scene (validated again) and says where it came from.
    pub fn scene(&self) -> Result<(Scene, Origin)> {
        match self {
            SceneSource::Builtin {
                name,
                objects,
                seed,
            } => {
                let scene = builtin(name, *objects, *seed)
                    .with_context(|| format!("cannot rebuild the built-in scene `{name}`"))?;
                let origin = Origin::Builtin {
                    objects: scene.bodies.len(),
                    seed: *seed,
                };
                Ok((scene, origin))
            }
            SceneSource::File { path, text, seed } => {
                let Some(format) = SceneFormat::from_path(Path::new(path)) else {
                    bail!("the scene file name `{path}` has neither a .toml nor a .json extension");
                };
                let mut scene = parse_scene(text, format, path)
                    .with_context(|| format!("cannot parse the scene file `{path}` it holds"))?;
                if let Some(seed) = seed {
                    scene.seed = *seed;
                }
                Ok((scene, Origin::File(PathBuf::from(path))))
            }
        }
    }
}

/// Events counted over the steps before a checkpoint, so a resumed run reports the whole
/// run's totals.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EventTotals {
    /// Bodies whose speed was capped.
    pub speed_capped: usize,
    /// Bodies removed for leaving the domain.
    pub left_domain: usize,
}

impl EventTotals {
    /// Adds the events of one committed frame.
    pub fn add(&mut self, frame: &Frame<EventKind>) {
        for e in &frame.events {
            match e.kind {
                EventKind::SpeedCapped => self.speed_capped += 1,
                EventKind::LeftDomain => self.left_domain += 1,
            }
        }
    }
}

/// Everything a rigid-body checkpoint holds besides the bodies.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunDescription {
    /// The scene.
    pub scene: SceneSource,
    /// The executor and kernel options of the run (a resume without executor options uses
    /// them).
    pub options: RunOptions,
    /// The step the run was asked to reach (`--steps`).
    pub last_step: u64,
    /// Steps between checkpoints (a resumed run keeps writing them).
    pub checkpoint_every: u64,
    /// Events of the steps up to the checkpoint's, including bodies outside the domain at
    /// step 0.
    pub events: EventTotals,
    /// The run's input script, whole (`--inputs`; a resume applies the entries after the
    /// checkpoint's step).
    #[serde(default)]
    pub inputs: soda::scene::InputScript,
}

/// Writes checkpoints of one run at committed steps.
pub struct CheckpointWriter {
    path: PathBuf,
    every: u64,
    run: RunDescription,
    written: Option<u64>,
}

impl CheckpointWriter {
    /// A writer to `path` (already checked as an output) every `run.checkpoint_every` steps
    /// and at `run.last_step`.
    pub fn new(path: PathBuf, run: RunDescription) -> CheckpointWriter {
        CheckpointWriter {
            path,
            every: run.checkpoint_every,
            run,
            written: None,
        }
    }

    /// Whether step `step` gets a checkpoint.
    pub fn wants(&self, step: u64) -> bool {
        step % self.every == 0 || step == self.run.last_step
    }

    /// Steps between checkpoints.
    pub fn every(&self) -> u64 {
        self.every
    }

    /// Counts the frame's events and, at a checkpoint step with states, writes the
    /// checkpoint (temporary file, fsync, rename, directory fsync).
    pub fn frame(&mut self, frame: &Frame<EventKind>, states: Option<&[&Body]>) -> Result<()> {
        self.run.events.add(frame);
        let Some(states) = states.filter(|_| self.wants(frame.step)) else {
            return Ok(());
        };
        let checkpoint =
            Checkpoint::new::<RigidBodyModel>(MODEL, frame.step, states, self.run.clone());
        let text = checkpoint
            .to_text()
            .context("cannot format the checkpoint")?;
        let mut file = soda::app::atomic::AtomicFile::create(&self.path)?;
        file.write_all(text.as_bytes())
            .with_context(|| format!("cannot write the checkpoint {}", self.path.display()))?;
        file.commit()?;
        soda::app::atomic::sync_dir_of(&self.path);
        self.written = Some(frame.step);
        Ok(())
    }

    /// The step of the last checkpoint written, if any.
    pub fn last_written(&self) -> Option<u64> {
        self.written
    }

    /// The checkpoint's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Reads the checkpoint `path`: its run description and bodies, every check passed.
pub fn read(path: &Path) -> Result<(Checkpoint<RunDescription>, Vec<Body>)> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read the checkpoint {}", path.display()))?;
    let text = String::from_utf8(bytes).map_err(|_| {
        anyhow::anyhow!(
            "{} is not a SODA checkpoint (it is not text); give the FILE a `soda run \
             --checkpoint FILE` wrote",
            path.display()
        )
    })?;
    let checkpoint = Checkpoint::<RunDescription>::from_text(&text, MODEL)
        .with_context(|| format!("cannot resume from {}", path.display()))?;
    check_run(&checkpoint.run).with_context(|| {
        format!(
            "cannot resume from {}: its run options are out of range (was it edited?); \
             give the FILE a `soda run --checkpoint FILE` wrote",
            path.display()
        )
    })?;
    let bodies = checkpoint
        .states::<RigidBodyModel>()
        .with_context(|| format!("cannot resume from {}", path.display()))?;
    Ok((checkpoint, bodies))
}

/// Checks a checkpoint's run options against the ranges `soda run` accepts: a checksum
/// proves the file whole, not that its options came from the command line (a
/// `checkpoint_every` of 0 divided by zero, 0 worlds panicked).
fn check_run(run: &RunDescription) -> Result<()> {
    let k = &run.options.kernel;
    let bad = if run.checkpoint_every == 0 {
        Some(format!(
            "checkpoint_every is {} (at least 1)",
            run.checkpoint_every
        ))
    } else if !(1..=4096).contains(&k.worlds) {
        Some(format!("options.kernel.worlds is {} (1 to 4096)", k.worlds))
    } else if !(1..=256).contains(&run.options.threads) {
        Some(format!(
            "options.threads is {} (1 to 256)",
            run.options.threads
        ))
    } else if k.window == 0 {
        Some("options.kernel.window is 0 (at least 1)".to_string())
    } else {
        None
    };
    match bad {
        Some(why) => Err(anyhow::anyhow!("{why}")),
        None => Ok(()),
    }
}
