//! Scene errors: each names the field, the value found and what is allowed.

use thiserror::Error;

/// Why a scene was rejected. All are fatal for that scene; nothing is partially loaded.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {reason}")]
    Io {
        /// The path given.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// The text is not valid TOML/JSON for a scene: syntax, a missing or unknown field, a
    /// wrong type, an unknown shape `type`.
    #[error("{origin}: {message}")]
    Parse {
        /// The file or `<input>`.
        origin: String,
        /// The parser's message: the line and column, what is wrong (naming the field) and,
        /// for TOML, the offending line.
        message: String,
    },
    /// A field has a value outside what is allowed.
    #[error("{origin}: field `{field}` = {value} is invalid: {allowed}")]
    Invalid {
        /// The file or `<input>`.
        origin: String,
        /// Path of the field, such as `bodies[3].shape.radius`.
        field: String,
        /// The value found.
        value: String,
        /// What is allowed, and how to fix it.
        allowed: String,
    },
    /// No built-in scene has that name.
    #[error("unknown built-in scene `{0}`: the built-ins are {names} (`soda scenes` describes them)", names = builtin_names())]
    UnknownBuiltin(String),
}

/// The built-in scene names, quoted and comma-separated.
fn builtin_names() -> String {
    super::builtin::BUILTINS
        .iter()
        .map(|b| format!("`{}`", b.name))
        .collect::<Vec<_>>()
        .join(", ")
}
