//! The staged pipeline: kill and resume, fingerprints, shards, sweeps.

mod common;
use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A profiling track over the plane: 4000 pulses, so four parts of 1000.
fn track_campaign(dir: &Path, rays: u64) -> PathBuf {
    let scene = write(
        dir,
        "plane.yaml",
        "name: p\nmaterials:\n  soil: { reflectance: { 1064: 0.3 } }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [100, 100]], material: soil }\n",
    );
    write(
        dir,
        "campaign.yaml",
        &format!(
            "name: track\nscene: {}\nseed: 9\nwavelength_nm: 1064\ninstrument: {{ pulse_energy_j: 0.001, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 0.5, fov_half_angle_mrad: 0.6, receiver_area_m2: 0.1 }}\nplatform: {{ kind: track, altitude_m: 300, track: {{ start: [10, 50], end: [90, 50] }}, along_track_step_m: 0.02 }}\nsimulation: {{ method: bdpt, rays_per_pulse: {rays}, max_order: 5 }}\n",
            scene.display()
        ),
    )
}

fn run_ok(args: &[&str]) -> String {
    let (code, out, err) = lidarsim(args);
    assert_eq!(code, 0, "lidarsim {args:?}: {err}");
    err + &out
}

/// The products of a run folder: the planned pulses and every waveform part, by name.
fn products(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = vec![(
        "pulses.parquet".to_string(),
        std::fs::read(dir.join("pulses.parquet")).unwrap(),
    )];
    let mut parts: Vec<PathBuf> = std::fs::read_dir(dir.join("waveforms"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "parquet"))
        .collect();
    parts.sort();
    for p in parts {
        files.push((
            p.file_name().unwrap().to_string_lossy().into_owned(),
            std::fs::read(&p).unwrap(),
        ));
    }
    files
}

fn no_temp_files(dir: &Path) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            no_temp_files(&p);
        } else {
            assert!(
                !p.to_string_lossy().contains(".tmp-"),
                "temporary file left: {}",
                p.display()
            );
        }
    }
}

#[test]
fn killed_run_resumes_to_the_same_products() {
    let dir = tmp("pipe_kill");
    let camp = track_campaign(&dir, 1500);
    let camp = camp.to_str().unwrap();
    let reference = dir.join("reference");
    run_ok(&["run", camp, "--out", reference.to_str().unwrap()]);
    assert_eq!(products(&reference).len(), 5, "pulses + 4 parts");

    let out = dir.join("killed");
    // kill twice during simulation: once right after the first part lands, once after the
    // second; each time the process is in the middle of writing the next one
    for wait_for in ["part-00000.parquet", "part-00001.parquet"] {
        let mut args = vec!["run", camp, "--out", out.to_str().unwrap()];
        if wait_for != "part-00000.parquet" {
            args.push("--resume");
        }
        let mut child = Command::new(env!("CARGO_BIN_EXE_lidarsim"))
            .args(&args)
            .spawn()
            .unwrap();
        let t = Instant::now();
        while !out.join("waveforms").join(wait_for).is_file() {
            assert!(t.elapsed() < Duration::from_secs(120), "no part appeared");
            assert!(
                child.try_wait().unwrap().is_none(),
                "the run ended before it could be killed"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        assert!(
            !out.join("report.md").exists(),
            "killed during simulation, the report cannot exist"
        );
    }
    let log = run_ok(&["run", camp, "--out", out.to_str().unwrap(), "--resume"]);
    assert!(log.contains("plan: up to date"), "{log}");
    no_temp_files(&out);
    assert_eq!(
        products(&out),
        products(&reference),
        "resumed products differ from an uninterrupted run"
    );
}

fn manifest(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap()
}

#[test]
fn resume_redoes_what_changed_and_nothing_else() {
    let dir = tmp("pipe_fingerprint");
    let camp = track_campaign(&dir, 200);
    let (camp, out) = (camp.to_str().unwrap(), dir.join("run"));
    let out_s = out.to_str().unwrap();
    run_ok(&["run", camp, "--out", out_s]);
    let first = std::fs::read(out.join("manifest.json")).unwrap();
    let part = std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap();

    // unchanged: nothing is redone, not one byte of the manifest changes
    let log = run_ok(&["run", camp, "--out", out_s, "--resume"]);
    assert!(log.contains("nothing to do"), "{log}");
    assert_eq!(std::fs::read(out.join("manifest.json")).unwrap(), first);

    // the scene changes: simulation and everything after it are redone, the plan is kept
    let m0 = manifest(&out);
    let scene = dir.join("plane.yaml");
    let text = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("1064: 0.3", "1064: 0.4");
    std::fs::write(&scene, text).unwrap();
    let log = run_ok(&["run", camp, "--out", out_s, "--resume"]);
    assert!(log.contains("plan: up to date"), "{log}");
    assert!(log.contains("simulated 4000 pulses"), "{log}");
    let m1 = manifest(&out);
    assert_eq!(m1["stages"]["plan"], m0["stages"]["plan"]);
    for stage in ["simulate", "products", "report"] {
        assert_ne!(
            m1["stages"][stage]["fingerprint"], m0["stages"][stage]["fingerprint"],
            "{stage}"
        );
        assert_eq!(m1["stages"][stage]["status"], "done");
    }
    assert_ne!(
        std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap(),
        part
    );

    // the products alone change (points and a DSM, then the DSM's cells): the plan and the
    // waveforms are kept, the products and the report redone
    let part = std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap();
    let with_products = |resolution: f64| {
        let text = std::fs::read_to_string(camp).unwrap();
        let text = text.split("products:").next().unwrap().to_string();
        let text =
            format!("{text}products: {{ points: true, dsm: {{ resolution_m: {resolution} }} }}\n");
        std::fs::write(camp, text).unwrap();
    };
    let mut last = m1;
    for resolution in [2.0, 4.0] {
        with_products(resolution);
        let log = run_ok(&["run", camp, "--out", out_s, "--resume"]);
        assert!(log.contains("plan: up to date"), "{log}");
        assert!(log.contains("simulate: up to date"), "{log}");
        assert!(log.contains("0 parts simulated"), "{log}");
        let m = manifest(&out);
        for stage in ["plan", "simulate"] {
            assert_eq!(m["stages"][stage], last["stages"][stage], "{stage}");
        }
        for stage in ["products", "report"] {
            assert_ne!(
                m["stages"][stage]["fingerprint"], last["stages"][stage]["fingerprint"],
                "{stage}"
            );
            assert_eq!(m["stages"][stage]["status"], "done");
        }
        assert!(out.join("points.las").is_file() && out.join("dsm/report.json").is_file());
        last = m;
    }
    // products no longer asked for go with the edit: LAZ for LAS, no DSM
    let text = std::fs::read_to_string(camp).unwrap();
    let text = text.split("products:").next().unwrap().to_string();
    std::fs::write(
        camp,
        format!("{text}products: {{ points: true, points_format: laz }}\n"),
    )
    .unwrap();
    let log = run_ok(&["run", camp, "--out", out_s, "--resume"]);
    assert!(log.contains("simulate: up to date"), "{log}");
    assert!(out.join("points.laz").is_file(), "{log}");
    assert!(!out.join("points.las").exists() && !out.join("dsm").exists());
    assert_eq!(
        std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap(),
        part
    );
}

#[test]
fn shards_then_resume_equal_one_run() {
    let dir = tmp("pipe_shards");
    let camp = track_campaign(&dir, 200);
    let camp = camp.to_str().unwrap();
    let whole = dir.join("whole");
    run_ok(&["run", camp, "--out", whole.to_str().unwrap()]);
    let sharded = dir.join("sharded");
    let s = sharded.to_str().unwrap();
    for k in 0..3 {
        let shard = format!("{k}/3");
        let log = run_ok(&["run", camp, "--out", s, "--shard", &shard]);
        // each shard simulates only its parts: 4 parts over 3 shards
        let expect = if k == 0 { 2 } else { 1 };
        assert!(
            log.contains(&format!("{expect} parts simulated")),
            "shard {k}: {log}"
        );
        if k == 0 {
            // the products asked for before the other shards ran: the simulation is said
            // unfinished (it was said out of date, as if the campaign had changed)
            let (code, _, err) = lidarsim(&["run", camp, "--out", s, "--stages", "products"]);
            assert_eq!(code, 1, "{err}");
            assert!(
                err.contains("simulate has not finished") && err.contains("other shards"),
                "{err}"
            );
        }
    }
    assert!(
        !sharded.join("report.md").exists()
            || manifest(&sharded)["stages"]["simulate"]["status"] == "done"
    );
    let log = run_ok(&["run", camp, "--out", s, "--resume"]);
    assert!(log.contains("0 parts simulated"), "{log}");
    // the rate over the pulses of the shard that finished the stage, not over all of them
    let report = std::fs::read_to_string(sharded.join("report.md")).unwrap();
    assert!(
        report.contains("for the last invocation's 1000 of 4000 pulses"),
        "{report}"
    );
    assert_eq!(products(&sharded), products(&whole));
}

/// A sweep stopped before its last run (here: that run's folder cannot be made) is still a
/// sweep `compare` reads: its index is written before the runs, and a run not begun is a
/// row of empty cells.
#[test]
fn a_sweep_stopped_midway_is_compared() {
    let dir = tmp("pipe_sweep_stopped");
    let camp = track_campaign(&dir, 4);
    let text =
        std::fs::read_to_string(&camp).unwrap() + "sweep:\n  platform.altitude_m: [300, 600]\n";
    let camp = write(&dir, "sweep.yaml", &text);
    let out = dir.join("runs");
    std::fs::create_dir_all(&out).unwrap();
    // a file where the second run's folder goes
    write(&out, "altitude_m=600", "in the way");
    let (code, _, err) = lidarsim(&[
        "run",
        camp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    let (code, table, err) = lidarsim(&["compare", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| l.contains("altitude_m="))
        .collect();
    assert_eq!(rows.len(), 2, "{table}");
    assert!(
        rows[0].contains("| 300 |") && rows[1].contains('–'),
        "{table}"
    );
    // and the empty row is said to be a run not begun, not a run that found nothing
    assert!(err.contains("altitude_m=600: not begun"), "{err}");
    assert!(!err.contains("altitude_m=300:"), "{err}");
}

#[test]
fn sweep_runs_every_combination_with_one_scene_load() {
    let dir = tmp("pipe_sweep");
    let camp = track_campaign(&dir, 100);
    let text = std::fs::read_to_string(&camp).unwrap()
        + "sweep:\n  platform.altitude_m: [300, 600]\n  instrument.fov_half_angle_mrad: [0.6, 1.0]\n";
    let camp = write(&dir, "sweep.yaml", &text);
    let out = dir.join("runs");
    let log = run_ok(&[
        "run",
        camp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(
        log.matches("loaded in").count(),
        1,
        "the scene must be loaded once: {log}"
    );
    for alt in ["300", "600"] {
        for fov in ["0.6", "1.0"] {
            let sub = out.join(format!("altitude_m={alt}_fov_half_angle_mrad={fov}"));
            assert!(sub.join("report.md").is_file(), "{}", sub.display());
            let resolved = std::fs::read_to_string(sub.join("campaign.resolved.yaml")).unwrap();
            assert!(
                resolved.contains(&format!("altitude_m: {alt}.0"))
                    && !resolved.contains("\nsweep:"),
                "{resolved}"
            );
        }
    }
    // a higher platform: the same energy arrives later and weaker (∝ 1/H²), over the part's
    // 1000 pulses, within 1 % (at 300 m the field of view clips the edge of the footprint
    // by a few tenths of a percent)
    let w = |alt: &str| {
        lidarsim::waveform::file::read_waveforms(&out.join(format!(
            "altitude_m={alt}_fov_half_angle_mrad=1.0/waveforms/part-00000.parquet"
        )))
        .unwrap()
    };
    let (a, b) = (w("300"), w("600"));
    assert!(b[0].t0_ns > a[0].t0_ns + 1900.0);
    let mean = |v: &[lidarsim::waveform::Waveform]| {
        let n = v.len() as f64;
        let e = v.iter().map(|w| w.received_energy_j).sum::<f64>() / n;
        let se = v
            .iter()
            .map(|w| w.received_energy_se_j.powi(2))
            .sum::<f64>()
            .sqrt()
            / n;
        (e, se)
    };
    let ((ea, sa), (eb, sb)) = (mean(&a), mean(&b));
    let ratio = ea / eb;
    let se = ratio * (sa / ea).hypot(sb / eb);
    println!("energy ratio 300 m / 600 m: {ratio:.4} ± {se:.4}");
    assert!(
        3.0 * se < 0.01 * 4.0,
        "standard error {se} too large for a 1% test"
    );
    assert!((ratio - 4.0).abs() < 0.04, "{ratio}");
}

#[test]
fn bad_shard_and_stage_arguments() {
    let dir = tmp("pipe_args");
    let camp = track_campaign(&dir, 10);
    let camp = camp.to_str().unwrap();
    for (args, words) in [
        (vec!["--shard", "3/3"], "--shard 3/3"),
        (vec!["--shard", "x"], "expected K/N"),
        (
            vec!["--stages", "plan,simulat"],
            "invalid value 'simulat' for '--stages",
        ),
        (
            vec!["--stages", "plan,simulat"],
            "possible values: plan, simulate, products, report",
        ),
        // a negative number is a value of its flag, refused as one, not a flag of its own
        (vec!["--threads", "-1"], "'--threads <THREADS>'"),
        (vec!["--shard", "-1/2"], "--shard -1/2"),
    ] {
        let mut a = vec!["run", camp];
        a.extend(args);
        let (code, _, err) = lidarsim(&a);
        assert_eq!(code, 1, "{err}");
        assert!(err.contains(words), "{err}");
    }
}

/// The same campaign run from another folder is the same run: the scene's path as found from
/// the working folder is no part of a stage's fingerprint, so `--resume` finds it up to date.
#[test]
fn a_campaign_run_from_another_folder_is_the_same_run() {
    let dir = tmp("pipeline-elsewhere");
    write(
        &dir,
        "plane.yaml",
        "name: p\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [100, 100]], material: soil }\n",
    );
    write(
        &dir,
        "campaign.yaml",
        "name: elsewhere\nscene: plane.yaml\nseed: 2\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 0.5, fov_half_angle_mrad: 0.6, receiver_area_m2: 0.1 }\nplatform: { kind: track, altitude_m: 300, track: { start: [10, 50], end: [90, 50] }, along_track_step_m: 0.5 }\nsimulation: { method: forward, rays_per_pulse: 20, max_order: 1 }\n",
    );
    let out = dir.join("run");
    let run_in = |cwd: &Path, campaign: &str, resume: bool| {
        let mut args = vec!["run", campaign, "--out", out.to_str().unwrap()];
        if resume {
            args.push("--resume");
        }
        let o = Command::new(env!("CARGO_BIN_EXE_lidarsim"))
            .current_dir(cwd)
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(0), "{err}");
        err
    };
    run_in(&dir, "campaign.yaml", false);
    let parent = dir.parent().unwrap();
    let name = dir.file_name().unwrap().to_str().unwrap();
    let again = run_in(parent, &format!("{name}/campaign.yaml"), true);
    assert!(again.contains("nothing to do"), "{again}");
}

/// SIGTERM (a scheduler's time limit) and SIGINT (Ctrl-C) stop a run at the next part: the
/// part in flight is written, the manifest says what is missing, the exit code is 128 + the
/// signal's number and the message says how to go on; `--resume` then finishes the run with
/// the same bytes as a run never stopped.
#[test]
fn a_signal_stops_a_run_cleanly_and_resume_finishes_it() {
    let dir = tmp("pipe_signal");
    let camp = track_campaign(&dir, 1500);
    let camp = camp.to_str().unwrap();
    let reference = dir.join("reference");
    run_ok(&["run", camp, "--out", reference.to_str().unwrap()]);
    let mut checked = 0;
    for signal in ["-TERM", "-INT"] {
        let out = dir.join(format!("stopped{signal}"));
        let child = Command::new(env!("CARGO_BIN_EXE_lidarsim"))
            .args(["run", camp, "--out", out.to_str().unwrap()])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let t = Instant::now();
        while !out.join("waveforms/part-00000.parquet").is_file() {
            assert!(t.elapsed() < Duration::from_secs(120), "no part appeared");
            std::thread::sleep(Duration::from_millis(5));
        }
        // the shell's own kill: a fresh machine may have no kill binary (procps)
        let sent = Command::new("sh")
            .args(["-c", &format!("kill {signal} {}", child.id())])
            .status()
            .unwrap();
        assert!(sent.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        if o.status.code() == Some(0) {
            // the run finished before the signal arrived: nothing to check this time
            eprintln!("{signal}: the run ended before the signal; not checked");
            continue;
        }
        // a stopped run is a failed run: exit code 1, as every failure
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("stopped by SIG") && err.contains("run again with --resume"),
            "{err}"
        );
        // stopped between parts of the simulation, or (had it simulated them all) at the
        // products stage's first part: either way no later stage counts as done
        let m = manifest(&out);
        let simulate = m["stages"]["simulate"]["status"].as_str().unwrap_or("");
        assert!(simulate == "partial" || simulate == "done", "{m}");
        assert!(m["stages"].get("products").is_none(), "{m}");
        assert!(!out.join("report.md").exists());
        no_temp_files(&out);
        checked += 1;
        run_ok(&["run", camp, "--out", out.to_str().unwrap(), "--resume"]);
        assert_eq!(
            products(&out),
            products(&reference),
            "{signal}: resumed products differ from an uninterrupted run"
        );
    }
    assert!(checked > 0, "no signal arrived while the run was going");
}

/// The disk filling mid-part, simulated with a file-size limit (RLIMIT_FSIZE, `ulimit -f`):
/// the run ends with exit code 1 and one message naming the file and what to do, leaves no
/// damaged file under a final name, and `--resume` without the limit finishes it with the same
/// bytes as a run never stopped. Before, SIGXFSZ killed the process without a word.
#[test]
fn a_full_disk_ends_the_run_with_a_message_and_resume_finishes_it() {
    let dir = tmp("pipe_fsize");
    let camp = track_campaign(&dir, 200);
    let camp = camp.to_str().unwrap();
    let reference = dir.join("reference");
    run_ok(&["run", camp, "--out", reference.to_str().unwrap()]);
    let part = std::fs::metadata(reference.join("waveforms/part-00000.parquet"))
        .unwrap()
        .len();
    let pulses = std::fs::metadata(reference.join("pulses.parquet"))
        .unwrap()
        .len();
    // 60 blocks: 30 or 60 KiB as the shell counts them, room for the plan, none for a part
    assert!(pulses < 30 * 1024 && part > 60 * 1024, "{pulses} {part}");
    let out = dir.join("full");
    let o = Command::new("sh")
        .args([
            "-c",
            &format!(
                "ulimit -f 60 && exec '{}' run '{camp}' --out '{}'",
                env!("CARGO_BIN_EXE_lidarsim"),
                out.display()
            ),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_default();
    assert!(
        line.contains("waveforms/part-00000") && line.contains("--resume"),
        "{err}"
    );
    assert!(!out.join("waveforms/part-00000.parquet").exists());
    no_temp_files(&out);
    run_ok(&["run", camp, "--out", out.to_str().unwrap(), "--resume"]);
    assert_eq!(products(&out), products(&reference));
}

/// Runs the track twice, damages the second run's `waveforms/` folder with `damage`, and
/// checks that `--resume` names part 2 as damaged, simulates it again, and leaves the run's
/// files equal to the untouched run's.
fn part_2_damaged_is_redone(name: &str, damage: impl FnOnce(&Path)) {
    let dir = tmp(name);
    let camp = track_campaign(&dir, 200);
    let camp = camp.to_str().unwrap();
    let reference = dir.join("reference");
    run_ok(&["run", camp, "--out", reference.to_str().unwrap()]);
    let out = dir.join("damaged");
    run_ok(&["run", camp, "--out", out.to_str().unwrap()]);
    damage(&out.join("waveforms"));
    let log = run_ok(&["run", camp, "--out", out.to_str().unwrap(), "--resume"]);
    assert!(
        log.contains("a part file is missing or damaged (waveforms/part-00002.parquet)"),
        "{log}"
    );
    assert_eq!(products(&out), products(&reference));
}

/// A part changed in the middle after its run finished (one flipped bit, which its Parquet
/// footer does not notice) is caught by the checksum written beside it.
#[test]
fn a_part_damaged_after_the_run_is_found_and_redone() {
    part_2_damaged_is_redone("pipe_bitflip", |wf| {
        let part = wf.join("part-00002.parquet");
        let mut bytes = std::fs::read(&part).unwrap();
        let middle = bytes.len() / 2;
        bytes[middle] ^= 0x01;
        std::fs::write(&part, &bytes).unwrap();
    });
}

/// Another part's file under a part's name, its checksum record copied with it (the bytes
/// and the record agree), holds other pulses: it is no part 2.
#[test]
fn a_part_holding_another_parts_pulses_is_redone() {
    part_2_damaged_is_redone("pipe_swapped", |wf| {
        for ext in ["parquet", "fnv"] {
            let from = wf.join(format!("part-00001.{ext}"));
            std::fs::copy(from, wf.join(format!("part-00002.{ext}"))).unwrap();
        }
    });
}

/// Shards of an edited campaign of fewer parts, in a folder of the first one's: the parts
/// past the new last are the old campaign's, and go; the folder then equals one run's.
#[test]
fn shards_of_a_shorter_campaign_leave_no_part_of_the_longer() {
    let dir = tmp("pipe_shorter");
    let camp = track_campaign(&dir, 200);
    let camp = camp.to_str().unwrap();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    run_ok(&["run", camp, "--out", o]);
    assert!(out.join("waveforms/part-00003.parquet").is_file());
    // the track cut to half its length: two parts of 1000 pulses
    let text = std::fs::read_to_string(camp).unwrap();
    std::fs::write(camp, text.replace("end: [90, 50]", "end: [50, 50]")).unwrap();
    let reference = dir.join("reference");
    run_ok(&["run", camp, "--out", reference.to_str().unwrap()]);
    for shard in ["0/2", "1/2"] {
        run_ok(&["run", camp, "--out", o, "--shard", shard]);
    }
    run_ok(&["run", camp, "--out", o, "--resume"]);
    for k in 2..4 {
        for ext in ["parquet", "fnv", "stats.csv"] {
            let old = out.join(format!("waveforms/part-0000{k}.{ext}"));
            assert!(!old.exists(), "{} left", old.display());
        }
    }
    assert_eq!(products(&out), products(&reference));
}

/// The marker naming the simulation that made the parts, lost or damaged after the run, is
/// put back by `--resume` (the parts are whole): the folder equals an untouched run's.
#[test]
fn a_lost_simulation_marker_is_put_back() {
    let dir = tmp("pipe_marker");
    let camp = track_campaign(&dir, 20);
    let camp = camp.to_str().unwrap();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    run_ok(&["run", camp, "--out", o]);
    let marker = out.join("waveforms/fingerprint");
    let want = std::fs::read_to_string(&marker).unwrap();
    for damage in [None, Some("hello")] {
        match damage {
            None => std::fs::remove_file(&marker).unwrap(),
            Some(text) => std::fs::write(&marker, text).unwrap(),
        }
        let log = run_ok(&["run", camp, "--out", o, "--resume"]);
        assert!(log.contains("simulate: up to date"), "{log}");
        assert_eq!(std::fs::read_to_string(&marker).unwrap(), want);
    }
}

/// `--stages` asks for stages whose inputs are there: a later stage without its earlier one
/// done is an error naming the stage to include, never "nothing to do" or "complete".
#[test]
fn stages_without_their_inputs_are_refused() {
    let dir = tmp("pipe_stage_inputs");
    let camp = track_campaign(&dir, 10);
    let camp = camp.to_str().unwrap();
    let out = dir.join("run");
    let out = out.to_str().unwrap();
    let (code, _, err) = lidarsim(&["run", camp, "--out", out, "--stages", "plan"]);
    assert_eq!(code, 0, "{err}");
    for (stages, missing) in [
        ("products", "stage simulate has not run"),
        ("report", "stage simulate has not run"),
        ("report,plan", "stage simulate has not run"),
    ] {
        let (code, _, err) = lidarsim(&["run", camp, "--out", out, "--stages", stages]);
        assert_eq!(code, 1, "--stages {stages}: {err}");
        assert!(
            err.contains(missing) && err.contains("include it in --stages"),
            "--stages {stages}: {err}"
        );
    }
    let (code, _, err) = lidarsim(&["run", camp, "--out", out, "--stages", "simulate"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = lidarsim(&["run", camp, "--out", out, "--stages", "report"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("stage products has not run"), "{err}");
    let (code, _, err) = lidarsim(&["run", camp, "--out", out, "--stages", "products,report"]);
    assert_eq!(code, 0, "{err}");
    assert!(Path::new(out).join("report.md").is_file());
}

/// A new campaign run into a used folder removes what the last run's products wrote (its
/// points and DSM), so that `compare` and Python never read them as this run's; a products
/// stage made stale by an edited campaign takes its files with it.
#[test]
fn a_new_run_in_a_used_folder_leaves_no_old_products() {
    let dir = tmp("pipe_old_products");
    let camp = track_campaign(&dir, 10);
    let text = std::fs::read_to_string(&camp).unwrap().replace(
        "instrument: { ",
        "products: { points: true, dsm: { resolution_m: 5 } }\ninstrument: { kind: discrete_return, ",
    );
    let points = write(&dir, "points.yaml", &text);
    let out = dir.join("run");
    let run = |c: &Path, extra: &[&str]| {
        let mut a = vec!["run", c.to_str().unwrap(), "--out", out.to_str().unwrap()];
        a.extend(extra);
        let (code, _, err) = lidarsim(&a);
        assert_eq!(code, 0, "{err}");
    };
    run(&points, &[]);
    assert!(out.join("points.las").is_file() && out.join("dsm/dsm.tif").is_file());
    run(&camp, &[]);
    assert!(!out.join("points.las").exists(), "the old points stayed");
    assert!(!out.join("dsm").exists(), "the old DSM stayed");
    assert!(out.join("report.md").is_file());
    // an edit that makes the products stale, resumed only as far as the plan
    run(&points, &[]);
    assert!(out.join("points.las").is_file());
    let edited = write(&dir, "edited.yaml", &text.replace("seed: 9", "seed: 10"));
    run(&edited, &["--resume", "--stages", "plan"]);
    assert!(!out.join("points.las").exists(), "stale points stayed");
}
