//! `soda scenes`: list the built-in scenes, or print one as a TOML scene file.

use super::output::print;
use anyhow::{Context, Result};
use clap::Args;
use soda::scene::builtin::{builtin, BUILTINS};
use soda::scene::SceneFormat;

/// Examples shown after `soda scenes --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda scenes                                        list the built-ins
  soda scenes --dump falling-cubes --objects 27 > my.toml
  soda run --scene my.toml                           run the edited copy";

/// Options of `soda scenes`.
#[derive(Debug, Args)]
pub struct ScenesArgs {
    /// Print the built-in scene NAME as a TOML scene file (a template to edit and run with
    /// `soda run --scene FILE.toml`).
    #[arg(long, value_name = "NAME")]
    pub dump: Option<String>,
    /// With --dump: number of bodies [default: the scene's own].
    #[arg(long, value_name = "N", requires = "dump", value_parser = super::numbers::count)]
    pub objects: Option<usize>,
    /// With --dump: seed of the scene's random jitter [default: 0].
    #[arg(long, value_name = "S", requires = "dump",
          value_parser = super::numbers::whole(0, u64::MAX))]
    pub seed: Option<u64>,
}

/// Runs the command.
pub fn scenes(args: &ScenesArgs) -> Result<()> {
    match &args.dump {
        Some(name) => dump(name, args.objects, args.seed.unwrap_or(0)),
        None => print(&list()),
    }
}

fn list() -> String {
    let width = BUILTINS.iter().map(|b| b.name.len()).max().unwrap_or(4);
    let mut out = format!("{:<width$}  {:>7}  ABOUT\n", "NAME", "OBJECTS");
    for b in BUILTINS {
        out += &format!(
            "{:<width$}  {:>7}  {}\n",
            b.name, b.default_objects, b.about
        );
    }
    out += "\nRun one with `soda run --scene NAME [--objects N] [--seed S]`; \
            print one as a scene file with `soda scenes --dump NAME`.\n";
    out
}

fn dump(name: &str, objects: Option<usize>, seed: u64) -> Result<()> {
    // Built from the options alone: what refuses it is a usage error (an unknown name,
    // `--objects` out of range).
    let scene = builtin(name, objects, seed).map_err(|e| {
        anyhow::Error::new(e).context(soda::app::UsageError(format!(
            "cannot dump the built-in scene `{name}`"
        )))
    })?;
    let body = SceneFormat::Toml
        .render(&scene)
        .with_context(|| format!("cannot write the built-in scene `{name}` as TOML"))?;
    let header = format!(
        "# The built-in scene `{name}` ({}, seed {seed}), written by `soda scenes --dump`.\n\
         # Edit it and run it with `soda run --scene FILE.toml`; docs/formats.md, \"Scene files\",\n\
         # describes every field.\n\n",
        soda::app::output::counted(scene.bodies.len(), "object", "objects")
    );
    print(&(header + &body))
}
