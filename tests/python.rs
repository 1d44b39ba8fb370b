//! The Python package, tested as a user gets it: a fresh virtual environment, `pip install .`
//! into it (the extension is built here, from this checkout), then its pytest suite
//! (python/tests). Skipped, saying why, where python3 or its venv module is missing; failed
//! then under `LIDARSIM_REQUIRE_TOOLS=1`, as `.ci/run` sets it.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Instant;

fn run(what: &str, cmd: &mut Command) -> Output {
    let t = Instant::now();
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    eprintln!("{what}: {:.1} s", t.elapsed().as_secs_f64());
    out
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn the_python_package_installs_with_pip_and_passes_its_suite() {
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let has_venv = Command::new(&python)
        .args(["-c", "import venv, ensurepip"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_venv {
        lidarsim::testdata::skip_tool(&format!(
            "{python} with its venv and ensurepip modules is not available (Debian: apt-get \
             install python3-venv)"
        ));
        return;
    }
    let repo = lidarsim::testdata::repo();
    let work = Path::new(env!("CARGO_TARGET_TMPDIR")).join("python");
    let _ = std::fs::remove_dir_all(&work);
    let (venv, scratch) = (work.join("venv"), work.join("tmp"));
    std::fs::create_dir_all(&scratch).unwrap();
    let venv_python = venv.join("bin/python");
    // Python's and pip's temporary files go to a folder removed at the end
    let env = |c: &mut Command| {
        c.env("TMPDIR", &scratch)
            .env("PIP_DISABLE_PIP_VERSION_CHECK", "1")
            .current_dir(&repo);
    };
    let o = run(
        "python3 -m venv",
        Command::new(&python).args(["-m", "venv"]).arg(&venv),
    );
    assert!(
        o.status.success(),
        "cannot make a virtual environment: {}",
        text(&o)
    );
    let mut pip = Command::new(&venv_python);
    pip.args(["-m", "pip", "install", "--quiet", ".[test]"]);
    env(&mut pip);
    let o = run(
        "pip install .[test] (the extension's build included)",
        &mut pip,
    );
    if !o.status.success() {
        let why = text(&o);
        // no registry to fetch maturin, pyarrow or pytest from: the suite cannot run here
        if why.contains("No matching distribution") || why.contains("Failed to establish") {
            lidarsim::testdata::skip_tool(&format!("pip cannot fetch the build's tools: {why}"));
            let _ = std::fs::remove_dir_all(&work);
            return;
        }
        panic!("pip install . failed: {why}");
    }
    let mut pytest = Command::new(&venv_python);
    pytest
        .args([
            "-m",
            "pytest",
            "python/tests",
            "-q",
            "-p",
            "no:cacheprovider",
            "--basetemp",
        ])
        .arg(work.join("pytest"))
        // the Rust binary this test run built: Python's runs must write its files
        .env("LIDARSIM_BIN", env!("CARGO_BIN_EXE_lidarsim"));
    env(&mut pytest);
    let o = run("pytest python/tests", &mut pytest);
    let out = text(&o);
    eprintln!(
        "{}",
        out.lines().rev().take(3).collect::<Vec<_>>().join("\n")
    );
    let _ = std::fs::remove_dir_all(&work);
    assert!(o.status.success(), "the Python suite failed:\n{out}");
}
