//! Files that a crash cannot leave half-written under their final name.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

pub use crate::error::{RUN_WRITE_ADVICE, WRITE_ADVICE};

/// The temporary name a file is written under before it is renamed into place.
pub fn temp_name(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".tmp-{}", std::process::id()));
    path.with_file_name(name)
}

/// Writes a file through `write` under a temporary name, syncs it, then renames it.
pub fn write_atomic<T>(path: &Path, write: impl FnOnce(File) -> Result<T>) -> Result<T> {
    let (pending, file) = Pending::create(path)?;
    let out = write(file)?;
    pending.commit()?;
    Ok(out)
}

/// The one way a file reaches its final name: `write` writes the temporary path given to it
/// (the temporary name, then `suffix`, for writers that choose a format by extension), which
/// is synced and renamed into place, or removed if anything failed.
pub fn write_atomic_at<T>(
    path: &Path,
    suffix: &str,
    write: impl FnOnce(&Path) -> Result<T>,
) -> Result<T> {
    let pending = Pending::new(path, suffix)?;
    let out = write(&pending.tmp)?;
    pending.commit()?;
    Ok(out)
}

/// A file being written under its temporary name, for writers that take many steps:
/// [`Pending::commit`] syncs it and moves it into place; dropped before that (an error, a
/// panic), it is removed.
pub struct Pending {
    tmp: PathBuf,
    path: PathBuf,
    committed: bool,
}

/// Where a file written to `path` goes: through a symbolic link to the file it names (the
/// link stays, its file is replaced), and into a device, a FIFO or a socket as it is (true:
/// there is no file to replace, `--csv /dev/stdout` writes to standard output).
fn destination(path: &Path) -> (PathBuf, bool) {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() && !m.is_dir() => return (path.to_path_buf(), true),
        Ok(m) if m.is_file() => {
            let linked = std::fs::symlink_metadata(path).is_ok_and(|l| l.file_type().is_symlink());
            if linked {
                if let Ok(target) = std::fs::canonicalize(path) {
                    return (target, false);
                }
            }
        }
        Ok(_) => {}
        Err(_) => {
            // a link to a file not yet there names the file to make
            if let Ok(target) = std::fs::read_link(path) {
                let dir = path.parent().unwrap_or(Path::new(""));
                return (dir.join(target), false);
            }
        }
    }
    (path.to_path_buf(), false)
}

impl Pending {
    /// Creates the folder of `path` and names the temporary file (the temporary name, then
    /// `suffix`); the caller creates the file. A device or FIFO is written in place (see
    /// [`destination`]), for writers that need no format by extension.
    pub fn new(path: &Path, suffix: &str) -> Result<Pending> {
        let (path, in_place) = destination(path);
        let path = path.as_path();
        if in_place {
            if !suffix.is_empty() {
                return Err(Error::file(
                    path,
                    "is a device, FIFO or socket, where this file cannot be written: give a file's name",
                ));
            }
            return Ok(Pending {
                tmp: path.to_path_buf(),
                path: path.to_path_buf(),
                committed: true,
            });
        }
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)
                .map_err(|e| Error::io(dir, "cannot create folder", e).advise(WRITE_ADVICE))?;
        }
        let mut tmp = temp_name(path).into_os_string();
        tmp.push(suffix);
        Ok(Pending {
            tmp: PathBuf::from(tmp),
            path: path.to_path_buf(),
            committed: false,
        })
    }

    /// A pending file with its temporary file created, and that file.
    pub fn create(path: &Path) -> Result<(Pending, File)> {
        let pending = Pending::new(path, "")?;
        let file = File::create(&pending.tmp)
            .map_err(|e| Error::io(path, "cannot create file", e).advise(WRITE_ADVICE))?;
        Ok((pending, file))
    }

    /// The temporary path being written.
    pub fn tmp(&self) -> &Path {
        &self.tmp
    }

    /// Syncs the written file and renames it to its final name.
    pub fn commit(self) -> Result<()> {
        if self.committed {
            // written in place (a device or FIFO): nothing to sync or move
            return Ok(());
        }
        if let Ok(f) = File::open(&self.tmp) {
            let _ = f.sync_all();
        }
        self.rename()
    }

    /// Renames the file, synced by the caller, to its final name.
    fn rename(mut self) -> Result<()> {
        std::fs::rename(&self.tmp, &self.path).map_err(|e| {
            Error::io(&self.path, "cannot move file into place", e).advise(WRITE_ADVICE)
        })?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for Pending {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Commits pending files on a thread of its own, in the order they come, each batch (with
/// those queued meanwhile) synced by one flush of the file system. A sync waits for the disk,
/// and a worker waiting there is a core idle: three syncs per part on the workers would make
/// the plan and simulate stages of a survey of cheap pulses measurably longer.
pub struct Committer {
    send: Option<std::sync::mpsc::Sender<Vec<Pending>>>,
    thread: std::sync::Mutex<Option<std::thread::JoinHandle<Result<()>>>>,
}

impl Default for Committer {
    fn default() -> Committer {
        let (send, received) = std::sync::mpsc::channel::<Vec<Pending>>();
        // on an error the thread stops: the files still queued are dropped, which removes them
        let thread = std::thread::spawn(move || -> Result<()> {
            for mut batch in received.iter() {
                // the batches queued while the last sync waited for the disk go in this one:
                // on a busy file system the syncs then keep pace with the parts
                while let Ok(more) = received.try_recv() {
                    batch.extend(more);
                }
                sync_together(&batch);
                for pending in batch {
                    pending.rename()?;
                }
            }
            Ok(())
        });
        Committer {
            send: Some(send),
            thread: std::sync::Mutex::new(Some(thread)),
        }
    }
}

impl Committer {
    /// Queues `pending` to be synced and renamed after those queued before it; an error is
    /// that of an earlier file the thread could not commit.
    pub fn commit(&self, batch: Vec<Pending>) -> Result<()> {
        match self.send.as_ref().map(|s| s.send(batch)) {
            Some(Ok(())) => Ok(()),
            _ => Err(self.stopped()),
        }
    }

    /// Waits until every queued file is in place.
    pub fn finish(mut self) -> Result<()> {
        drop(self.send.take());
        self.join()
    }

    fn join(&self) -> Result<()> {
        let handle = self.thread.lock().ok().and_then(|mut t| t.take());
        match handle.map(|h| h.join()) {
            None | Some(Ok(Ok(()))) => Ok(()),
            Some(Ok(Err(e))) => Err(e),
            Some(Err(_)) => Err(Error::msg("the thread committing files panicked")),
        }
    }

    /// The error that stopped the thread.
    fn stopped(&self) -> Error {
        match self.join() {
            Err(e) => e,
            Ok(()) => Error::msg("the thread committing files has stopped"),
        }
    }
}

/// Syncs the files of a batch with one flush of their file system: a sync of each would make
/// a journal commit of each.
fn sync_together(batch: &[Pending]) {
    #[cfg(target_os = "linux")]
    if batch.len() > 1 {
        use std::os::fd::AsRawFd;
        if let Some(f) = batch.first().and_then(|p| File::open(&p.tmp).ok()) {
            // SAFETY: syncfs reads nothing but the descriptor, which `f` keeps open
            if unsafe { libc::syncfs(f.as_raw_fd()) } == 0 {
                return;
            }
        }
    }
    // one file, another system, or a flush that failed: each file on its own
    for p in batch {
        if let Ok(f) = File::open(&p.tmp) {
            let _ = f.sync_all();
        }
    }
}

impl Drop for Committer {
    /// Files queued before a failure elsewhere are still committed: they are whole.
    fn drop(&mut self) {
        drop(self.send.take());
        let _ = self.join();
    }
}

pub fn write_text_atomic(path: &Path, text: &str) -> Result<()> {
    text_pending(path, text)?.commit()
}

/// `text` written under the temporary name of `path`, not yet committed.
pub fn text_pending(path: &Path, text: &str) -> Result<Pending> {
    bytes_pending(path, text.as_bytes())
}

fn bytes_pending(path: &Path, bytes: &[u8]) -> Result<Pending> {
    let (pending, mut f) = Pending::create(path)?;
    f.write_all(bytes)
        .map_err(|e| Error::io(path, "cannot write", e).advise(WRITE_ADVICE))?;
    Ok(pending)
}

/// Writes a CSV table (RFC 4180: a field with a comma, quote or line break is quoted) under
/// a temporary name, then renames it: every CSV a user reads goes through here.
pub fn write_csv_atomic<R, F>(path: &Path, header: &[&str], rows: R) -> Result<()>
where
    R: IntoIterator<Item = Vec<F>>,
    F: AsRef<[u8]>,
{
    csv_pending(path, header, rows)?.commit()
}

/// [`write_csv_atomic`]'s table under its temporary name, not yet committed.
pub fn csv_pending<R, F>(path: &Path, header: &[&str], rows: R) -> Result<Pending>
where
    R: IntoIterator<Item = Vec<F>>,
    F: AsRef<[u8]>,
{
    bytes_pending(path, &csv_bytes(path, header, rows)?)
}

fn csv_bytes<R, F>(path: &Path, header: &[&str], rows: R) -> Result<Vec<u8>>
where
    R: IntoIterator<Item = Vec<F>>,
    F: AsRef<[u8]>,
{
    let bad = |e: csv::Error| Error::data(path, format!("cannot encode CSV: {e}"));
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(header).map_err(bad)?;
    for row in rows {
        w.write_record(row).map_err(bad)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| Error::data(path, format!("cannot encode CSV: {e}")))?;
    Ok(bytes)
}

/// FNV-1a, 64 bits, over length-prefixed parts: a fingerprint that is stable across platforms
/// and tool builds, for stage inputs and for checksums of the files a run wrote.
pub fn fingerprint(parts: &[&[u8]]) -> String {
    let mut h = Fnv::default();
    for p in parts {
        h.add(&(p.len() as u64).to_le_bytes());
        h.add(p);
    }
    h.hex()
}

/// FNV-1a, 64 bits.
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    fn add(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= *b as u64;
            self.0 = self.0.wrapping_mul(0x100_0000_01b3);
        }
    }

    fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// The checksum of a file's bytes (XXH64 of its length and bytes, in hex), or None when it
/// cannot be read. Read a block at a time: run files reach gigabytes, and memory must not
/// grow with them. XXH64 reads 8 bytes a step where FNV-1a ([`fingerprint`]) reads one:
/// checking a run's parts with FNV-1a would be a measurable share of the products stage.
pub fn file_checksum(path: &Path) -> Option<String> {
    use std::hash::Hasher;
    use std::io::Read;
    let mut file = File::open(path).ok()?;
    let len = file.metadata().ok()?.len();
    let mut h = twox_hash::XxHash64::with_seed(0);
    h.write(&len.to_le_bytes());
    let mut block = vec![0u8; 1 << 20];
    let mut read = 0u64;
    loop {
        let n = file.read(&mut block).ok()?;
        if n == 0 {
            break;
        }
        h.write(&block[..n]);
        read += n as u64;
    }
    // a file that changed while it was read has no checksum
    (read == len).then(|| format!("{:016x}", h.finish()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file's checksum, read a block at a time, is XXH64 of its length and bytes in one
    /// go, and any one byte changed changes it.
    #[test]
    fn file_checksum_is_the_hash_of_the_bytes() {
        let dir = crate::testdata::TempDir::new("sum");
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f.bin");
        for len in [0usize, 1, (1 << 20) - 1, 1 << 20, (1 << 20) + 7, 3 << 20] {
            let mut bytes: Vec<u8> = (len as u64).to_le_bytes().to_vec();
            bytes.extend((0..len).map(|i| (i * 7 + i / 3) as u8));
            std::fs::write(&path, &bytes[8..]).unwrap();
            let whole = format!("{:016x}", twox_hash::XxHash64::oneshot(0, &bytes));
            let sum = file_checksum(&path);
            assert_eq!(sum.as_deref(), Some(whole.as_str()), "{len}");
            if len > 0 {
                bytes[8 + len / 2] ^= 0x10;
                std::fs::write(&path, &bytes[8..]).unwrap();
                assert_ne!(file_checksum(&path), sum, "{len}");
            }
        }
        assert_eq!(file_checksum(&dir.join("missing")), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Batches reach their final names, whole, once `finish` returns; a file that cannot be
    /// moved into place is an error of a later call, and the temporary files queued after it
    /// are removed, never moved into place.
    #[test]
    fn the_committer_moves_batches_into_place_or_reports_why_not() {
        let dir = crate::testdata::TempDir::new("commit");
        let _ = std::fs::remove_dir_all(&dir);
        let committer = Committer::default();
        for k in 0..20 {
            let a = text_pending(&dir.join(format!("{k}.txt")), &format!("part {k}")).unwrap();
            let b = text_pending(&dir.join(format!("{k}.sum")), "sum").unwrap();
            let batch = if k % 2 == 0 { vec![a, b] } else { vec![a] };
            committer.commit(batch).unwrap();
        }
        committer.finish().unwrap();
        for k in 0..20 {
            let text = std::fs::read_to_string(dir.join(format!("{k}.txt"))).unwrap();
            assert_eq!(text, format!("part {k}"));
            assert_eq!(dir.join(format!("{k}.sum")).exists(), k % 2 == 0);
        }
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 30);

        // a final name that is a folder cannot be renamed over
        let committer = Committer::default();
        std::fs::create_dir_all(dir.join("taken")).unwrap();
        let bad = text_pending(&dir.join("taken"), "x").unwrap();
        let bad_tmp = bad.tmp().to_path_buf();
        committer.commit(vec![bad]).unwrap();
        let mut failed = None;
        for k in 0..200 {
            let p = text_pending(&dir.join(format!("late{k}.txt")), "late").unwrap();
            if let Err(e) = committer.commit(vec![p]) {
                failed = Some(e);
                break;
            }
        }
        let e = match failed {
            Some(e) => e,
            None => committer.finish().unwrap_err(),
        };
        assert!(e.to_string().contains("taken"), "{e}");
        let left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp-") || n.starts_with("late"))
            .collect();
        assert!(!bad_tmp.exists());
        assert!(left.is_empty(), "{left:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn csv_fields_are_quoted_only_when_needed() {
        let dir = crate::testdata::TempDir::new("csv");
        let path = dir.join("t.csv");
        let rows = vec![
            vec!["plain".to_string(), "1.5".to_string()],
            vec!["a,b".to_string(), "say \"hi\"".to_string()],
        ];
        write_csv_atomic(&path, &["run", "value"], rows).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "run,value\nplain,1.5\n\"a,b\",\"say \"\"hi\"\"\"\n");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
