//! `soda resume FILE`: continue a checkpointed run to the same hash as the uninterrupted one.

use super::exec_args::ExecutorArgs;
use super::run::{execute, Job, OutputArgs};
use anyhow::Result;
use clap::{ArgMatches, Args};
use soda::sim::ResumeFrom;
use std::path::PathBuf;

/// Examples shown after `soda resume --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda run --objects 8000 --steps 6000 --checkpoint pile.ckpt --checkpoint-every 500
  soda resume pile.ckpt                         continue to step 6000, as the run was set up
  soda resume pile.ckpt --steps 9000            go further than the run was asked to
  soda resume pile.ckpt --executor threaded --threads 2 --worlds 4

Without executor options the run continues on the checkpointed run's executor, worlds, mode
and other kernel options; with any of them (--executor, --worlds, ...) on the ones given,
whose other options take their defaults. Every executor commits the same bits, so the final
hash is the uninterrupted run's. The resumed run keeps writing checkpoints to FILE (every
--checkpoint-every steps, as before, unless given here).";

/// Options of `soda resume`.
#[derive(Debug, Args)]
pub struct ResumeArgs {
    /// The checkpoint file `soda run --checkpoint FILE` wrote.
    #[arg(value_name = "FILE")]
    pub file: PathBuf,

    /// The step to reach [default: the checkpointed run's --steps].
    #[arg(long, value_name = "N", help_heading = "Run",
          value_parser = super::numbers::whole(0, u64::MAX))]
    pub steps: Option<u64>,

    /// Steps between the checkpoints this run keeps writing to FILE [default: the
    /// checkpointed run's].
    #[arg(long, value_name = "N", help_heading = "Checkpoint",
          value_parser = super::numbers::whole(1, u64::MAX))]
    pub checkpoint_every: Option<u64>,

    #[command(flatten)]
    pub executor: ExecutorArgs,

    #[command(flatten)]
    pub output: OutputArgs,
}

/// Whether any executor or kernel option was given on the command line (rather than left
/// to its default).
fn executor_given(matches: &ArgMatches) -> bool {
    let command = ExecutorArgs::augment_args(clap::Command::new("executor"));
    let given = command.get_arguments().any(|a| {
        matches.value_source(a.get_id().as_str()) == Some(clap::parser::ValueSource::CommandLine)
    });
    given
}

/// Runs the command; `matches` are `soda resume`'s own, to tell given options from defaults.
pub fn resume(args: &ResumeArgs, matches: &ArgMatches) -> Result<()> {
    // A checkpoint of another model than rigid bodies: the registered models' resume.
    if let Ok(text) = std::fs::read_to_string(&args.file) {
        if let Ok(model) = soda::checkpoint::model_of(&text) {
            if model != super::RIGID_BODIES {
                // These outputs are the rigid-body run's; a registered model's resume prints
                // its summary only, so refuse them rather than ignore them.
                let o = &args.output;
                let given: Vec<&str> = [
                    ("--record", o.record.is_some()),
                    ("--counters", o.counters.is_some()),
                    ("--csv", o.csv.is_some()),
                    ("--trace", o.trace.is_some()),
                    ("--territories", o.territories.is_some()),
                ]
                .iter()
                .filter(|(_, on)| *on)
                .map(|(flag, _)| *flag)
                .collect();
                if !given.is_empty() {
                    return Err(soda::app::usage(format!(
                        "{} cannot be written when resuming a checkpoint of the model `{model}`: \
                         a registered model's resume prints its summary (and --json) only; drop {}",
                        given.join(", "),
                        if given.len() == 1 { "it" } else { "them" }
                    )));
                }
                let options = if executor_given(matches) {
                    Some(args.executor.options()?)
                } else {
                    None
                };
                return soda::app::checkpoint::resume(
                    &soda::app::Registry::examples(),
                    &args.file,
                    args.steps,
                    options,
                    args.output.json,
                );
            }
        }
    }
    let (checkpoint, bodies) = super::checkpoint::read(&args.file)?;
    let run = checkpoint.run;
    let options = if executor_given(matches) {
        args.executor.options()?
    } else {
        run.options.clone()
    };
    let (scene, origin) = run.scene.scene()?;
    execute(Job {
        scene,
        origin,
        source: run.scene,
        scene_file: None,
        script: run.inputs,
        script_origin: ("the checkpoint's input script".to_string(), None),
        options,
        from: Some(ResumeFrom {
            step: checkpoint.step,
            bodies,
        }),
        events_before: run.events,
        last_step: args.steps.unwrap_or(run.last_step),
        output: &args.output,
        checkpoint: Some((
            args.file.clone(),
            args.checkpoint_every.unwrap_or(run.checkpoint_every),
        )),
        resumed_from: Some(args.file.clone()),
    })
}
