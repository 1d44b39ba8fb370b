//! Files that a crash cannot leave half-written under their final name.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary name a file is written under before it is renamed into place.
pub fn temp_name(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".tmp-{}", std::process::id()));
    path.with_file_name(name)
}

/// Writes a file through `write` under a temporary name, syncs it, then renames it.
pub fn write_atomic<T>(path: &Path, write: impl FnOnce(File) -> Result<T>) -> Result<T> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::file(dir, format!("cannot create folder: {e}")))?;
    }
    let tmp = temp_name(path);
    let file =
        File::create(&tmp).map_err(|e| Error::file(&tmp, format!("cannot create file: {e}")))?;
    let out = match write(file) {
        Ok(v) => v,
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
    };
    if let Ok(f) = File::open(&tmp) {
        let _ = f.sync_all();
    }
    std::fs::rename(&tmp, path)
        .map_err(|e| Error::file(path, format!("cannot move file into place: {e}")))?;
    Ok(out)
}

pub fn write_text_atomic(path: &Path, text: &str) -> Result<()> {
    write_atomic(path, |mut f| {
        f.write_all(text.as_bytes())
            .map_err(|e| Error::file(path, format!("cannot write: {e}")))
    })
}
