//! The real RAMI Wellington citrus orchard (../shared/data/rami-wco): loads through
//! scenes/rami_wco.yaml with instances, and `lidarsim check` reports its size and memory.
//! Skips, saying so, when the data folder is absent.

mod common;
use common::*;

use lidarsim::testdata::rami_dir;

/// Face count from a PLY header, read here independently of the simulator's reader.
fn ply_faces(path: &std::path::Path) -> u64 {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes.windows(10).position(|w| w == b"end_header").unwrap();
    let header = String::from_utf8_lossy(&bytes[..end]);
    header
        .lines()
        .find_map(|l| {
            l.strip_prefix("element face ")
                .map(|n| n.trim().parse().unwrap())
        })
        .unwrap()
}

fn count(report: &str, key: &str) -> u64 {
    report
        .lines()
        .find_map(|l| {
            l.strip_prefix(key)
                .map(|v| v.split_whitespace().next().unwrap().parse::<f64>().unwrap() as u64)
        })
        .unwrap_or_else(|| panic!("no {key} in:\n{report}"))
}

#[test]
fn orchard_check_reports_counts_and_memory() {
    let Some(dir) = rami_dir() else { return };
    let mut trees = 0u64;
    let mut triangles = 0u64;
    for n in 1..=10 {
        let t = dir.join(format!("CISI{n}"));
        let text = std::fs::read_to_string(t.join("location.txt")).unwrap();
        let k = text.lines().filter(|l| !l.trim().is_empty()).count() as u64;
        trees += k;
        triangles += k * (ply_faces(&t.join("foliage.ply")) + ply_faces(&t.join("trunk.ply")));
    }
    assert_eq!(trees, 1115);
    let camp = repo().join("pipelines/rami_wco_gedi.yaml");
    let (code, out, err) = lidarsim(&["check", camp.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    println!("{out}");
    // one instance per tree for the foliage and one for the trunk, plus the ground plane
    assert_eq!(count(&out, "instances:"), 2 * trees + 1);
    // traced as one mesh per template (foliage and trunk share their table) and the ground
    let traced = out.lines().find(|l| l.starts_with("traced as:")).unwrap();
    assert_eq!(
        traced,
        "traced as: 11 meshes, 1116 instances (objects with equal instance tables are one mesh)"
    );
    assert_eq!(count(&out, "triangles (instanced):"), triangles + 2);
    assert!(triangles > 80_000_000, "{triangles}");
    let mb = count(&out, "scene memory:");
    let peak = count(&out, "peak process memory:");
    assert!(
        mb < 2000 && peak < 2000,
        "scene {mb} MB, process peak {peak} MB"
    );
}

/// The bench's repeated orchard is named by an absolute path in its campaign, as every other
/// bench scene is: with a relative output folder (the default, runs/bench) the campaign,
/// written one folder down, named a scene that did not exist there.
#[test]
fn bench_names_the_repeated_orchard_by_an_absolute_path() {
    let Some(_) = rami_dir() else { return };
    use lidarsim::bench::campaigns as bc;
    let repo = lidarsim::testdata::repo();
    let abs = tmp("bench_relative");
    let cwd = std::env::current_dir().unwrap();
    let dir = abs.strip_prefix(&cwd).unwrap_or(&abs);
    let planned = bc::plan(
        dir,
        &repo.join("pipelines/bench"),
        &repo.join("scenes/rami_wco.yaml"),
        false,
    )
    .unwrap();
    let text = planned
        .iter()
        .find_map(|p| match p {
            bc::Planned::Run { name, text, .. } if name == "orchard_gedi_sun_repeated" => {
                Some(text.clone())
            }
            _ => None,
        })
        .expect("the repeated orchard row is planned");
    let scene = text
        .lines()
        .find_map(|l| l.strip_prefix("scene: "))
        .expect("the campaign names its scene");
    let scene = std::path::Path::new(scene.trim().trim_matches('"').trim_matches('\''));
    assert!(
        scene.is_absolute() && scene.is_file(),
        "{}",
        scene.display()
    );
}

/// The repeated orchard is the orchard's scene file with `repeat: true` and a header: nothing
/// else may drift between the two.
#[test]
fn the_repeated_orchard_is_the_orchard_repeated() {
    let read = |f: &str| std::fs::read_to_string(repo().join("scenes").join(f)).unwrap();
    let body = |text: String| -> Vec<String> {
        text.lines()
            .filter(|l| !l.starts_with('#') && *l != "repeat: true")
            .map(str::to_string)
            .collect()
    };
    let repeated = read("rami_wco_repeated.yaml");
    assert!(repeated.lines().any(|l| l == "repeat: true"));
    assert_eq!(body(read("rami_wco.yaml")), body(repeated));
}

/// The bundled spaceborne campaigns write files that look like real granules to mission
/// code: at their site (Wellington, 33.64 S, 19.00 E) and date, GEDI's gate and noise, and
/// ATLAS's six beams, strong and weak as sc_orient 0 says, with a daytime background.
#[test]
fn bundled_mission_campaigns_look_like_granules() {
    let Some(_) = rami_dir() else { return };
    if !python_with("h5py, numpy", "h5py") {
        return;
    }
    let dir = tmp("rami_granules");
    run_cli(
        &repo().join("pipelines/rami_wco_gedi.yaml"),
        &dir.join("gedi"),
        None,
    );
    run_cli(
        &repo().join("pipelines/rami_wco_icesat2.yaml"),
        &dir.join("atl"),
        None,
    );
    let script = r#"
import sys, h5py, numpy as np
d = sys.argv[1]
with h5py.File(d + "/gedi/waveforms_l1b.h5") as f:
    b = f["BEAM0000"]
    assert abs(b["geolocation/latitude_bin0"][0] + 33.64) < 0.01, b["geolocation/latitude_bin0"][0]
    assert abs(b["geolocation/longitude_bin0"][0] - 19.00) < 0.01
    # 2020-03-15T22:00:00Z in seconds since 2018-01-01
    assert b["delta_time"][0] == 69544800.0, b["delta_time"][0]
    assert b["rx_sample_count"][0] == 780
    assert abs(b["noise_mean_corrected"][0] - 205) < 1 and abs(b["noise_stddev_corrected"][0] - 3.3) < 0.3
with h5py.File(d + "/gedi/waveforms_l2a.h5") as f:
    b = f["BEAM0000"]
    assert b["quality_flag"][0] == 1
    # the ground found within a metre of the scene's under the orchard's canopy
    assert abs(b["elev_lowestmode"][0] - b["truth_ground_elev"][0]) < 1.0
with h5py.File(d + "/atl/photons_atl03.h5") as f:
    assert f["orbit_info/sc_orient"][0] == 0
    laser = {}
    for g in ["gt1l", "gt1r", "gt2l", "gt2r", "gt3l", "gt3r"]:
        kind = f[g].attrs["atlas_beam_type"].decode()
        assert kind == ("strong" if g.endswith("l") else "weak"), (g, kind)
        laser[g] = int((f[g + "/heights/truth_source"][:] == 0).sum())
        rate = f[g + "/bckgrd_atlas/bckgrd_rate"][:]
        assert 1e5 < np.median(rate) < 1e7, (g, np.median(rate))
    for p in "123":
        assert laser["gt" + p + "l"] > 2 * laser["gt" + p + "r"], laser
    print("laser photons per beam:", laser)
"#;
    run_python(script, &dir);
}
