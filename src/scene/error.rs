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
    /// The text is not valid TOML/JSON for a scene (syntax, missing or unknown field, wrong type).
    #[error("{origin}: {message}")]
    Parse {
        /// The file or `<input>`.
        origin: String,
        /// The parser's message, which names the line and field.
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
    #[error("unknown built-in scene `{0}`; `soda scenes` lists them")]
    UnknownBuiltin(String),
}
