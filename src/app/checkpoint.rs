//! Checkpoints of registered models (`run --model NAME --checkpoint FILE`, `resume FILE`):
//! what a checkpoint holds besides the states, and writing one atomically.

use super::registry::{ModelSize, Registry};
use crate::checkpoint::Checkpoint;
use crate::sim::RunOptions;
use anyhow::{anyhow, Context, Result};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Everything a registered model's checkpoint holds besides the states: how to rebuild the
/// model and grid, and how the run goes on.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AppRun {
    /// `--entities` and `--seed` (the model and grid are rebuilt from them).
    pub size: ModelSize,
    /// Executor, kernel configuration and threads.
    pub options: RunOptions,
    /// The step the run was asked to reach.
    pub last_step: u64,
    /// Steps between checkpoints.
    pub checkpoint_every: u64,
}

/// Where and how often to write checkpoints.
#[derive(Debug, Clone)]
pub struct CheckpointPlan {
    /// The checkpoint file.
    pub path: PathBuf,
    /// Steps between checkpoints (and the last step).
    pub every: u64,
}

impl CheckpointPlan {
    /// Checks before the run that `path` can be written (a regular file or nothing, in a
    /// writable directory) by creating its temporary file.
    pub fn checked(path: &Path, every: u64) -> Result<CheckpointPlan> {
        if let Ok(m) = std::fs::metadata(path) {
            if !m.is_file() {
                return Err(anyhow!(
                    "--checkpoint `{}` is not a regular file: give the path of a file",
                    path.display()
                ));
            }
        }
        drop(super::atomic::AtomicFile::create(path).context("--checkpoint")?);
        Ok(CheckpointPlan {
            path: path.to_path_buf(),
            every,
        })
    }

    /// Writes `checkpoint` to a temporary file, syncs it, renames it into place and syncs
    /// the directory.
    pub fn write(&self, checkpoint: &Checkpoint<AppRun>) -> Result<()> {
        let text = checkpoint
            .to_text()
            .context("cannot format the checkpoint")?;
        let mut file = super::atomic::AtomicFile::create(&self.path)?;
        file.write_all(text.as_bytes())
            .with_context(|| format!("cannot write the checkpoint {}", self.path.display()))?;
        file.commit()?;
        super::atomic::sync_dir_of(&self.path);
        Ok(())
    }
}

/// `resume FILE` for a registered model: reads the checkpoint (the model it names must be in
/// `registry`), runs to `steps` (default: the checkpointed run's target) on `options`
/// (default: the checkpointed run's), keeps writing checkpoints to FILE, prints the summary.
pub fn resume(
    registry: &Registry,
    file: &Path,
    steps: Option<u64>,
    options: Option<RunOptions>,
    json: bool,
) -> Result<()> {
    let text = std::fs::read_to_string(file)
        .with_context(|| format!("cannot read the checkpoint {}", file.display()))?;
    let name = crate::checkpoint::model_of(&text)
        .with_context(|| format!("cannot resume from {}", file.display()))?;
    let model = registry.get(&name).ok_or_else(|| {
        anyhow!(
            "{} holds a run of the model `{name}`, which this program does not know (see \
             `models`)",
            file.display()
        )
    })?;
    let checkpoint = Checkpoint::<AppRun>::from_text(&text, &name)
        .with_context(|| format!("cannot resume from {}", file.display()))?;
    let run = checkpoint.run.clone();
    let options = options.unwrap_or(run.options.clone());
    let plan = CheckpointPlan {
        path: file.to_path_buf(),
        every: run.checkpoint_every,
    };
    let last_step = steps.unwrap_or(run.last_step);
    if let Err(e) = super::interrupt::install() {
        eprintln!("warning: Ctrl-C will not stop the run cleanly: {e}");
    }
    let (report, written) = model
        .run_from(
            &run.size,
            &options,
            Some(&checkpoint),
            last_step,
            Some(&plan),
        )
        .with_context(|| format!("cannot resume from {}", file.display()))?;
    super::commands::interrupted(&report, Some(file), written);
    let mut notes = vec![format!(
        "resumed          from {} at step {}",
        file.display(),
        checkpoint.step
    )];
    if let Some(step) = written {
        notes.push(format!(
            "checkpoint       {} at step {step}",
            file.display()
        ));
    }
    // The summary still ends with the hash.
    super::commands::print_report(model, &report, json, &notes)?;
    Ok(())
}
