//! the Slurm recipe of docs/guide.md on a real one-node Slurm: `tools/slurm_test.sh` starts munged,
//! slurmctld and slurmd in a temporary folder, submits a campaign as a job array with
//! `--shard K/N` and then the `--resume` job with a dependency on the array, checks that the
//! result equals a single-machine run byte for byte, and stops the daemons. Where Slurm is not
//! installed (`apt-get install slurm-wlm munge`, which `.ci/run` does) the test says so on
//! stderr and passes, or fails when `LIDARSIM_REQUIRE_TOOLS=1`.

use lidarsim::testdata::{repo, skip_tool};
use std::process::Command;

/// Whether `slurmctld` is on the PATH (or in /usr/sbin, which a user's PATH may lack).
fn slurmctld_installed() -> bool {
    Command::new("sh")
        .args(["-c", "command -v slurmctld || test -x /usr/sbin/slurmctld"])
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn slurm_array_then_resume_equals_a_single_run() {
    if !slurmctld_installed() {
        skip_tool("slurm test: slurmctld is not installed (apt-get install slurm-wlm munge)");
        return;
    }
    let out = Command::new("bash")
        .arg(repo().join("tools/slurm_test.sh"))
        .arg(env!("CARGO_BIN_EXE_lidarsim"))
        .output()
        .expect("bash runs tools/slurm_test.sh");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    match out.status.code() {
        Some(0) => {
            print!("{stdout}");
            eprint!("{stderr}");
            assert!(stdout.contains("slurm test: passed"), "{stdout}");
        }
        // not run: a tool missing, or not root; the script says which on one line
        Some(2) => skip_tool(stderr.trim()),
        code => panic!("tools/slurm_test.sh exited with {code:?}\n{stdout}\n{stderr}"),
    }
}
