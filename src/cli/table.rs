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
    put(
        "window",
        k.map_or("0".into(), |k| k.window_spec().to_string()),
    );
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

/// The header line of a run table (with its line break): the column names of
/// [`run_row`], which depend on no run.
pub fn header() -> String {
    let mut names: Vec<String> = [
        "scene",
        "executor",
        "bodies",
        "worlds",
        "threads",
        "mode",
        "window",
        "partition",
        "steps",
        "wall_seconds",
        "hash",
        "efficiency",
        "step_efficiency",
        "rollbacks",
    ]
    .map(String::from)
    .to_vec();
    if let Ok(serde_json::Value::Object(map)) =
        serde_json::to_value(soda::kernel::WorldCounters::default())
    {
        names.extend(map.keys().cloned());
    }
    names.extend(
        [
            "gvt_advances",
            "busy_seconds",
            "gvt_seconds",
            "idle_seconds",
        ]
        .map(String::from),
    );
    csv_line(names)
}

/// The longest first line read from an existing table (a longer one is not ours).
const FIRST_LINE_LIMIT: u64 = 64 * 1024;

/// The first line of `file` (without its line break), reading at most
/// [`FIRST_LINE_LIMIT`] bytes from the start; `None` if the file is empty.
fn first_line(file: &std::fs::File) -> std::io::Result<Option<String>> {
    use std::io::{BufRead, Read};
    let mut reader = std::io::BufReader::new(file.take(FIRST_LINE_LIMIT));
    let mut bytes = Vec::new();
    reader.read_until(b'\n', &mut bytes)?;
    if bytes.is_empty() {
        return Ok(None);
    }
    let text = String::from_utf8_lossy(&bytes);
    Ok(Some(text.trim_end_matches(['\n', '\r']).to_string()))
}

/// Refuses a table whose first line is not `header` (nothing is written).
fn check_header(path: &Path, first: Option<&str>, header: &str) -> Result<()> {
    match first {
        None => Ok(()),
        Some(first) if first == header.trim_end() => Ok(()),
        Some(first) => bail!(
            "--csv {}: the file already holds a table with other columns (its header starts \
             `{}`); give --csv a new file name",
            path.display(),
            first.chars().take(60).collect::<String>()
        ),
    }
}

/// Checks, before the run, that a row can be appended to the table `path`: it is absent, or
/// a regular file whose first line (the only part read) is the run table's header.
pub fn check_table(path: &Path) -> Result<()> {
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e).with_context(|| format!("--csv: cannot open {}", path.display())),
    };
    let first = first_line(&file)
        .with_context(|| format!("--csv: cannot read the header of {}", path.display()))?;
    check_header(path, first.as_deref(), &header())?;
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .with_context(|| format!("--csv: cannot open {} for appending", path.display()))?;
    Ok(())
}

/// Appends `report`'s row to the CSV file at `path`, writing the header first if the file is
/// new or empty. An existing file with a different header is an error (nothing is written).
///
/// The file is locked (`flock`) while the row is appended, so runs appending to one table at
/// once each add a whole row; if the append fails (a full disk) the file is cut back to its
/// length before, so it holds the old table or the old table and one whole row.
pub fn append_run_row(path: &Path, report: &RunReport, bodies: usize) -> Result<()> {
    use std::os::unix::fs::FileExt;
    use std::os::unix::io::AsRawFd;
    let row = run_row(report, bodies);
    let header = csv_line(row.iter().map(|(k, _)| k));
    let file = std::fs::OpenOptions::new()
        .read(true)
        .append(true)
        .create(true)
        .open(path)
        .with_context(|| format!("cannot open the CSV file {}", path.display()))?;
    let meta = file
        .metadata()
        .with_context(|| format!("cannot inspect the CSV file {}", path.display()))?;
    if !meta.is_file() {
        bail!("--csv {} is not a regular file", path.display());
    }
    // SAFETY: flock on a descriptor this function owns; released when `file` closes.
    if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
        return Err(std::io::Error::last_os_error())
            .with_context(|| format!("cannot lock the CSV file {}", path.display()));
    }
    let len = file
        .metadata()
        .with_context(|| format!("cannot inspect the CSV file {}", path.display()))?
        .len();
    let first = first_line(&file)
        .with_context(|| format!("cannot read the header of {}", path.display()))?;
    check_header(path, first.as_deref(), &header)?;
    let mut text = String::new();
    if len == 0 {
        text.push_str(&header);
    } else {
        let mut last = [0u8];
        file.read_exact_at(&mut last, len - 1)
            .with_context(|| format!("cannot read {}", path.display()))?;
        if last[0] != b'\n' {
            text.push('\n');
        }
    }
    text.push_str(&csv_line(row.iter().map(|(_, v)| v)));
    let written = (&file)
        .write_all(text.as_bytes())
        .and_then(|()| file.sync_data());
    if let Err(e) = written {
        let restored = file.set_len(len).is_ok();
        return Err(e).with_context(|| {
            format!(
                "cannot append to the CSV file {} ({})",
                path.display(),
                if restored {
                    "cut back to the table it held before"
                } else {
                    "and cannot cut it back: its last row may be partial"
                }
            )
        });
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    #[test]
    fn the_header_names_the_columns_of_a_row() {
        let scene = soda::scene::builtin::builtin("falling-cubes", Some(8), 0).unwrap();
        let options = soda::sim::RunOptions {
            executor: soda::sim::ExecutorKind::Virtual,
            ..soda::sim::RunOptions::default()
        };
        let none = soda::frame::StatesWanted::none();
        for options in [soda::sim::RunOptions::default(), options] {
            let report = soda::sim::run_scene(&scene, &options, 2, &none, |_, _| {}).unwrap();
            let row = super::run_row(&report, 8);
            assert_eq!(super::csv_line(row.iter().map(|c| &c.0)), super::header());
        }
    }
}
