//! Reading scene files (TOML or JSON) into validated scenes, and writing scenes back out.

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

impl SceneFormat {
    /// The format's name in messages: `TOML` or `JSON`.
    pub fn name(self) -> &'static str {
        match self {
            SceneFormat::Toml => "TOML",
            SceneFormat::Json => "JSON",
        }
    }

    /// The format a path's extension names (`.toml` or `.json`, any case), if any.
    pub fn from_path(path: &Path) -> Option<SceneFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "toml" => Some(SceneFormat::Toml),
            "json" => Some(SceneFormat::Json),
            _ => None,
        }
    }

    /// Writes `scene` as text in this format; [`parse_scene`] reads it back to an equal
    /// scene (every `f32` keeps its bits).
    ///
    /// TOML has no null, so a scene without a ground plane (`environment.ground` absent)
    /// cannot be written as TOML — reading the file back would give the default ground at
    /// y = 0. That case is an error naming the field; write JSON (`"ground": null`) instead.
    pub fn render(self, scene: &Scene) -> Result<String, SceneError> {
        let failed = |message: String| SceneError::Invalid {
            origin: format!("scene `{}`", scene.name),
            field: "<scene>".into(),
            value: "<in memory>".into(),
            allowed: format!("it could not be written as {}: {message}", self.name()),
        };
        match self {
            SceneFormat::Toml => {
                if scene.environment.ground.is_none() {
                    return Err(SceneError::Invalid {
                        origin: format!("scene `{}`", scene.name),
                        field: "environment.ground".into(),
                        value: "null (no ground plane)".into(),
                        allowed: "TOML has no null, so a scene without a ground cannot be written as TOML (an absent `ground` reads back as the default ground at y = 0); write it as JSON, where `\"ground\": null` means no ground".into(),
                    });
                }
                toml::to_string(scene).map_err(|e| failed(e.to_string()))
            }
            SceneFormat::Json => {
                serde_json::to_string_pretty(scene).map_err(|e| failed(e.to_string()))
            }
        }
    }
}

/// Parses and validates a scene text. `origin` names it in error messages.
///
/// Syntax errors, missing or unknown fields, wrong types and unknown shape types are
/// [`SceneError::Parse`] (the message names the line and column, and the field); values
/// outside what is allowed are [`SceneError::Invalid`] (naming the field path, such as
/// `bodies[3].shape.radius`, the value and what is allowed).
pub fn parse_scene(text: &str, format: SceneFormat, origin: &str) -> Result<Scene, SceneError> {
    let scene: Scene = match format {
        SceneFormat::Toml => from_toml(text).map_err(|message| SceneError::Parse {
            origin: origin.to_string(),
            message,
        })?,
        SceneFormat::Json => from_json(text).map_err(|message| SceneError::Parse {
            origin: origin.to_string(),
            message,
        })?,
    };
    validate(&scene, origin)?;
    Ok(scene)
}

/// Parses a TOML scene or input script: on an error, the message names the field's path
/// (`at `bodies[0].material.density``), the line and column, and shows the line.
pub(crate) fn from_toml<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    let de = toml::Deserializer::parse(text).map_err(|e| toml_message(&e, text))?;
    serde_path_to_error::deserialize(de)
        .map_err(|e| at_path(e.path(), toml_message(e.inner(), text)))
}

/// A parser's `message` prefixed with the field's path (`at `bodies[0].id`: ...`), unless
/// the error is at the top.
///
/// Where the path holds a key the parser could not read (a JSON syntax error where a field
/// name goes: a trailing comma, a missing comma, an unquoted name), `serde_path_to_error`
/// writes `?`; the message says in words where it is instead: `between the fields of
/// `bodies[0]``.
fn at_path(path: &serde_path_to_error::Path, message: String) -> String {
    use serde_path_to_error::Segment;
    let mut known = String::new();
    let mut unreadable = false;
    for segment in path.iter() {
        match segment {
            Segment::Seq { index } => known += &format!("[{index}]"),
            Segment::Map { key } | Segment::Enum { variant: key } => {
                if !known.is_empty() {
                    known.push('.');
                }
                known += key;
            }
            Segment::Unknown => {
                unreadable = true;
                break;
            }
        }
    }
    match (unreadable, known.is_empty()) {
        (false, true) => message,
        (false, false) => format!("at `{known}`: {message}"),
        (true, true) => format!("between the top-level fields: {message}"),
        (true, false) => format!("between the fields of `{known}`: {message}"),
    }
}

/// The parser's words for what it expected, in a scene file's terms rather than Rust's:
/// `expected f32` becomes `expected a number`, `expected u64` `expected a whole number, 0
/// or more`, `expected struct BodySpec` `expected a table of fields` (TOML) or `an object
/// of fields` (JSON).
fn plain_types(message: &str, format: SceneFormat) -> String {
    let fields = match format {
        SceneFormat::Toml => "a table of fields",
        SceneFormat::Json => "an object of fields",
    };
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(at) = rest.find("expected ") {
        let (before, after) = rest.split_at(at + "expected ".len());
        out += before;
        let word_end = |s: &str| {
            s.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(s.len())
        };
        let word = &after[..word_end(after)];
        let plain = match word {
            "f32" | "f64" => Some("a number"),
            "u64" | "usize" => Some("a whole number, 0 or more"),
            "u32" => Some("a whole number from 0 to 4294967295"),
            "u16" => Some("a whole number from 0 to 65535"),
            "u8" => Some("a whole number from 0 to 255"),
            _ => None,
        };
        rest = match plain {
            Some(plain) => {
                out += plain;
                &after[word.len()..]
            }
            None => match after.strip_prefix("struct ") {
                Some(tail) => {
                    out += fields;
                    &tail[word_end(tail)..]
                }
                None => match after.strip_prefix("a sequence") {
                    Some(tail) => {
                        out += "an array";
                        tail
                    }
                    None => after,
                },
            },
        };
    }
    out + rest
}

/// The TOML parser's message, with the line and column when it has a location.
pub(crate) fn toml_message(e: &toml::de::Error, text: &str) -> String {
    let message = plain_types(e.message().trim_end(), SceneFormat::Toml);
    let Some(span) = e.span() else {
        return message.to_string();
    };
    let start = span.start.min(text.len());
    let before = &text.as_bytes()[..start];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let column = start
        - before
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |p| p + 1)
        + 1;
    if start == 0 && span.end >= text.len() {
        // The whole document: a missing top-level field.
        return format!("at the top level: {message}");
    }
    let source = text.lines().nth(line - 1).unwrap_or("").trim_end();
    if source.is_empty() {
        return format!("line {line}, column {column}: {message}");
    }
    format!("line {line}, column {column}: {message}\n  |\n{line:>3} | {source}")
}

/// Parses a JSON scene or input script: on an error, the message names the field's path
/// (`at `bodies[0].material.density`: invalid type: ...`), the line and column, as TOML's do.
pub(crate) fn from_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    // A byte-order mark (some editors save UTF-8 with one) is not JSON, but the text is:
    // TOML files with one were read, JSON files failed at line 1 column 1.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if text.trim_start().starts_with('[') {
        return Err(
            "the file is a JSON array: a scene or input script is one JSON object \
                    ({ ... }) with named fields"
                .into(),
        );
    }
    let mut de = serde_json::Deserializer::from_str(text);
    let value = serde_path_to_error::deserialize(&mut de)
        .map_err(|e| at_path(e.path(), json_message(e.inner(), text)))?;
    de.end().map_err(|e| json_message(&e, text))?;
    Ok(value)
}

/// The JSON parser's message, which already ends with the line and column; a syntax error
/// on a line holding `NaN` or `Infinity` (not JSON, which has finite numbers only) says so.
pub(crate) fn json_message(e: &serde_json::Error, text: &str) -> String {
    let kind = match e.classify() {
        serde_json::error::Category::Syntax => "syntax error: ",
        serde_json::error::Category::Eof => "unexpected end of file: ",
        _ => "",
    };
    let line = text.lines().nth(e.line().saturating_sub(1)).unwrap_or("");
    let not_json = ["NaN", "Infinity"].into_iter().find(|w| line.contains(w));
    match not_json {
        Some(word) if e.classify() == serde_json::error::Category::Syntax => format!(
            "{kind}{e}: `{word}` is not a JSON number (JSON has no NaN or Infinity); every \
             number in a scene must be finite"
        ),
        _ => format!("{kind}{}", plain_types(&e.to_string(), SceneFormat::Json)),
    }
}

/// Reads, parses and validates a scene file; the extension (`.toml` or `.json`) picks the
/// syntax.
pub fn load_scene_file(path: &Path) -> Result<Scene, SceneError> {
    let origin = path.display().to_string();
    let Some(format) = SceneFormat::from_path(path) else {
        return Err(SceneError::Invalid {
            origin,
            field: "<file name>".into(),
            value: match path.extension() {
                Some(e) => format!("`.{}`", e.to_string_lossy()),
                None => "no extension".into(),
            },
            allowed: "a scene file's extension must be .toml or .json".into(),
        });
    };
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::Io {
        path: origin.clone(),
        reason: e.to_string(),
    })?;
    parse_scene(&text, format, &origin)
}
