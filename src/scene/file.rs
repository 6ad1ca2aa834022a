//! Reading scene files (TOML or JSON) into validated scenes.

use super::validate::validate;
use super::{Scene, SceneError};
use std::path::Path;

/// The syntax of a scene text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// TOML (`.toml`).
    Toml,
    /// JSON (`.json`).
    Json,
}

/// Parses and validates a scene text. `origin` names it in error messages.
pub fn parse_scene(text: &str, format: SceneFormat, origin: &str) -> Result<Scene, SceneError> {
    let scene: Scene = match format {
        SceneFormat::Toml => toml::from_str(text).map_err(|e| SceneError::Parse {
            origin: origin.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?,
        SceneFormat::Json => serde_json::from_str(text).map_err(|e| SceneError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?,
    };
    validate(&scene, origin)?;
    Ok(scene)
}

/// Reads, parses and validates a scene file; the extension (`.toml` or `.json`) picks the
/// syntax.
pub fn load_scene_file(path: &Path) -> Result<Scene, SceneError> {
    let origin = path.display().to_string();
    let format = match path.extension().and_then(|e| e.to_str()) {
        Some("toml") => SceneFormat::Toml,
        Some("json") => SceneFormat::Json,
        other => {
            return Err(SceneError::Invalid {
                origin,
                field: "<file name>".into(),
                value: format!("{:?}", other.unwrap_or("")),
                allowed: "the extension must be .toml or .json".into(),
            })
        }
    };
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::Io {
        path: origin.clone(),
        reason: e.to_string(),
    })?;
    parse_scene(&text, format, &origin)
}
