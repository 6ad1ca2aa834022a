//! Which scene to load: a built-in by name (sized by `--objects`, seeded by `--seed`) or a
//! scene file (`.toml` / `.json`).

use super::checkpoint::SceneSource;
use anyhow::{Context, Result};
use clap::Args;
use soda::app::{usage, UsageError};
use soda::scene::builtin::{builtin, BUILTINS};
use soda::scene::{parse_scene, SceneFormat};
use soda::{Scene, SceneError};
use std::path::{Path, PathBuf};

/// The default scene of `soda run`.
pub const DEFAULT_SCENE: &str = "falling-cubes";

/// Options choosing the scene.
#[derive(Debug, Clone, Args)]
#[command(next_help_heading = "Scene")]
pub struct SceneArgs {
    /// A built-in scene name (see `soda scenes`) or a scene file ending in .toml or .json.
    #[arg(long, value_name = "NAME|FILE", default_value = DEFAULT_SCENE)]
    pub scene: String,
    /// Number of bodies of a built-in scene [default: the scene's own, see `soda scenes`].
    /// Not allowed with a scene file.
    #[arg(long, value_name = "N", value_parser = super::numbers::count)]
    pub objects: Option<usize>,
    /// Seed of a built-in scene's random jitter [default: 0]. With a scene file it replaces
    /// the file's `seed` field.
    #[arg(long, value_name = "S", value_parser = super::numbers::whole(0, u64::MAX))]
    pub seed: Option<u64>,
}

/// Where a loaded scene came from, for summaries.
#[derive(Debug, Clone)]
pub enum Origin {
    /// A built-in scene with its body count and seed.
    Builtin { objects: usize, seed: u64 },
    /// A scene file.
    File(PathBuf),
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Origin::Builtin { objects, seed } => {
                let objects = soda::app::output::counted(*objects, "object", "objects");
                write!(f, "built-in, {objects}, seed {seed}")
            }
            Origin::File(p) => write!(f, "file {}", p.display()),
        }
    }
}

impl SceneArgs {
    /// The scene file these options name, if they name a file rather than a built-in.
    pub fn file(&self) -> Option<&Path> {
        let path = Path::new(&self.scene);
        SceneFormat::from_path(path).map(|_| path)
    }

    /// Loads and validates the scene these options name, with the source a checkpoint needs
    /// to rebuild it (a file's text is read once, for both).
    pub fn load_with_source(&self) -> Result<(Scene, Origin, SceneSource)> {
        let path = Path::new(&self.scene);
        if let Some(format) = SceneFormat::from_path(path) {
            if let Some(n) = self.objects {
                return Err(usage(format!(
                    "--objects {n} applies to built-in scenes only, but --scene `{}` is a scene file: \
                     its bodies are the ones listed in the file",
                    self.scene
                )));
            }
            let context = || format!("cannot load scene file `{}`", self.scene);
            let text = std::fs::read_to_string(path)
                .map_err(|e| SceneError::Io {
                    path: self.scene.clone(),
                    reason: e.to_string(),
                })
                .with_context(context)?;
            let mut scene = parse_scene(&text, format, &self.scene).with_context(context)?;
            if let Some(seed) = self.seed {
                scene.seed = seed;
            }
            let source = SceneSource::File {
                path: self.scene.clone(),
                text,
                seed: self.seed,
            };
            return Ok((scene, Origin::File(path.to_path_buf()), source));
        }
        if !BUILTINS.iter().any(|b| b.name == self.scene) && path.exists() {
            return Err(usage(format!(
                "--scene `{}` is not a built-in scene name, and as a file it lacks a scene \
                 extension: scene files must end in .toml or .json",
                self.scene
            )));
        }
        let seed = self.seed.unwrap_or(0);
        // A built-in is built from the options alone: what refuses it is a usage error
        // (`--scene` unknown, `--objects` out of range).
        let scene = builtin(&self.scene, self.objects, seed).map_err(|e| {
            let context = match e {
                SceneError::UnknownBuiltin(_) => format!(
                    "--scene `{}` is neither a built-in scene nor a file ending in .toml or .json",
                    self.scene
                ),
                _ => format!("cannot build the built-in scene `{}`", self.scene),
            };
            anyhow::Error::new(e).context(UsageError(context))
        })?;
        let objects = scene.bodies.len();
        let source = SceneSource::Builtin {
            name: self.scene.clone(),
            objects: self.objects,
            seed,
        };
        Ok((scene, Origin::Builtin { objects, seed }, source))
    }

    /// Loads and validates the scene these options name.
    pub fn load(&self) -> Result<(Scene, Origin)> {
        self.load_with_source()
            .map(|(scene, origin, _)| (scene, origin))
    }
}
