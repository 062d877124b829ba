//! Crash-safe file output: write to a temporary file in the destination's directory, flush it
//! to disk, then rename it over the destination.
//!
//! A rename within one directory is atomic on the file systems we target (ext4, xfs, btrfs,
//! APFS, NTFS), so a reader (or a later run after a crash or power cut) sees either the old file
//! or the complete new one, never half a file. Every writer in this crate goes through
//! [`write_atomically`]; other scarp crates use it for their PNG, JSON and text outputs.
//!
//! The temporary file is named `.<file name>.<process id>.<counter>.tmp` and sits next to the
//! destination. It is removed if the write fails or the closure panics.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use thiserror::Error;

/// Why an atomic write failed. The message names the destination path and the step that failed.
#[derive(Debug, Error)]
#[error("{}: {action}: {source}", path.display())]
pub struct AtomicWriteError {
    /// The destination path the caller asked for (not the temporary file).
    pub path: PathBuf,
    /// The step that failed, for example `"cannot create a temporary file"`.
    pub action: &'static str,
    /// The underlying I/O error (for errors of the caller's closure, the error it returned).
    #[source]
    pub source: io::Error,
}

/// Removes the temporary file unless the write was committed (also on panic).
struct TempGuard {
    path: PathBuf,
    armed: bool,
}

impl Drop for TempGuard {
    fn drop(&mut self) {
        if self.armed {
            // Best effort: the file may already be gone, and there is nobody to report to.
            let _ = fs::remove_file(&self.path);
        }
    }
}

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes a file atomically: `write` fills a buffered temporary file in the same directory as
/// `path`, which is then flushed, synced to disk and renamed to `path` (replacing any existing
/// file; if `path` is a symbolic link, the link itself is replaced). Returns what `write`
/// returns.
///
/// If `path` already exists, the new file takes over its permissions; otherwise it gets the
/// process's default permissions (mode 0666 minus the umask on Unix).
///
/// Callers whose encoders return other error types wrap them with [`io::Error::other`]; the
/// writer is a `BufWriter<File>`, so it also implements [`io::Seek`] (as PNG encoders need).
///
/// # Errors
/// An [`AtomicWriteError`] naming `path` when `path` has no file name, the directory does not
/// exist or is not writable, `write` returns an error, or flushing, syncing or renaming fails.
/// On error the destination is untouched and the temporary file is removed.
///
/// # Example
/// ```
/// use std::io::Write;
/// let dir = std::env::temp_dir().join(format!("scarp-atomic-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("hello.txt");
/// scarp_export::atomic::write_atomically(&path, |w| writeln!(w, "hello")).unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "hello\n");
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_atomically<T, F>(path: impl AsRef<Path>, write: F) -> Result<T, AtomicWriteError>
where
    F: FnOnce(&mut BufWriter<File>) -> io::Result<T>,
{
    let path = path.as_ref();
    let fail = |action: &'static str| {
        move |source: io::Error| AtomicWriteError {
            path: path.to_path_buf(),
            action,
            source,
        }
    };
    let file_name = path.file_name().ok_or_else(|| {
        fail("not a file path")(io::Error::new(
            io::ErrorKind::InvalidInput,
            "the path has no file name",
        ))
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };

    let (file, guard) =
        create_temp(dir, file_name).map_err(fail("cannot create a temporary file"))?;
    let mut writer = BufWriter::new(file);
    let value = write(&mut writer).map_err(fail("write failed"))?;
    let file = writer
        .into_inner()
        .map_err(|e| fail("cannot flush the temporary file")(e.into_error()))?;
    if let Ok(meta) = fs::metadata(path) {
        // Keep the permissions of the file we replace; failure only changes the mode.
        let _ = file.set_permissions(meta.permissions());
    }
    file.sync_all()
        .map_err(fail("cannot sync the temporary file to disk"))?;
    drop(file);
    commit(guard, path)?;
    Ok(value)
}

/// Writes `bytes` to `path` atomically, as [`write_atomically`] does.
///
/// # Errors
/// As [`write_atomically`].
pub fn write_bytes_atomically(
    path: impl AsRef<Path>,
    bytes: &[u8],
) -> Result<(), AtomicWriteError> {
    write_atomically(path, |w| w.write_all(bytes))
}

fn create_temp(dir: &Path, file_name: &std::ffi::OsStr) -> io::Result<(File, TempGuard)> {
    let pid = std::process::id();
    let mut last_error = None;
    // Another process (or thread) may hold the same name; a few attempts with fresh counters
    // resolve any realistic collision.
    for _ in 0..64 {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut name = std::ffi::OsString::from(".");
        name.push(file_name);
        name.push(format!(".{pid}.{n}.tmp"));
        let temp_path = dir.join(name);
        match OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp_path)
        {
            Ok(file) => {
                return Ok((
                    file,
                    TempGuard {
                        path: temp_path,
                        armed: true,
                    },
                ));
            }
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last_error = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last_error.unwrap_or_else(|| io::Error::other("no free temporary file name")))
}

fn commit(mut guard: TempGuard, path: &Path) -> Result<(), AtomicWriteError> {
    fs::rename(&guard.path, path).map_err(|source| AtomicWriteError {
        path: path.to_path_buf(),
        action: "cannot rename the temporary file into place",
        source,
    })?;
    guard.armed = false;
    sync_parent_dir(path);
    Ok(())
}

/// Makes the rename itself durable where the platform allows it (best effort).
fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_files(dir: &Path) -> Vec<String> {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect()
    }

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_bytes_atomically(&path, b"first").unwrap();
        write_bytes_atomically(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        assert!(temp_files(dir.path()).is_empty());
    }

    #[test]
    fn failed_write_leaves_old_file_and_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_bytes_atomically(&path, b"old").unwrap();
        let err = write_atomically(&path, |w| {
            w.write_all(b"half a fi")?;
            Err::<(), _>(io::Error::other("encoder gave up"))
        })
        .unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("a.txt") && msg.contains("encoder gave up"),
            "{msg}"
        );
        assert_eq!(fs::read(&path).unwrap(), b"old");
        assert!(temp_files(dir.path()).is_empty());
    }

    #[test]
    fn panic_in_closure_removes_temp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.bin");
        let result = std::panic::catch_unwind(|| {
            let _ = write_atomically(&path, |w| -> io::Result<()> {
                w.write_all(b"x")?;
                panic!("boom")
            });
        });
        assert!(result.is_err());
        assert!(!path.exists());
        assert!(temp_files(dir.path()).is_empty());
    }

    #[test]
    fn missing_directory_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/dir/out.ply");
        let err = write_bytes_atomically(&path, b"x").unwrap_err();
        assert!(err.to_string().contains("no/such/dir/out.ply"), "{err}");
        assert_eq!(err.source.kind(), io::ErrorKind::NotFound);
    }

    #[test]
    fn path_without_file_name_is_rejected() {
        assert!(write_bytes_atomically("/", b"x").is_err());
        assert!(write_bytes_atomically("..", b"x").is_err());
    }

    #[cfg(unix)]
    #[test]
    fn keeps_permissions_of_replaced_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_bytes_atomically(&path, b"1").unwrap();
        fs::set_permissions(&path, fs::Permissions::from_mode(0o640)).unwrap();
        write_bytes_atomically(&path, b"2").unwrap();
        assert_eq!(
            fs::metadata(&path).unwrap().permissions().mode() & 0o777,
            0o640
        );
    }
}
