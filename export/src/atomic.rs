//! Atomic file writes: write to a temporary file beside the target, then rename, so a crash
//! never leaves half a file.

use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes a file atomically. `write` fills a buffered writer; on success the temporary file is
/// flushed, synced and renamed over `path`. On failure the temporary file is removed and `path`
/// is untouched.
///
/// # Errors
/// Any I/O error from creating, writing, syncing or renaming.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let file_name = path.file_name().ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
    })?;
    let mut temporary_name = std::ffi::OsString::from(".");
    temporary_name.push(file_name);
    temporary_name.push(format!(".tmp{}", std::process::id()));
    let temporary = path.with_file_name(temporary_name);
    let result = (|| {
        let mut writer = BufWriter::new(std::fs::File::create(&temporary)?);
        write(&mut writer)?;
        let file = writer.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&temporary, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

/// Writes bytes to a file atomically; see [`write_atomically`].
///
/// # Errors
/// Any I/O error.
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomically(path, |w| w.write_all(bytes))
}
