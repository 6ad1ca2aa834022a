//! Output files that are either the old file or a whole new one, never half-written.
//!
//! An [`AtomicFile`] writes to a temporary file beside its target, `<dir>/.<name>.tmp-<pid>`,
//! and [`AtomicFile::commit`] flushes it, syncs it to disk and renames it over the target in
//! one step. A temporary file that is never committed (an error, Ctrl-C) is removed: when the
//! `AtomicFile` is dropped, or by [`discard_all`] on the way out of an interrupted run, which
//! runs no destructors. A crash or `kill -9` can leave a hidden `.NAME.tmp-PID` file behind,
//! never a damaged target.

use anyhow::{Context, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Every temporary file not yet committed or discarded, for [`discard_all`].
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// A file being written under a temporary name, renamed into place by [`AtomicFile::commit`].
pub struct AtomicFile {
    target: PathBuf,
    temp: PathBuf,
    out: Option<BufWriter<File>>,
}

/// The temporary name of `target`: a hidden file in the same directory (so the final rename
/// never crosses file systems), unique to this process.
pub fn temp_path(target: &Path) -> PathBuf {
    let name = target
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    let temp = format!(".{name}.tmp-{}", std::process::id());
    match target.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(temp),
        _ => PathBuf::from(temp),
    }
}

impl AtomicFile {
    /// Creates the temporary file of `target` (which is not touched until the commit).
    pub fn create(target: &Path) -> Result<AtomicFile> {
        let temp = temp_path(target);
        let file = File::options()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&temp)
            .with_context(|| {
                format!(
                    "cannot create the temporary file {} (written first, then renamed to {})",
                    temp.display(),
                    target.display()
                )
            })?;
        lock_live().push(temp.clone());
        Ok(AtomicFile {
            target: target.to_path_buf(),
            temp,
            out: Some(BufWriter::with_capacity(1 << 16, file)),
        })
    }

    /// Flushes, syncs and renames the temporary file over the target: afterwards the target
    /// holds exactly what was written. On an error the temporary file is removed and the
    /// target is left as it was.
    pub fn commit(mut self) -> Result<()> {
        let Some(out) = self.out.take() else {
            return Ok(());
        };
        let result = out
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|file| file.sync_all())
            .with_context(|| format!("cannot write {}", self.target.display()))
            .and_then(|()| {
                std::fs::rename(&self.temp, &self.target).with_context(|| {
                    format!(
                        "cannot rename {} to {}",
                        self.temp.display(),
                        self.target.display()
                    )
                })
            });
        match result {
            Ok(()) => forget(&self.temp),
            Err(_) => self.remove_temp(),
        }
        result
    }

    fn remove_temp(&self) {
        let _ = std::fs::remove_file(&self.temp);
        forget(&self.temp);
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.out.as_mut() {
            Some(out) => out.write(buf),
            None => Err(std::io::Error::other("the file was already committed")),
        }
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        match self.out.as_mut() {
            Some(out) => out.write_all(buf),
            None => Err(std::io::Error::other("the file was already committed")),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self.out.as_mut() {
            Some(out) => out.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.out.take().is_some() {
            self.remove_temp();
        }
    }
}

/// Syncs the directory holding `path`, so a rename into it survives a power cut (best
/// effort: some file systems cannot sync a directory).
pub fn sync_dir_of(path: &Path) {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// Writes `bytes` to `target` through an [`AtomicFile`].
pub fn write(target: &Path, bytes: &[u8]) -> Result<()> {
    let mut file = AtomicFile::create(target)?;
    file.write_all(bytes)
        .with_context(|| format!("cannot write {}", target.display()))?;
    file.commit()
}

/// Removes every temporary file not yet committed (an interrupted run's way out, which runs
/// no destructors).
pub fn discard_all() {
    let live = std::mem::take(&mut *lock_live());
    for temp in live {
        let _ = std::fs::remove_file(temp);
    }
}

fn forget(temp: &Path) {
    lock_live().retain(|p| p != temp);
}

fn lock_live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn the_target_is_untouched_until_the_commit_replaces_it_whole() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.json");
        std::fs::write(&target, "old").unwrap();
        let mut f = AtomicFile::create(&target).unwrap();
        f.write_all(b"new and longer").unwrap();
        f.flush().unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        f.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new and longer");
        assert_eq!(names(dir.path()), ["out.json"]);
    }

    #[test]
    fn an_uncommitted_file_leaves_the_target_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.csv");
        std::fs::write(&target, "old").unwrap();
        {
            let mut f = AtomicFile::create(&target).unwrap();
            f.write_all(b"half").unwrap();
        }
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        assert_eq!(names(dir.path()), ["out.csv"]);
    }
}
