//! For the tests: data they need from outside the repository, and how a test that cannot run
//! says so. A skip is printed on stderr (cargo shows it). `LIDARSIM_REQUIRE_DATA=1`, which
//! `.ci/run` sets where `../shared/` is present, turns a skip for want of data into a failure;
//! `LIDARSIM_REQUIRE_TOOLS=1`, which it sets once it has installed laspy and Slurm, does the
//! same for a skip for want of an outside tool.

use std::path::PathBuf;

/// The repository's folder.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The RAMI orchard's files, `../shared/data/rami-wco` beside the repository, when present;
/// otherwise the test skips, saying so.
pub fn rami_dir() -> Option<PathBuf> {
    let d = repo().join("../shared/data/rami-wco");
    if d.join("CISI1/foliage.ply").is_file() {
        Some(d)
    } else {
        skip(&format!(
            "RAMI data not found at {} (docs/guide.md, \"Scenes\")",
            d.display()
        ));
        None
    }
}

/// The real mission granules, `../shared/reference` beside the repository, when present;
/// otherwise the test skips, saying so.
pub fn reference_dir() -> Option<PathBuf> {
    let d = repo().join("../shared/reference");
    if d.join("gedi").is_dir() && d.join("icesat2").is_dir() {
        Some(d)
    } else {
        skip(&format!(
            "real GEDI and ATL03 granules not found at {}",
            d.display()
        ));
        None
    }
}

/// Says on stderr why a test cannot run for want of data; fails the test instead when
/// `LIDARSIM_REQUIRE_DATA=1`.
pub fn skip(why: &str) {
    skip_unless("LIDARSIM_REQUIRE_DATA", why);
}

/// Says on stderr why a test cannot run for want of an outside tool (laspy, Slurm); fails the test
/// instead when `LIDARSIM_REQUIRE_TOOLS=1`.
pub fn skip_tool(why: &str) {
    skip_unless("LIDARSIM_REQUIRE_TOOLS", why);
}

fn skip_unless(required: &str, why: &str) {
    if std::env::var(required).is_ok_and(|v| v == "1") {
        panic!("this test cannot run, and {required}=1 requires it: {why}");
    }
    eprintln!("SKIPPED: {why}");
}

/// The most of `n` independent bins that may fall outside 3 standard errors by chance: each
/// does with p = 0.0027, and more than this many with a probability below 1e-6 (the Poisson
/// tail of mean n p).
pub fn most_outside_3se(n: usize) -> usize {
    let lambda = 0.0027 * n as f64;
    let (mut k, mut term) = (0usize, (-lambda).exp());
    let mut below = term;
    while 1.0 - below > 1e-6 {
        k += 1;
        term *= lambda / k as f64;
        below += term;
    }
    k
}

/// A folder for one test's files in the system's temporary directory, named after the test
/// and the process (tests run side by side), removed with everything in it when dropped: a
/// test leaves nothing behind, passed or failed. It derefs to its path.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(name: &str) -> TempDir {
        let d = std::env::temp_dir().join(format!("lidarsim-{name}-{}", std::process::id()));
        TempDir::at(d)
    }

    /// The folder `dir` itself, made fresh (emptied if it was there) and removed when
    /// dropped: an integration test's folder under cargo's `CARGO_TARGET_TMPDIR`.
    pub fn at(dir: PathBuf) -> TempDir {
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot make the test folder {}: {e}", dir.display()));
        TempDir(dir)
    }

    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl std::ops::Deref for TempDir {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for TempDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
