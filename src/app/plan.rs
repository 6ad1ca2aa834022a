//! Every output path of a command, checked before it computes anything: an hour of
//! computing must not be lost to a typo in an output path.
//!
//! [`OutputPlan`] resolves each output (its directory must exist; a symbolic link is followed
//! to the file it names), refuses an output that is not a regular file (a device, a FIFO, a
//! directory: outputs are renamed into place, see [`crate::app::atomic`]), two outputs naming the
//! same file, and an output that is one of the command's inputs. It proves each directory
//! writable by creating (and removing) a file in it.

use super::atomic::temp_path;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// The outputs (and inputs) of one command, checked as they are added.
#[derive(Debug, Default)]
pub struct OutputPlan {
    outputs: Vec<Planned>,
    inputs: Vec<(String, PathBuf)>,
}

/// One output: the flag that named it, its path as given and resolved.
#[derive(Debug)]
struct Planned {
    flag: String,
    given: PathBuf,
    resolved: PathBuf,
    /// A directory the command fills with files of its own naming.
    dir: bool,
}

impl OutputPlan {
    /// An empty plan.
    pub fn new() -> OutputPlan {
        OutputPlan::default()
    }

    /// Registers an input file (`what` names it in messages, e.g. "the scene file"): no
    /// output may be it. A missing input is left for its loader to report.
    pub fn input(&mut self, what: &str, path: &Path) {
        if let Ok(resolved) = std::fs::canonicalize(path) {
            self.inputs.push((what.to_string(), resolved));
        }
    }

    /// Checks the output file `path` of `flag`: its directory exists and is writable, the
    /// file is absent or a regular file, and no other output or input is the same file.
    /// Returns the path to write (a symbolic link resolved).
    pub fn file(&mut self, flag: &str, path: &Path) -> Result<PathBuf> {
        let shown = path.display();
        let Some(name) = path.file_name() else {
            bail!("{flag} `{shown}` names a directory, not a file: give a file name");
        };
        let dir = existing_dir(flag, path)?;
        let resolved = match std::fs::metadata(path) {
            // Renaming a whole file into place would replace it whatever its mode: a file
            // its owner made read-only is kept, as `--csv` (which appends) keeps it.
            Ok(m) if m.is_file() && m.permissions().readonly() => bail!(
                "{flag} `{shown}` is read-only: soda would replace it; make it writable (chmod u+w {shown}) \
                 or choose another path"
            ),
            Ok(m) if m.is_file() => std::fs::canonicalize(path)
                .with_context(|| format!("{flag}: cannot resolve `{shown}`"))?,
            Ok(m) => bail!(
                "{flag} `{shown}` is {}, not a regular file: soda writes its outputs to regular files only (each \
                 renamed into place once whole), so give the path of a file",
                kind(&m)
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => dir.join(name),
            Err(e) => {
                return Err(e).with_context(|| format!("{flag}: cannot inspect `{shown}`"));
            }
        };
        self.add(flag, path, resolved.clone(), false)?;
        probe_writable(flag, resolved.parent().unwrap_or(&dir))?;
        Ok(resolved)
    }

    /// Checks the output directory `path` of `flag`, creating it (and its parents) if
    /// missing, and proves it writable. Returns its resolved path.
    pub fn dir(&mut self, flag: &str, path: &Path) -> Result<PathBuf> {
        let shown = path.display();
        match std::fs::metadata(path) {
            Ok(m) if !m.is_dir() => bail!(
                "{flag} `{shown}` is {}, not a directory: give a directory (created if missing)",
                kind(&m)
            ),
            _ => {}
        }
        std::fs::create_dir_all(path)
            .with_context(|| format!("{flag}: cannot create the directory `{shown}`"))?;
        let resolved = std::fs::canonicalize(path)
            .with_context(|| format!("{flag}: cannot resolve `{shown}`"))?;
        self.add(flag, path, resolved.clone(), true)?;
        probe_writable(flag, &resolved)?;
        Ok(resolved)
    }

    /// Records an output after checking it against the inputs and the other outputs.
    fn add(&mut self, flag: &str, given: &Path, resolved: PathBuf, dir: bool) -> Result<()> {
        if let Some((what, _)) = self.inputs.iter().find(|(_, p)| *p == resolved) {
            bail!(
                "{flag} `{}` is {what} this command reads: writing it would destroy it; \
                 choose another path for {flag}",
                given.display()
            );
        }
        for other in &self.outputs {
            let clash = other.resolved == resolved
                || (other.dir && resolved.parent() == Some(&other.resolved) && owned(&resolved))
                || (dir && other.resolved.parent() == Some(&resolved) && owned(&other.resolved));
            if clash {
                bail!(
                    "{flag} `{}` and {} `{}` name the same file: each output needs its own path",
                    given.display(),
                    other.flag,
                    other.given.display()
                );
            }
        }
        self.outputs.push(Planned {
            flag: flag.to_string(),
            given: given.to_path_buf(),
            resolved,
            dir,
        });
        Ok(())
    }
}

/// Whether `path` has the name of a file the command writes into an output directory
/// (`--territories`: territory-STEP.svg, imbalance.svg).
fn owned(path: &Path) -> bool {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    name.is_some_and(|n| {
        n == "imbalance.svg" || (n.starts_with("territory-") && n.ends_with(".svg"))
    })
}

/// The directory `path` is in, which must exist.
fn existing_dir(flag: &str, path: &Path) -> Result<PathBuf> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => std::fs::canonicalize(dir)
            .with_context(|| format!("{flag}: cannot resolve the directory `{}`", dir.display())),
        Ok(m) => bail!(
            "{flag} `{}`: `{}` is {}, not a directory",
            path.display(),
            dir.display(),
            kind(&m)
        ),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "{flag} `{}`: the directory `{}` does not exist; create it first (mkdir -p {}) or \
             choose another path",
            path.display(),
            dir.display(),
            dir.display()
        ),
        Err(e) => Err(e).with_context(|| {
            format!(
                "{flag} `{}`: cannot inspect the directory `{}`",
                path.display(),
                dir.display()
            )
        }),
    }
}

/// Creates and removes a file in `dir`, to fail now rather than after the run.
fn probe_writable(flag: &str, dir: &Path) -> Result<()> {
    let probe = temp_path(&dir.join("soda-probe"));
    std::fs::File::create(&probe).with_context(|| {
        format!(
            "{flag}: cannot create a file in the directory `{}` (is it writable?)",
            dir.display()
        )
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// "a directory", "a device", ... for messages.
fn kind(m: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = m.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_outputs_naming_one_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.json");
        let mut plan = OutputPlan::new();
        plan.file("--counters", &a).unwrap();
        let same = dir.path().join(".").join("a.json");
        let err = plan.file("--trace", &same).unwrap_err().to_string();
        assert!(
            err.contains("--trace") && err.contains("--counters"),
            "{err}"
        );
    }

    #[test]
    fn an_output_that_is_an_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("s.toml");
        std::fs::write(&scene, "x").unwrap();
        let mut plan = OutputPlan::new();
        plan.input("the scene file", &scene);
        let err = plan.file("--record", &scene).unwrap_err().to_string();
        assert!(err.contains("scene file"), "{err}");
    }

    #[test]
    fn a_read_only_file_is_refused_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("kept.csv");
        std::fs::write(&path, "mine\n").unwrap();
        let mut perms = std::fs::metadata(&path).unwrap().permissions();
        perms.set_readonly(true);
        std::fs::set_permissions(&path, perms).unwrap();
        let err = OutputPlan::new().file("--record", &path).unwrap_err();
        assert!(format!("{err:#}").contains("is read-only"), "{err:#}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "mine\n");
    }

    #[test]
    fn a_device_or_a_missing_directory_is_refused() {
        let mut plan = OutputPlan::new();
        let err = plan
            .file("--csv", Path::new("/dev/full"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("device"), "{err}");
        let err = plan
            .file("--trace", Path::new("/no/such/dir/t.json"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("does not exist"), "{err}");
    }

    #[test]
    fn a_file_inside_the_territories_directory_with_one_of_its_names_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut plan = OutputPlan::new();
        plan.dir("--territories", dir.path()).unwrap();
        let err = plan
            .file("--counters", &dir.path().join("imbalance.svg"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("same file"), "{err}");
        plan.file("--trace", &dir.path().join("trace.json"))
            .unwrap();
    }
}
