//! Command-line parsing (clap derive) and dispatch. Each subcommand lives in its own module;
//! options shared by several commands (which scene to load) are flattened `Args` structs so
//! later commands (`verify`, benchmarks) and later `run` options (executor, worlds, threads,
//! rollback mode, window, partition, schedule seed) slot in without reshaping the rest.

mod checkpoint;
mod exec_args;
mod experiment;
mod mpi;
mod numbers;
mod output;
mod plot;
mod record;
mod resume;
mod run;
mod scenes;
mod source;
mod table;
mod verify;
mod view;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use std::process::ExitCode;

/// SODA: deterministic optimistic (Time Warp) parallel rigid-body simulation.
///
/// Rigid bodies in a bounded 3D domain, a uniform grid over it, and a locality contract
/// that makes every committed step bit-identical whatever the partition into worlds, the
/// number of threads or the order in which they run. `soda run` with no arguments runs the
/// built-in `falling-cubes` scene (1,000 cubes, 600 steps = 10 simulated seconds) and prints
/// a summary ending with the final state hash.
#[derive(Debug, Parser)]
#[command(name = "soda", version, arg_required_else_help = true)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a scene on an executor (reference, virtual or threaded) and print a summary with
    /// the final state hash.
    ///
    /// With no arguments: the built-in `falling-cubes` scene, 1,000 cubes, 600 steps, on the
    /// reference executor.
    #[command(after_help = run::AFTER_HELP, allow_negative_numbers = true)]
    Run(Box<run::RunArgs>),
    /// Continue a run from a checkpoint (`soda run --checkpoint FILE`) to the same final hash
    /// as the uninterrupted run, on any executor.
    #[command(
        after_help = resume::AFTER_HELP,
        allow_negative_numbers = true,
        mut_args = |arg: clap::Arg| arg.hide_default_value(true)
    )]
    Resume(Box<resume::ResumeArgs>),
    /// List the built-in scenes, or print one as a TOML scene file to start your own from.
    #[command(after_help = scenes::AFTER_HELP, allow_negative_numbers = true)]
    Scenes(scenes::ScenesArgs),
    /// Check that the virtual and threaded executors commit the reference's bits: every
    /// step's hash, under many schedules, thread interleavings and rollback modes.
    ///
    /// A divergence is reported as the first step, body, field and cell that differ, with
    /// the command that reproduces it; the exit status is then 1.
    #[command(
        after_help = verify::AFTER_HELP,
        allow_negative_numbers = true,
        mut_arg("objects", |a| a.help(verify::OBJECTS_HELP))
    )]
    Verify(verify::VerifyArgs),
    /// Draw a trace written by `soda run --trace`: a space-time diagram (each world's LVT
    /// over wall time, rollbacks as drops, the GVT line), a territory map and a rollback heat
    /// map, as SVG files.
    #[command(after_help = plot::AFTER_HELP)]
    Plot(plot::PlotArgs),
    /// Run one of the thesis's §4.2 experiments and write its data (CSV) and a chart (SVG).
    ///
    /// For the other models: `soda experiment granularity --model NAME [--windows 4,16,64]`.
    #[command(after_help = experiment::AFTER_HELP)]
    Experiment(experiment::ExperimentArgs),
    /// Watch a run live in the browser and act on it: the bodies in 3D tinted by the world
    /// that owns them, GVT and each world's LVT, rollbacks as flashes; click to push a body,
    /// shift-click to drop a cube; "save run" writes a scene and input log that replay it.
    ///
    /// Serves http://127.0.0.1:7878/ (loopback only) on the threaded executor by default.
    #[command(after_help = view::AFTER_HELP, allow_negative_numbers = true)]
    View(Box<view::ViewArgs>),
    /// List the models `--model` takes: the rigid bodies of the scenes, and the example
    /// models (`soda run --model epidemic`, `soda verify --model phold`).
    Models,
}

/// The name of the rigid-body model, whose runs take scenes.
pub const RIGID_BODIES: &str = "rigid-bodies";

/// The value of `--model NAME` or `--model=NAME`, if given.
fn model_arg(args: &[std::ffi::OsString]) -> Option<String> {
    args.iter().enumerate().find_map(|(i, a)| {
        let a = a.to_str()?;
        if a == "--model" {
            args.get(i + 1).map(|v| v.to_string_lossy().into_owned())
        } else {
            a.strip_prefix("--model=").map(str::to_string)
        }
    })
}

/// Parses the command line, runs the command and turns any error into a message on stderr
/// and exit status 1 (usage errors, clap's and [`soda::app::UsageError`]s, exit with status 2).
pub fn main() -> ExitCode {
    let args = help_help(std::env::args_os().collect());
    // Another model than rigid bodies: the generic command line over the example models.
    let result = match model_arg(&args) {
        Some(m) if m != RIGID_BODIES => {
            let registry = soda::app::Registry::examples();
            if registry.get(&m).is_none() {
                // The registry knows its own models; this binary also has the rigid bodies.
                let names: Vec<&str> = std::iter::once(RIGID_BODIES)
                    .chain(registry.models().map(|r| r.name()))
                    .collect();
                eprintln!(
                    "error: --model {m}: no such model; this binary has: {}",
                    names.join(", ")
                );
                return ExitCode::from(2);
            }
            soda::app::run_with(&registry, args)
        }
        _ => {
            let matches = Cli::command().get_matches_from(args);
            match Cli::from_arg_matches(&matches) {
                Ok(cli) => run_rigid(cli, &matches),
                Err(e) => e.exit(),
            }
        }
    };
    report(result)
}

/// Runs a command of the rigid-body command line (`matches` are the parsed command line,
/// for commands that tell given options from defaults).
fn run_rigid(cli: Cli, matches: &clap::ArgMatches) -> anyhow::Result<()> {
    match cli.command {
        Command::Run(args) => run::run(&args),
        Command::Resume(args) => {
            let empty = clap::ArgMatches::default();
            let sub = matches.subcommand_matches("resume").unwrap_or(&empty);
            resume::resume(&args, sub)
        }
        Command::Scenes(args) => scenes::scenes(&args),
        Command::View(args) => {
            let empty = clap::ArgMatches::default();
            let sub = matches.subcommand_matches("view").unwrap_or(&empty);
            view::view(&args, sub)
        }
        Command::Verify(args) => verify::verify(&args),
        Command::Plot(args) => plot::plot(&args),
        Command::Experiment(args) => experiment::experiment(&args),
        Command::Models => {
            output::print_line(format_args!(
                "{RIGID_BODIES:<16} rigid bodies of a scene (--scene, --objects): the default"
            ))?;
            for m in soda::app::Registry::examples().models() {
                output::print_line(format_args!("{:<16} {}", m.name(), m.about()))?;
            }
            Ok(())
        }
    }
}

/// Turns a command's result into an exit status, printing an error and its causes: 2 for a
/// usage error (a [`soda::app::UsageError`]: an option's value the command does not take, or
/// options that do not go together), as clap's own; 1 for any other.
fn report(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if output::is_broken_pipe(&e) => ExitCode::SUCCESS,
        // A usage error of a model's command line: clap's message and status 2, as for the
        // rigid-body commands.
        Err(e) if e.downcast_ref::<clap::Error>().is_some() => {
            e.downcast_ref::<clap::Error>().expect("checked").exit()
        }
        Err(e) => {
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                let text = cause.to_string().replace('\n', "\n  ");
                eprintln!("  caused by: {text}");
            }
            ExitCode::from(soda::app::usage::exit_status(&e))
        }
    }
}

/// `soda help --help` (or `-h`) asks for help about `help`: clap's built-in `help`
/// subcommand takes no options and would exit with a usage error, so it is read as
/// `soda --help`.
fn help_help(mut args: Vec<std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    let is = |i: usize, words: &[&str]| args.get(i).is_some_and(|a| words.iter().any(|w| a == w));
    if is(1, &["help"]) && (2..args.len()).any(|i| is(i, &["--help", "-h"])) {
        args.truncate(1);
        args.push("--help".into());
    }
    args
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_definition_is_consistent() {
        Cli::command().debug_assert();
    }
}
