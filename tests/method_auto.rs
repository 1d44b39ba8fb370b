//! `simulation.method: auto`: a pilot picks the method that costs least for a given error, and
//! the run is then the run of that method, byte for byte.

mod common;
use common::*;

/// The score a pilot's note gives candidate `name` (" name 1.2e0,").
fn score_in(note: &str, name: &str) -> f64 {
    let at = note
        .find(&format!(" {name} "))
        .unwrap_or_else(|| panic!("{note}"))
        + name.len()
        + 2;
    note[at..]
        .split([',', ' '])
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// (chosen method, the resolved campaign's text, report.md) of an auto run, after checking that
/// its waveforms are those of a run with the chosen method written out, on 1 and 2 threads.
fn auto_run(name: &str, inst: &Inst) -> (String, String, String) {
    let dir = tmp(name);
    let scene = plane_scene(&dir, 0.3, 200.0);
    let text = |method: &str| {
        campaign(
            &scene,
            inst,
            [0.0, 0.0, 100.0],
            [0.0, 0.0, -1.0],
            method,
            4096,
            3,
        )
    };
    let camp = write(&dir, "auto.yaml", &text("auto"));
    let out = dir.join("auto");
    let err = run_cli(&camp, &out, Some(2));
    assert!(err.contains("simulation.method auto chose"), "{err}");
    let resolved = std::fs::read_to_string(out.join("campaign.resolved.yaml")).unwrap();
    let chosen = ["bdpt", "forward", "backward"]
        .into_iter()
        .find(|m| resolved.contains(&format!("method: {m}\n")))
        .unwrap_or_else(|| panic!("{resolved}"))
        .to_string();
    // the scores in the note: the chosen one is the least
    let note = resolved.lines().next().unwrap();
    let score = |m: &str| score_in(note, m);
    for m in ["bdpt", "forward", "backward"] {
        assert!(score(&chosen) <= score(m), "{note}");
    }
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    // the same campaign with the method written out, on one thread: the same waveforms
    let explicit = write(&dir, "explicit.yaml", &text(&chosen));
    let out1 = dir.join("explicit");
    run_cli(&explicit, &out1, Some(1));
    let part = "waveforms/part-00000.parquet";
    assert!(
        std::fs::read(out.join(part)).unwrap() == std::fs::read(out1.join(part)).unwrap(),
        "auto's waveforms differ from {chosen}'s"
    );
    (chosen, resolved, report)
}

/// A narrow footprint in a wide field of view: receiver paths almost never find the lit spot,
/// so backward tracing is the costliest by far; a wide footprint in a narrow field of view is
/// the mirror case for forward tracing.
#[test]
fn auto_avoids_the_method_that_cannot_find_the_light() {
    let narrow_beam = Inst {
        fp_mrad: 0.5,
        fov_mrad: 100.0,
        area: 0.01,
        ..Inst::default()
    };
    let (chosen, resolved, report) = auto_run("auto_narrow_beam", &narrow_beam);
    println!("narrow beam: {}", resolved.lines().next().unwrap());
    assert_ne!(chosen, "backward");
    assert!(
        resolved.starts_with("# simulation.method auto chose"),
        "{resolved}"
    );
    assert!(
        report.contains("| pilot's choices | simulation.method auto chose"),
        "{report}"
    );

    let narrow_view = Inst {
        fp_mrad: 100.0,
        fov_mrad: 0.5,
        area: 0.01,
        ..Inst::default()
    };
    let (chosen, resolved, _) = auto_run("auto_narrow_view", &narrow_view);
    println!("narrow view: {}", resolved.lines().next().unwrap());
    assert_ne!(chosen, "forward");
}

/// A campaign that names no method gets `auto`, and the pilot's pulses do not alias with the
/// scan: here every eighth of the plan is a whole number of scan periods, so pulses taken at
/// the start of each eighth all looked 15° off nadir, past the edge of a 20 m plane, and the
/// pilot found no energy with any method (what it did before its pulses were drawn within
/// each eighth).
#[test]
fn auto_is_the_default_and_its_pilot_sees_the_scene_whatever_the_scan() {
    let dir = tmp("auto_default_als");
    let scene = plane_scene(&dir, 0.3, 10.0);
    let text = format!(
        "name: alias\nscene: {}\nseed: 5\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.0001\n  pulse_fwhm_ns: 3.0\n  footprint_half_angle_mrad: 0.25\n  fov_half_angle_mrad: 0.375\n  receiver_area_m2: 0.01\n  bin_ns: 0.5\nplatform:\n  kind: als\n  altitude_m: 100\n  speed_m_s: 20\n  prf_hz: 4000\n  lines: [ {{ start: [0, -3.2], end: [0, 3.2] }} ]\n  scanner: {{ pattern: oscillating, scan_angle_deg: [-15, 15], scan_frequency_hz: 50 }}\nsimulation: {{ rays_per_pulse: 4, max_order: 2 }}\n",
        scene.display()
    );
    let camp = write(&dir, "campaign.yaml", &text);
    let out = dir.join("run");
    let err = run_cli(&camp, &out, Some(2));
    assert!(err.contains("plan: 1280 pulses"), "{err}");
    assert!(err.contains("simulation.method auto chose"), "{err}");
    // a tenth of the campaign's 5120 rays per method: 128 pulses of 4 rays
    assert!(err.contains("over 128 pilot pulses of 4 rays"), "{err}");
    let resolved = std::fs::read_to_string(out.join("campaign.resolved.yaml")).unwrap();
    assert!(
        resolved.starts_with("# simulation.method auto chose"),
        "{resolved}"
    );
}

/// `simulation.receiver_depth: auto`, the default, with bdpt named: the pilot scores `full`
/// and `first` on the same pulses and keeps the cheaper (over a plane, where nothing is seen
/// twice, the receiver's deeper vertices find no light: `first`), says so in the log and the
/// resolved campaign, and the run is that of the depth written out, on 1 and 2 threads. A
/// depth written out runs no pilot; forward, with one sub-path, has no use for one.
#[test]
fn receiver_depth_auto_is_chosen_by_the_pilot_and_said() {
    let dir = tmp("depth_auto");
    let scene = plane_scene(&dir, 0.3, 200.0);
    let inst = Inst {
        fp_mrad: 1.0,
        fov_mrad: 1.5,
        ..Inst::default()
    };
    let text = |method: &str| {
        campaign(
            &scene,
            &inst,
            [0.0, 0.0, 100.0],
            [0.0, 0.0, -1.0],
            method,
            4096,
            3,
        )
    };
    let camp = write(&dir, "auto.yaml", &text("bdpt"));
    let out = dir.join("auto");
    let err = run_cli(&camp, &out, Some(2));
    assert!(
        err.contains("simulation.receiver_depth auto chose first"),
        "{err}"
    );
    let resolved = std::fs::read_to_string(out.join("campaign.resolved.yaml")).unwrap();
    assert!(resolved.contains("receiver_depth: first"), "{resolved}");
    let note = resolved.lines().next().unwrap();
    let score = |d: &str| score_in(note, d);
    assert!(score("first") < score("full"), "{note}");
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("simulation.receiver_depth auto chose first"));
    // written out, on one thread: no pilot, the same part
    let explicit = write(&dir, "first.yaml", &text("bdpt, receiver_depth: first"));
    let out1 = dir.join("first");
    let err1 = run_cli(&explicit, &out1, Some(1));
    assert!(!err1.contains("receiver_depth auto"), "{err1}");
    let part = "waveforms/part-00000.parquet";
    assert!(
        std::fs::read(out.join(part)).unwrap() == std::fs::read(out1.join(part)).unwrap(),
        "auto's waveforms differ from first's"
    );
    // full written out: a run of its own
    let full = write(&dir, "full.yaml", &text("bdpt, receiver_depth: full"));
    let out2 = dir.join("full");
    run_cli(&full, &out2, Some(2));
    assert!(std::fs::read(out.join(part)).unwrap() != std::fs::read(out2.join(part)).unwrap());
    // forward: nothing to choose
    let fwd = write(&dir, "forward.yaml", &text("forward"));
    let err3 = run_cli(&fwd, &dir.join("forward"), Some(2));
    assert!(!err3.contains("receiver_depth"), "{err3}");
}

/// `auto` never picks a method that cannot sample a contribution the campaign asks for, and
/// says which it left out and why: forward with the sun over a repeated scene (its sun
/// sub-paths start over one copy only), backward over water (no connection through a smooth
/// surface). The candidates left are scored as before.
#[test]
fn auto_excludes_the_methods_that_cannot_see_a_contribution() {
    let dir = tmp("auto_excluded");
    write(
        &dir,
        "tile.yaml",
        "name: tile\nrepeat: true\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [10, 10]], material: soil }\n",
    );
    let camp = write(
        &dir,
        "c.yaml",
        "name: c\nscene: tile.yaml\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 0.5, fov_half_angle_mrad: 5, receiver_area_m2: 0.1, bandwidth_nm: 1 }\nplatform: { kind: track, altitude_m: 300, track: { start: [0, 5], end: [40, 5] }, along_track_step_m: 1 }\nsun: { zenith_deg: 30, azimuth_deg: 0, irradiance_w_m2_um: 640 }\nsimulation: { method: auto, rays_per_pulse: 64, max_order: 2 }\n",
    );
    let loaded = lidarsim::plan::read_campaign(&camp).unwrap();
    let scene = lidarsim::scene::Scene::load(&loaded.scene_path, 1064.0).unwrap();
    let plan = lidarsim::plan::Plan::new(&loaded.campaign).unwrap();
    let excluded = lidarsim::pipeline::simulate::excluded_methods(&loaded, &scene);
    assert_eq!(excluded.len(), 1, "{excluded:?}");
    assert_eq!(excluded[0].0, lidarsim::campaign::Method::Forward);
    let chosen = lidarsim::pipeline::with_method_chosen(&loaded, &scene, &plan).unwrap();
    assert_ne!(
        chosen.campaign.simulation.method,
        lidarsim::campaign::Method::Forward
    );
    let note = chosen.method_note.unwrap();
    assert!(
        note.contains("excluded: forward (it cannot sample the sun's light"),
        "{note}"
    );
    assert!(
        !note.contains(" forward fixed ") && !note.contains(" forward power "),
        "{note}"
    );
    // over water, backward
    let lake = lidarsim::testdata::repo().join("pipelines/bathymetry.yaml");
    let loaded = lidarsim::plan::read_campaign(&lake).unwrap();
    let scene =
        lidarsim::scene::Scene::load_bands(&loaded.scene_path, loaded.campaign.wavelength_nm.all())
            .unwrap();
    let excluded = lidarsim::pipeline::simulate::excluded_methods(&loaded, &scene);
    assert_eq!(
        excluded.iter().map(|e| e.0).collect::<Vec<_>>(),
        [lidarsim::campaign::Method::Backward]
    );
}

/// A pulse from the centre of a sphere (`sphere`, a scene file) at `rays` rays to `order`:
/// a 20 mrad beam seen through a 500 mrad field of view.
fn in_sphere(sphere: &std::path::Path, method: &str, rays: u64, order: &str) -> String {
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad: 500.0,
        area: 0.01,
        energy: 0.001,
        ..Inst::default()
    };
    campaign(
        sphere,
        &inst,
        [0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0],
        method,
        rays,
        3,
    )
    .replace("max_order: 3", &format!("max_order: {order}"))
}

/// The order `max_order: auto` chose, and its line of the log `err`.
fn chosen_order(err: &str) -> (usize, &str) {
    let note = err
        .lines()
        .find(|l| l.contains("max_order auto chose"))
        .unwrap_or_else(|| panic!("{err}"));
    let k = note
        .split("max_order auto chose ")
        .nth(1)
        .and_then(|s| s.split([':', ',', ' ']).next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{note}"));
    (k, note)
}

/// `simulation.max_order: auto` models only the orders a scene needs: over a plane (one
/// order: nothing scatters light back to it) it picks 1; inside a sphere of albedo 0.9 it
/// picks the order past which the energy left, in a run to order 100 with 16 times the rays,
/// is below a tenth of a pulse's standard error (within that run's own 3 SE), and the auto
/// run is the run with that order written out, byte for byte. So it does where the run traces
/// more rays than its pilot's 2048, whose paths stop short of orders that still matter at the
/// run's error (albedo 0.8: none of the pilot's paths passes order 26, yet past it lies four
/// times order 26's energy), and with bdpt.
#[test]
fn max_order_auto_keeps_the_orders_that_matter() {
    let dir = tmp("auto_order");
    let plane = plane_scene(&dir, 0.3, 200.0);
    let inst = Inst {
        fp_mrad: 1.0,
        fov_mrad: 2.0,
        area: 0.01,
        ..Inst::default()
    };
    let text = campaign(
        &plane,
        &inst,
        [0.0, 0.0, 100.0],
        [0.0, 0.0, -1.0],
        "forward",
        4096,
        3,
    )
    .replace("max_order: 3", "max_order: auto");
    let camp = write(&dir, "over_plane.yaml", &text);
    let err = run_cli(&camp, &dir.join("plane"), None);
    assert!(err.contains("max_order auto chose 1:"), "{err}");
    let resolved = std::fs::read_to_string(dir.join("plane/campaign.resolved.yaml")).unwrap();
    assert!(resolved.contains("max_order: 1\n"), "{resolved}");

    for (albedo, rays, method) in [
        (0.9, 2048, "forward"),
        (0.8, 8192, "forward"),
        (0.9, 8192, "bdpt"),
    ] {
        let name = format!("{method}_{albedo}_{rays}");
        let sphere = sphere_scene(&dir, albedo);
        let text = |rays: u64, order: &str| in_sphere(&sphere, method, rays, order);
        let camp = write(&dir, &format!("{name}.yaml"), &text(rays, "auto"));
        let err = run_cli(&camp, &dir.join(&name), None);
        let (k, note) = chosen_order(&err);
        eprintln!("{name}: {note}");
        assert!((10..100).contains(&k), "{note}");
        let auto = all_waveforms(&dir.join(&name));
        if name == "forward_0.9_2048" {
            let explicit = write(&dir, "explicit.yaml", &text(rays, &k.to_string()));
            run_cli(&explicit, &dir.join("explicit"), None);
            let part = "waveforms/part-00000.parquet";
            assert!(
                std::fs::read(dir.join(&name).join(part)).unwrap()
                    == std::fs::read(dir.join("explicit").join(part)).unwrap(),
                "the auto run differs from max_order {k}"
            );
        }
        let deep_name = format!("{name}_deep");
        let deep = write(&dir, &format!("{deep_name}.yaml"), &text(16 * rays, "100"));
        run_cli(&deep, &dir.join(&deep_name), None);
        let d = &all_waveforms(&dir.join(&deep_name))[0];
        let tail: f64 = d.order_energy_j[k..].iter().sum();
        let tail_se = d.order_energy_se_j[k..]
            .iter()
            .map(|s| s * s)
            .sum::<f64>()
            .sqrt();
        let pulse_se = auto[0].received_energy_se_j;
        eprintln!(
            "{name}: order {k}: tail past it {tail:.3e} J (SE {tail_se:.3e}) against a pulse's SE {pulse_se:.3e} J"
        );
        assert!(
            tail <= 0.1 * pulse_se + 3.0 * tail_se,
            "{name}: tail {tail:.3e} J past order {k}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// With several bands each band's tail is bounded: inside a sphere of albedo 0.2 at 532 nm
/// and 0.9 at 1064 nm, traced once for both with 532 nm first, `auto` keeps the orders the
/// 1064 nm band needs (10 or more, as the sphere of albedo 0.9 alone) and says it was that
/// band, where the first band alone would stop within a few orders.
#[test]
fn max_order_auto_bounds_every_band() {
    let dir = tmp("auto_order_bands");
    let mesh = repo().join("scenes/meshes/sphere_r10.obj");
    let sphere = write(
        &dir,
        "sphere.yaml",
        &format!(
            "name: s\nmaterials:\n  wall: {{ reflectance: {{ 532: 0.2, 1064: 0.9 }} }}\nobjects:\n  - mesh: {{ file: {}, material: wall }}\n",
            mesh.display()
        ),
    );
    let text = in_sphere(&sphere, "forward", 2048, "auto")
        .replace("wavelength_nm: 1064", "wavelength_nm: [532, 1064]");
    assert!(text.contains("[532, 1064]"), "{text}");
    let camp = write(&dir, "bands.yaml", &text);
    let err = run_cli(&camp, &dir.join("bands"), None);
    let (k, note) = chosen_order(&err);
    eprintln!("{note}");
    assert!(k >= 10 && note.contains("the 1064 nm band"), "{note}");
    let _ = std::fs::remove_dir_all(&dir);
}
