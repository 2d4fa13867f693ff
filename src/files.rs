//! Files: atomic writes and the number format of every text file the crate writes.
//!
//! Every writer is atomic: the bytes go to a temporary file in the target's directory, which is
//! flushed, synced and renamed over the target only once everything was written. A failed write
//! (missing directory, full disk, ...) therefore never leaves a partial file at the target path,
//! and any previous file there is kept intact. Errors are one line naming the target path.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

/// Writes a file atomically: `fill` writes the content into a buffered temporary file next to
/// `path`, which is then synced and renamed to `path`.
///
/// On any failure the temporary file is removed, nothing appears at `path` (an existing file
/// there is left untouched) and the error is a one-line [`Error::Io`] naming `path`.
/// Precondition: `path` names a file (not a directory); its directory must exist.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let file_name = path.file_name().ok_or_else(|| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"),
        )
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let (tmp_path, file) = create_temp(&dir, file_name).map_err(|e| Error::io(path, e))?;
    let written = (|| {
        let mut writer = BufWriter::new(file);
        fill(&mut writer)?;
        let file = writer.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&tmp_path, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp_path);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// Creates a fresh temporary file `.<name>.tmp-<pid>-<n>` in `dir` (never overwrites one).
fn create_temp(dir: &Path, name: &std::ffi::OsStr) -> std::io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(".tmp-{}-{n}", std::process::id()));
        let tmp_path = dir.join(tmp_name);
        match File::options().write(true).create_new(true).open(&tmp_path) {
            Ok(f) => return Ok((tmp_path, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

/// Replaces a non-finite value by 0 so that no NaN or infinity ever reaches an output.
pub fn sanitize(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

/// Formats an f64 so that it parses back to the same value: plain decimal for moderate
/// magnitudes, scientific notation otherwise. Non-finite values are written as 0.
pub fn format_f64(x: f64) -> String {
    let x = sanitize(x);
    let a = x.abs();
    if x == 0.0 {
        "0".to_string()
    } else if (1e-4..1e15).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}
