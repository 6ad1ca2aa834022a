//! One CSV row per run (`soda run --csv`, the experiments): the run's configuration, its
//! wall time and hash, and every kernel counter in total, so runs can be compared in a
//! spreadsheet or a notebook.

use anyhow::{bail, Context, Result};
use soda::sim::RunReport;
use std::io::Write;
use std::path::Path;

/// The column names and values of `report`'s row.
pub fn run_row(report: &RunReport, bodies: usize) -> Vec<(String, String)> {
    let mut row: Vec<(String, String)> = Vec::new();
    let mut put = |k: &str, v: String| row.push((k.to_string(), v));
    put("scene", report.scene.clone());
    put("executor", report.executor.clone());
    put("bodies", bodies.to_string());
    let k = report.kernel.as_ref();
    put("worlds", k.map_or(1, |k| k.worlds).to_string());
    put("threads", k.map_or(1, |k| k.threads).to_string());
    put(
        "mode",
        k.map_or("none".into(), |k| k.mode.name().to_string()),
    );
    put("window", k.map_or(0, |k| k.window).to_string());
    put(
        "partition",
        k.map_or("none".into(), |k| k.partition.name().to_string()),
    );
    put("steps", report.steps.to_string());
    put("wall_seconds", format!("{:.6}", report.wall_seconds));
    put("hash", report.hash.clone());
    let total = k.map(|k| k.counters.total.clone()).unwrap_or_default();
    put("efficiency", format!("{:.6}", total.efficiency()));
    put("step_efficiency", format!("{:.6}", total.step_efficiency()));
    put("rollbacks", total.rollbacks().to_string());
    if let Ok(serde_json::Value::Object(map)) = serde_json::to_value(&total) {
        for (name, value) in map {
            put(&name, value.to_string());
        }
    }
    put(
        "gvt_advances",
        k.map_or(0, |k| k.counters.gvt_advances).to_string(),
    );
    let times = k.and_then(|k| k.thread_times.clone());
    put(
        "busy_seconds",
        times
            .as_ref()
            .map_or(String::new(), |t| format!("{:.6}", t.busy_seconds)),
    );
    put(
        "gvt_seconds",
        times
            .as_ref()
            .map_or(String::new(), |t| format!("{:.6}", t.gvt_seconds)),
    );
    put(
        "idle_seconds",
        times
            .as_ref()
            .map_or(String::new(), |t| format!("{:.6}", t.idle_seconds)),
    );
    row
}

/// Appends `report`'s row to the CSV file at `path`, writing the header first if the file is
/// new or empty. An existing file with a different header is an error (nothing is written).
pub fn append_run_row(path: &Path, report: &RunReport, bodies: usize) -> Result<()> {
    let row = run_row(report, bodies);
    let header = csv_line(row.iter().map(|(k, _)| k));
    let existing = match std::fs::read_to_string(path) {
        Ok(text) => Some(text),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            return Err(e).with_context(|| format!("cannot read the CSV file {}", path.display()))
        }
    };
    let mut text = String::new();
    match existing.as_deref().and_then(|t| t.lines().next()) {
        None => text.push_str(&header),
        Some(first) if first == header.trim_end() => {}
        Some(first) => bail!(
            "{} already holds a table with other columns (its header starts `{}`); \
             give --csv a new file name",
            path.display(),
            first.chars().take(60).collect::<String>()
        ),
    }
    text.push_str(&csv_line(row.iter().map(|(_, v)| v)));
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("cannot open the CSV file {}", path.display()))?;
    file.write_all(text.as_bytes())
        .with_context(|| format!("cannot append to the CSV file {}", path.display()))
}

/// One CSV line (fields quoted where needed, a line break at the end).
pub fn csv_line<S: AsRef<str>>(fields: impl IntoIterator<Item = S>) -> String {
    let fields: Vec<String> = fields.into_iter().map(|f| csv_field(f.as_ref())).collect();
    fields.join(",") + "\n"
}

/// A CSV field, quoted when it holds a comma, a quote or a line break.
fn csv_field(v: &str) -> String {
    if v.contains([',', '"', '\n']) {
        format!("\"{}\"", v.replace('"', "\"\""))
    } else {
        v.to_string()
    }
}
