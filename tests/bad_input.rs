//! Bad input ends with exit code 1 and one message naming the file, the line and the key.

mod common;
use common::*;

const SCENE: &str = "name: s
materials:
  soil: { reflectance: { 1064: 0.3 } }
objects:
  - plane: { z: 0, extent: [[0, 0], [10, 10]], material: soil }
";

const CAMPAIGN: &str = "name: bad
scene: scene.yaml
wavelength_nm: 1064
instrument:
  pulse_energy_j: 0.001
  pulse_fwhm_ns: 2
  footprint_half_angle_mrad: 1
  fov_half_angle_mrad: 2
  receiver_area_m2: 0.1
platform:
  kind: static
  pulses:
    - position: [5, 5, 100]
      direction: [0, 0, -1]
simulation: { rays_per_pulse: 100 }
";

/// Writes a campaign and scene (either may be edited) and runs `lidarsim check` on it.
fn check(name: &str, campaign: &str, scene: &str) -> (i32, String, Tmp) {
    let dir = tmp(&format!("bad_{name}"));
    write(&dir, "scene.yaml", scene);
    let path = write(&dir, "campaign.yaml", campaign);
    let (code, _out, err) = lidarsim(&["check", path.to_str().unwrap()]);
    (code, err, dir)
}

fn assert_one_message(code: i32, err: &str, words: &[&str]) {
    assert_eq!(code, 1, "exit code for: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("RUST_BACKTRACE"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one line expected: {err}");
    for w in words {
        assert!(err.contains(w), "expected {w:?} in: {err}");
    }
}

#[test]
fn valid_input_passes() {
    let (code, err, _) = check("valid", CAMPAIGN, SCENE);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn unknown_key() {
    let c = CAMPAIGN.replace(
        "  receiver_area_m2: 0.1",
        "  receiver_area_m2: 0.1\n  reciever_gain: 3",
    );
    let (code, err, _) = check("unknown_key", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &[
            "campaign.yaml:10:",
            "instrument.reciever_gain",
            "unknown field",
        ],
    );
}

#[test]
fn wrong_type() {
    let c = CAMPAIGN.replace("pulse_energy_j: 0.001", "pulse_energy_j: high");
    let (code, err, _) = check("wrong_type", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &[
            "campaign.yaml:5:",
            "instrument.pulse_energy_j: expected a number, found \"high\"",
        ],
    );
}

#[test]
fn missing_campaign_file() {
    let (code, _, err) = lidarsim(&["check", "/nonexistent/campaign.yaml"]);
    assert_one_message(
        code,
        &err,
        &["/nonexistent/campaign.yaml", "does not exist"],
    );
    let (code, _, err) = lidarsim(&["run", "/nonexistent/campaign.yaml"]);
    assert_one_message(
        code,
        &err,
        &["/nonexistent/campaign.yaml", "does not exist"],
    );
}

#[test]
fn missing_scene_file() {
    let c = CAMPAIGN.replace("scene: scene.yaml", "scene: nowhere.yaml");
    let (code, err, _) = check("missing_scene", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &[
            "campaign.yaml:2:",
            "scene",
            "nowhere.yaml",
            "does not exist",
        ],
    );
}

#[test]
fn missing_mesh_file() {
    let s = format!("{SCENE}  - mesh: {{ file: meshes/tree.obj, material: soil }}\n");
    let (code, err, _) = check("missing_mesh", CAMPAIGN, &s);
    assert_one_message(
        code,
        &err,
        &[
            "scene.yaml:6:",
            "objects[1].mesh.file",
            "tree.obj",
            "does not exist",
        ],
    );
}

#[test]
fn negative_energy() {
    let c = CAMPAIGN.replace("pulse_energy_j: 0.001", "pulse_energy_j: -0.001");
    let (code, err, _) = check("negative_energy", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &[
            "campaign.yaml:5:",
            "instrument.pulse_energy_j",
            "positive",
            "-0.001",
        ],
    );
}

#[test]
fn nan_energy() {
    let c = CAMPAIGN.replace("pulse_energy_j: 0.001", "pulse_energy_j: .nan");
    let (code, err, _) = check("nan_energy", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &[
            "campaign.yaml:5:",
            "instrument.pulse_energy_j",
            "finite",
            "NaN",
        ],
    );
}

#[test]
fn wavelength_missing_from_material() {
    let s = SCENE.replace("{ 1064: 0.3 }", "{ 532: 0.1 }");
    let (code, err, _) = check("missing_wavelength", CAMPAIGN, &s);
    assert_one_message(
        code,
        &err,
        &["scene.yaml:3:", "materials.soil.reflectance", "1064"],
    );
}

#[test]
fn empty_mesh() {
    let dir = tmp("bad_empty_mesh_files");
    let obj = write(&dir, "empty.obj", "# no faces\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
    let s = format!(
        "{SCENE}  - mesh: {{ file: {}, material: soil }}\n",
        obj.display()
    );
    let (code, err, _) = check("empty_mesh", CAMPAIGN, &s);
    // the mesh file, and the scene key that names it
    assert_one_message(
        code,
        &err,
        &[
            "empty.obj",
            "no triangles",
            "scene.yaml:6: objects[1].mesh.file",
        ],
    );
}

/// A face of two vertices, which tobj drops without a word, is refused at its line.
#[test]
fn a_face_of_two_vertices() {
    let dir = tmp("bad_two_vertex_face_files");
    let obj = write(
        &dir,
        "short.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 # a line, not a face\n",
    );
    let s = format!(
        "{SCENE}  - mesh: {{ file: {}, material: soil }}\n",
        obj.display()
    );
    let (code, err, _) = check("two_vertex_face", CAMPAIGN, &s);
    assert_one_message(code, &err, &["short.obj:5", "2 vertices", "at least 3"]);
}

/// A vertex that is not a finite number of metres, or lies beyond 1000 km, is refused at its
/// line: in an OBJ, and in an ASCII PLY whose vertices come first (whose parser refuses a
/// "nan" itself; a binary PLY names the vertex by its index, having no lines).
#[test]
fn a_bad_vertex_is_named_by_its_line() {
    let dir = tmp("bad_vertex_line_files");
    let cases = [
        ("nan.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "nan.obj:2", "non-finite"),
        ("inf.obj", "# far\nv 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n", "inf.obj:4", "non-finite"),
        ("far.obj", "v 0 0 0\nv 2e6 0 0\nv 0 1 0\nf 1 2 3\n", "far.obj:2", "1000 km"),
        ("w.obj", "v 0 0 0\nv 1 0 0\nv 0 1 1 0\nf 1 2 3\n", "w.obj:3", "non-finite"),
        ("winf.obj", "v 0 0 0\nv 1 0 0 1\nv 0 1 1 inf\nf 1 2 3\n", "winf.obj:3", "non-finite"),
        ("wfar.obj", "v 0 0 0\nv 0 1 10 1e-6\nv 0 1 0\nf 1 2 3\n", "wfar.obj:2", "1000 km"),
        (
            "far.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 -3e6\n3 0 1 2\n",
            "far.ply:12",
            "1000 km",
        ),
        (
            "nan.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 nan\n3 0 1 2\n",
            "nan.ply:12",
            "cannot parse PLY",
        ),
    ];
    for (name, text, at, what) in cases {
        let mesh = write(&dir, name, text);
        let s = format!(
            "{SCENE}  - mesh: {{ file: {}, material: soil }}\n",
            mesh.display()
        );
        let (code, err, _) = check(&format!("bad_vertex_{name}"), CAMPAIGN, &s);
        assert_one_message(code, &err, &[at, what, "vertex"]);
    }
}

#[test]
fn degenerate_mesh() {
    let dir = tmp("bad_degenerate_mesh_files");
    let obj = write(
        &dir,
        "flat.obj",
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n",
    );
    let s = format!(
        "{SCENE}  - mesh: {{ file: {}, material: soil }}\n",
        obj.display()
    );
    let (code, err, _) = check("degenerate_mesh", CAMPAIGN, &s);
    assert_one_message(code, &err, &["flat.obj", "degenerate"]);
}

#[test]
fn instance_row_with_wrong_column_count() {
    let dir = tmp("bad_csv_files");
    write(&dir, "leaf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write(
        &dir,
        "trees.csv",
        "# x y z rotation scale\n1 2\n3, 4, 0\n5 6 0 10 1 9\n",
    );
    let s = format!(
        "{SCENE}  - mesh: {{ file: {}, material: soil, instances: {} }}\n",
        dir.join("leaf.obj").display(),
        dir.join("trees.csv").display()
    );
    let (code, err, _) = check("csv_columns", CAMPAIGN, &s);
    assert_one_message(
        code,
        &err,
        &[
            "trees.csv:4:",
            "columns",
            "6",
            "scene.yaml:6: objects[1].mesh.instances",
        ],
    );
}

#[test]
fn out_of_range_numbers() {
    for (from, to, key) in [
        (
            "edge_energy_fraction",
            "  edge_energy_fraction: 1.5\n",
            "instrument.edge_energy_fraction",
        ),
        (
            "receiver_area_m2: 0.1",
            "receiver_area_m2: 0",
            "instrument.receiver_area_m2",
        ),
        (
            "rays_per_pulse: 100",
            "rays_per_pulse: 0",
            "simulation.rays_per_pulse",
        ),
        // past these, ranges and times were infinite, or a kernel asked for gigabytes
        (
            "position: [5, 5, 100]",
            "position: [5, 5, 1e300]",
            "platform.pulses[0].position: must be a coordinate in metres within 100,000 km, found 1e300",
        ),
        (
            "receiver_area_m2: 0.1",
            "receiver_area_m2: 0.1\n  detector_response_fwhm_ns: 1e300",
            "instrument.detector_response_fwhm_ns",
        ),
        // a waveform's samples past what GEDI's 16-bit rx_sample_count holds, given or as
        // the scene's ranges and the pulse's length make them
        (
            "  pulse_fwhm_ns: 2",
            "  pulse_fwhm_ns: 20\n  bin_ns: 0.001",
            "instrument.bin_ns: the scene's ranges make gates of",
        ),
        (
            "receiver_area_m2: 0.1",
            "receiver_area_m2: 0.1\n  range_gate: { start_ns: 0, bins: 70000 }",
            "instrument.range_gate.bins: a waveform instrument's gate holds at most 65535 bins",
        ),
    ] {
        let c = if from == "edge_energy_fraction" {
            CAMPAIGN.replace(
                "  fov_half_angle_mrad: 2\n",
                &format!("  fov_half_angle_mrad: 2\n{to}"),
            )
        } else {
            CAMPAIGN.replace(from, to)
        };
        let (code, err, _) = check("range", &c, SCENE);
        assert_one_message(code, &err, &["campaign.yaml:", key]);
    }
}

#[test]
fn bad_yaml_syntax() {
    let c = CAMPAIGN.replace("kind: static", "kind: [static");
    let (code, err, _) = check("syntax", &c, SCENE);
    assert_one_message(code, &err, &["campaign.yaml:"]);
    // an unclosed list is the text's fault, not a wrong type at its key; a tab in the
    // indentation says so once, without naming the key before it; an empty enum is a null
    for (from, to, words) in [
        (
            "scene: scene.yaml",
            "scene: [scene.yaml",
            &["campaign.yaml:3:", "(YAML syntax)"][..],
        ),
        (
            "  receiver_area_m2: 0.1",
            "\treceiver_area_m2: 0.1",
            &[
                "campaign.yaml:9:",
                "a tab character where YAML expects indentation",
            ][..],
        ),
        (
            "  kind: static",
            "\tkind: static",
            &[
                "campaign.yaml:11:",
                "a tab character where YAML expects indentation",
            ][..],
        ),
        (
            "kind: static",
            "kind:",
            &[
                "campaign.yaml:11:",
                "platform.kind: found nothing, expected one of",
            ][..],
        ),
        (
            "kind: static",
            "kind: ~",
            &[
                "campaign.yaml:11:",
                "platform.kind: found nothing, expected one of",
            ][..],
        ),
    ] {
        let c = CAMPAIGN.replace(from, to);
        let (code, err, _) = check("syntax_more", &c, SCENE);
        assert_one_message(code, &err, words);
        assert!(!err.contains(" at line "), "{err}");
    }
}

/// A campaign name that cannot name a run folder (YAML's null, a line break, a slash) is
/// refused at `name`.
#[test]
fn names_that_cannot_name_a_folder() {
    for name in ["~", "null", "\"a\\nb\"", "a/b", "\"\\ttab\""] {
        let c = CAMPAIGN.replace("name: bad", &format!("name: {name}"));
        let (code, err, _) = check("bad_name", &c, SCENE);
        assert_one_message(
            code,
            &err,
            &["campaign.yaml:1:", "name: must be a non-empty name"],
        );
    }
}

/// A repeated scene's period far smaller than its geometry (down to 1e-300 m, whose count of
/// periods no integer holds) is refused at `period`.
#[test]
fn a_period_too_small_for_its_geometry() {
    for side in ["1e-6", "1e-300"] {
        let s = format!("{SCENE}repeat: true\nperiod: [[0, 0], [{side}, {side}]]\n");
        let (code, err, _) = check("tiny_period", CAMPAIGN, &s);
        assert_one_message(code, &err, &["scene.yaml:7:", "period", "1024 periods"]);
    }
}

/// Brackets nested 100,000 deep (in the campaign and in its scene) are refused at the bracket
/// past the limit, under the key of their line, before the YAML parser's slow descent.
#[test]
fn deeply_nested_brackets() {
    let deep = "[".repeat(100_000);
    let c = CAMPAIGN.replace("kind: static", &format!("kind: {deep}"));
    let (code, err, _) = check("deep", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &["campaign.yaml:11:1009", "kind", "nested more than 1000"],
    );
    // an apostrophe inside a plain value, or an escaped quote in a quoted one, opens no
    // quote that would hide the brackets after it
    for name in ["it's", "\"a\\\"b\""] {
        let c = c.replace("name: bad", &format!("name: {name}"));
        let (code, err, _) = check("deep_apostrophe", &c, SCENE);
        assert_one_message(
            code,
            &err,
            &["campaign.yaml:11:1009", "nested more than 1000"],
        );
    }
    let s = SCENE.replace("z: 0,", &format!("z: 0, tag: {deep}"));
    let (code, err, _) = check("deep_scene", CAMPAIGN, &s);
    assert_one_message(code, &err, &["scene.yaml:5:", "nested more than 1000"]);
    // quoted and commented brackets are not nesting
    let c = format!("{CAMPAIGN}# {deep}\n");
    let s = SCENE.replace("name: s", &format!("name: \"{deep}\" # {deep}"));
    let (code, err, _) = check("deep_quoted", &c, &s);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn sun_selection_probability_without_fixed_selection() {
    let c = CAMPAIGN.replace("  receiver_area_m2: 0.1\n", "  receiver_area_m2: 0.1\n  bandwidth_nm: 1\n")
        + "sun:\n  zenith_deg: 30\n  azimuth_deg: 0\n  irradiance_w_m2_um: 600\n  selection: power\n  selection_probability: 0.3\n";
    let (code, err, _) = check("sun_selection", &c, SCENE);
    assert_one_message(
        code,
        &err,
        &["campaign.yaml:22:", "sun.selection_probability", "fixed"],
    );
    let c = c.replace("selection: power", "selection: sometimes");
    let (code, err, _) = check("sun_selection_kind", &c, SCENE);
    assert_one_message(code, &err, &["campaign.yaml:21:", "sun.selection"]);
}

/// `sun.share` outside (0, 1], or not a number, is refused at its line.
#[test]
fn sun_share_out_of_range() {
    let base = CAMPAIGN.replace(
        "  receiver_area_m2: 0.1\n",
        "  receiver_area_m2: 0.1\n  bandwidth_nm: 1\n",
    )
        + "sun:\n  zenith_deg: 30\n  azimuth_deg: 0\n  irradiance_w_m2_um: 600\n  share: SHARE\n";
    for (k, share) in ["0", "1.5", "-0.25", ".nan", "half"]
        .into_iter()
        .enumerate()
    {
        let c = base.replace("SHARE", share);
        let (code, err, _) = check(&format!("sun_share_{k}"), &c, SCENE);
        assert_one_message(code, &err, &["campaign.yaml:", "sun.share"]);
    }
}

/// A swept value the campaign rejects is reported at its entry under `sweep:` (line and
/// key), before any combination runs.
#[test]
fn bad_sweep_value_is_located_at_its_sweep_entry() {
    let dir = tmp("bad_sweep");
    write(&dir, "scene.yaml", SCENE);
    let text = format!("{CAMPAIGN}sweep:\n  instrument.pulse_energy_j: [0.001, -2]\n");
    let path = write(&dir, "campaign.yaml", &text);
    let out = dir.join("run");
    let (code, _out, err) = lidarsim(&[
        "run",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let line = text.lines().count();
    assert_one_message(
        code,
        &err,
        &[&format!(
            "campaign.yaml:{line}:3: sweep.instrument.pulse_energy_j: value -2"
        )],
    );
    assert!(
        !out.join("pulse_energy_j=0.001").exists(),
        "a combination ran before the check"
    );
    // `lidarsim check` finds it too, where it used to say ok
    let (code, _out, err) = lidarsim(&["check", path.to_str().unwrap()]);
    assert_one_message(
        code,
        &err,
        &[&format!(
            "campaign.yaml:{line}:3: sweep.instrument.pulse_energy_j: value -2"
        )],
    );
    // and with good values it lists the runs and counts all their rays
    let good = format!("{CAMPAIGN}sweep:\n  simulation.rays_per_pulse: [100, 300]\n");
    let path = write(&dir, "campaign.yaml", &good);
    let (code, out, err) = lidarsim(&["check", path.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("sweep: 2 runs (rays_per_pulse=100, rays_per_pulse=300)"),
        "{out}"
    );
    assert!(out.contains("(4.000e2 rays at"), "{out}");
}

/// Coordinates beyond ±1000 km, an instance scale beyond 10^4 and heights beyond ±1000 km are
/// typos or unit mistakes: each is one located message, never the BVH builder's panic (found
/// by the fuzz test: `99999999999999999999` as a scale, `1e308` as a z, a height of 1e38).
#[test]
fn far_coordinates_and_huge_scales() {
    let dir = tmp("bad_far");
    write(&dir, "leaf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write(&dir, "far.obj", "v 0 0 0\nv 1 0 0\nv 0 1e9 0\nf 1 2 3\n");
    write(
        &dir,
        "scale.csv",
        "1 2 0 0 1\n3, 4, 0, 90, 99999999999999999999\n",
    );
    write(&dir, "z.csv", "# x y z\n1 2 1e308\n");
    write(
        &dir,
        "dem.csv",
        "1,2,3\n1,99999999999999999999999999999999999999,3\n",
    );
    let mesh = |obj: &str, table: &str| {
        format!(
            "{SCENE}  - mesh: {{ file: {}, material: soil, instances: {} }}\n",
            dir.join(obj).display(),
            dir.join(table).display()
        )
    };
    let (code, err, _) = check("far_scale", CAMPAIGN, &mesh("leaf.obj", "scale.csv"));
    assert_one_message(code, &err, &["scale.csv:2:", "column 5 (scale)"]);
    let (code, err, _) = check("far_z", CAMPAIGN, &mesh("leaf.obj", "z.csv"));
    assert_one_message(code, &err, &["z.csv:2:", "column 3 (z)", "1000 km"]);
    let far = format!(
        "{SCENE}  - mesh: {{ file: {}, material: soil }}\n",
        dir.join("far.obj").display()
    );
    let (code, err, _) = check("far_vertex", CAMPAIGN, &far);
    assert_one_message(code, &err, &["far.obj", "vertex", "1000 km"]);
    let dem = format!(
        "{SCENE}  - heightfield: {{ file: {}, cell_m: 1, material: soil }}\n",
        dir.join("dem.csv").display()
    );
    let (code, err, _) = check("far_height", CAMPAIGN, &dem);
    assert_one_message(code, &err, &["dem.csv:2:", "column 2", "1000 km"]);
}

/// A frame whose CRS cannot place the scene's metres, or whose origin is no number, or a
/// points format that is neither las nor laz: one message at the line of the key.
#[test]
fn bad_frames_and_points_formats() {
    for (text, line, words) in [
        (
            "frame: { crs: EPSG:4326, origin: [0, 0, 0] }\n",
            16,
            &["frame.crs", "not a projected CRS"][..],
        ),
        (
            "frame: { crs: EPSG:2227, origin: [0, 0, 0] }\n",
            16,
            &["frame.crs", "not in metres"][..],
        ),
        (
            "frame: { crs: UTM31N, origin: [0, 0, 0] }\n",
            16,
            &["frame.crs", "EPSG:NNNN"][..],
        ),
        (
            "frame:\n  crs: EPSG:32631\n  origin: [500000, .nan, 0]\n",
            18,
            &["frame.origin[1]", "finite"][..],
        ),
        ("frame: { crs: EPSG:32631 }\n", 16, &["frame", "origin"][..]),
        // axes pointing west and south would mirror the scene
        (
            "frame: { crs: EPSG:2046, origin: [0, 0, 0] }\n",
            16,
            &["frame.crs", "west and south"][..],
        ),
        // Krovak has no inverse to latitude and longitude here, which this waveform
        // instrument's mission files hold: refused before any pulse
        (
            "frame: { crs: EPSG:5514, origin: [-700000, -1100000, 0] }\n",
            16,
            &["frame.crs", "no inverse projection", "mission files"][..],
        ),
        (
            "products: { points: true, points_format: copc }\n",
            16,
            &["products.points_format", "copc"][..],
        ),
    ] {
        let (code, err, _) = check("frame", &format!("{CAMPAIGN}{text}"), SCENE);
        let at = format!("campaign.yaml:{line}");
        let mut expect = vec![at.as_str()];
        expect.extend_from_slice(words);
        assert_one_message(code, &err, &expect);
    }
}

/// Bad detector and digitiser settings: one message at the line of the key, saying what is
/// allowed. The instrument block's added line is line 10.
#[test]
fn bad_noise_and_digitisers() {
    for (name, text, key, words) in [
        (
            "bits0",
            "  digitiser: { gain: 2, bits: 0 }\n",
            "instrument.digitiser.bits",
            &["between 1 and 24"][..],
        ),
        (
            "bits30",
            "  digitiser: { gain: 2, bits: 30 }\n",
            "instrument.digitiser.bits",
            &["between 1 and 24"][..],
        ),
        (
            "bits-1",
            "  digitiser: { gain: 2, bits: -1 }\n",
            "instrument.digitiser.bits",
            &["between 1 and 24, found -1"][..],
        ),
        (
            "gain",
            "  digitiser: { gain: -2, bits: 8 }\n",
            "instrument.digitiser.gain",
            &["positive"][..],
        ),
        (
            "sat",
            "  digitiser: { gain: 2, bits: 8, saturation: 256 }\n",
            "instrument.digitiser.saturation",
            &["255"][..],
        ),
        ("nogain", "  digitiser: { bits: 8 }\n", "gain", &[][..]),
        (
            "extra",
            "  digitiser: { gain: 2, bits: 8, dither: 1 }\n",
            "dither",
            &[][..],
        ),
        (
            "sd",
            "  noise: { electronic_sd_photons: -1 }\n",
            "instrument.noise.electronic_sd_photons",
            &[][..],
        ),
        (
            "offset",
            "  receiver_offset_m: [0, 5000, 0]\n",
            "instrument.receiver_offset_m[1]",
            &["between -1000 and 1000"][..],
        ),
        (
            "resp",
            "  detector_response_fwhm_ns: .nan\n",
            "instrument.detector_response_fwhm_ns",
            &["finite"][..],
        ),
    ] {
        let text = CAMPAIGN.replace(
            "  receiver_area_m2: 0.1\n",
            &format!("  receiver_area_m2: 0.1\n{text}"),
        );
        let (code, err, _) = check(&format!("detector_{name}"), &text, SCENE);
        let mut expect = vec!["campaign.yaml:10", key];
        expect.extend_from_slice(words);
        assert_one_message(code, &err, &expect);
    }
}

/// An atmosphere layer without an optical depth at the campaign's wavelength, or with a
/// scale height or optical depth that is no physical value: one message at the layer's line.
#[test]
fn bad_atmospheres() {
    for (name, layer, key, words) in [
        (
            "missing",
            "{ scale_height_m: 8000, optical_depth: { 532: 0.1 } }",
            "atmosphere.layers[0].optical_depth",
            &["no value for 1064 nm", "532"][..],
        ),
        (
            "height",
            "{ scale_height_m: 0, optical_depth: 0.1 }",
            "atmosphere.layers[0].scale_height_m",
            &["positive"][..],
        ),
        (
            "negative",
            "{ scale_height_m: 8000, optical_depth: -0.1 }",
            "atmosphere.layers[0].optical_depth",
            &[][..],
        ),
        (
            "unknown",
            "{ scale_height_m: 8000, optical_depth: 0.1, angstrom: 1.3 }",
            "angstrom",
            &[][..],
        ),
    ] {
        let text = format!("{CAMPAIGN}atmosphere:\n  layers:\n    - {layer}\n");
        let (code, err, _) = check(&format!("atmosphere_{name}"), &text, SCENE);
        let mut expect = vec!["campaign.yaml:18", key];
        expect.extend_from_slice(words);
        assert_one_message(code, &err, &expect);
    }
}

/// Valid but likely unmeant: the sun with forward tracing is accepted with a warning that
/// says why and what to use instead; with bdpt there is none.
#[test]
fn a_sun_with_forward_tracing_is_warned_about() {
    let sun = "sun: { zenith_deg: 40, azimuth_deg: 0, irradiance_w_m2_um: 640 }\n";
    for (method, warned) in [("forward", true), ("bdpt", false)] {
        let dir = tmp(&format!("warn_{method}"));
        write(&dir, "scene.yaml", SCENE);
        let text = CAMPAIGN
            .replace(
                "simulation: { rays_per_pulse: 100 }",
                &format!("simulation: {{ method: {method}, rays_per_pulse: 100 }}"),
            )
            .replace(
                "  receiver_area_m2: 0.1\n",
                "  receiver_area_m2: 0.1\n  bandwidth_nm: 1\n",
            )
            + sun;
        let path = write(&dir, "campaign.yaml", &text);
        let (code, out, err) = lidarsim(&["check", path.to_str().unwrap()]);
        assert_eq!(code, 0, "{err}");
        assert_eq!(
            out.contains("warning: with simulation.method forward the sun"),
            warned,
            "{out}"
        );
        if warned {
            assert!(out.contains("bdpt or backward"), "{out}");
        }
    }
}

/// A run that could not fit in any machine's memory is refused before it starts, at the key
/// that sizes it, by `check` and by `run`: gates of 10^15 bins (bins of 10^-12 ns), DSM grids
/// of 10^16 cells (0.1 µm cells) and gates made of a 10^9 ns pulse's tails, where the
/// allocations used to abort the process with no message (the DSM's only after the
/// simulation). More threads than can start are refused
/// too: 100,000 ended the process in a panic as their stacks failed to map.
#[test]
fn runs_that_cannot_fit_in_memory() {
    let dsm = CAMPAIGN
        .replace("instrument:\n", "instrument:\n  kind: discrete_return\n")
        .replace(
            "simulation: { rays_per_pulse: 100 }\n",
            "simulation: { rays_per_pulse: 100 }\nproducts: { points: true, dsm: { resolution_m: 1.0e-7 } }\n",
        );
    for (name, campaign, key) in [
        (
            "gate",
            CAMPAIGN.replace(
                "  receiver_area_m2: 0.1\n",
                "  receiver_area_m2: 0.1\n  bin_ns: 1.0e-12\n",
            ),
            "instrument.bin_ns",
        ),
        ("dsm", dsm, "products.dsm.resolution_m"),
        (
            "pulse",
            CAMPAIGN.replace("pulse_fwhm_ns: 2", "pulse_fwhm_ns: 1.0e9"),
            "instrument.pulse_fwhm_ns",
        ),
    ] {
        let (code, err, dir) = check(&format!("memory_{name}"), &campaign, SCENE);
        assert_one_message(code, &err, &["campaign.yaml:", key, "memory"]);
        let (code, err) = run(&dir, &[]);
        // the run logs its plan stage first; its error is still one line
        assert!(!err.contains("panicked"), "{err}");
        let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
        assert_eq!(errors.len(), 1, "{err}");
        assert_one_message(code, errors[0], &["campaign.yaml:", key]);
    }
    let dir = tmp("bad_threads");
    write(&dir, "scene.yaml", SCENE);
    write(&dir, "campaign.yaml", CAMPAIGN);
    let (code, err) = run(&dir, &["--threads", "100000"]);
    assert_one_message(code, &err, &["--threads", "4096"]);
    // and a bench canopy of 10^11 crowns, which grew past 5 GB in a minute
    let out = dir.join("bench");
    let (code, _, err) = lidarsim(&[
        "bench",
        "--no-campaigns",
        "--trees",
        "100000000000",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("--trees") && !err.contains("panicked"),
        "{err}"
    );
}

/// `lidarsim run DIR/campaign.yaml --out DIR/out ARGS`: its exit code and stderr.
fn run(dir: &std::path::Path, args: &[&str]) -> (i32, String) {
    let (path, out) = (dir.join("campaign.yaml"), dir.join("out"));
    let mut all = vec![
        "run",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    all.extend(args);
    let (code, _, err) = lidarsim(&all);
    (code, err)
}

/// Values that would name a folder outside the run's, exhaust memory or mean nothing are
/// refused at their key: a name of `..`, a detector's dark counts beyond any detector's, a
/// sun brighter than any, a pulse of a kilojoule and more, no returns kept.
#[test]
fn values_beyond_any_instrument_are_refused() {
    let cases = [
        (
            "name_dotdot",
            CAMPAIGN.replace("name: bad", "name: .."),
            "name",
        ),
        (
            "name_dot",
            CAMPAIGN.replace("name: bad", "name: '.'"),
            "name",
        ),
        (
            "name_long",
            CAMPAIGN.replace("name: bad", &format!("name: {}", "n".repeat(256))),
            "name",
        ),
        (
            "dark",
            CAMPAIGN.replace(
                "  receiver_area_m2: 0.1\n",
                "  receiver_area_m2: 0.1\n  kind: photon_counting\n  dark_count_hz: 1e300\n",
            ),
            "instrument.dark_count_hz",
        ),
        // a noise past f32's range filled the record with infinities
        (
            "electronic",
            CAMPAIGN.replace(
                "  receiver_area_m2: 0.1\n",
                "  receiver_area_m2: 0.1\n  noise: { electronic_sd_photons: 1e39 }\n",
            ),
            "instrument.noise.electronic_sd_photons",
        ),
        (
            "energy",
            CAMPAIGN.replace("pulse_energy_j: 0.001", "pulse_energy_j: 1e308"),
            "instrument.pulse_energy_j",
        ),
        (
            "bin",
            CAMPAIGN.replace(
                "  pulse_fwhm_ns: 2\n",
                "  pulse_fwhm_ns: 2\n  bin_ns: 1e300\n",
            ),
            "instrument.bin_ns",
        ),
        (
            "returns",
            CAMPAIGN.replace(
                "  receiver_area_m2: 0.1\n",
                "  receiver_area_m2: 0.1\n  kind: discrete_return\n  max_returns: 0\n",
            ),
            "instrument.max_returns",
        ),
        (
            "sun",
            format!(
                "{CAMPAIGN}sun: {{ zenith_deg: 30, azimuth_deg: 0, irradiance_w_m2_um: 1e25 }}\n"
            )
            .replace(
                "  pulse_fwhm_ns: 2\n",
                "  pulse_fwhm_ns: 2\n  bandwidth_nm: 1\n",
            ),
            "sun.irradiance_w_m2_um",
        ),
        (
            "gps_before",
            CAMPAIGN.replace("  kind: static\n", "  kind: static\n  gps_start_s: -5\n"),
            "platform.gps_start_s",
        ),
        (
            "gps_far",
            CAMPAIGN.replace("  kind: static\n", "  kind: static\n  gps_start_s: 1e20\n"),
            "platform.gps_start_s",
        ),
    ];
    for (name, text, key) in cases {
        let (code, err, _) = check(name, &text, SCENE);
        assert_one_message(code, &err, &["campaign.yaml:", key]);
    }
}

/// A sweep whose combinations run into the millions, that lists a value twice (two runs, one
/// folder) or that sweeps the scene (its runs share one) is refused at its key, at once.
#[test]
fn sweeps_that_cannot_run_are_refused() {
    let ten = "[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]";
    let huge = format!(
        "{CAMPAIGN}sweep:\n  seed: {ten}\n  instrument.pulse_energy_j: [0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.007, 0.008, 0.009, 0.01]\n  instrument.pulse_fwhm_ns: {ten}\n  instrument.receiver_area_m2: {ten}\n  instrument.fov_half_angle_mrad: {ten}\n  simulation.rays_per_pulse: {ten}\n"
    );
    let (code, err, _) = check("sweep_huge", &huge, SCENE);
    assert_one_message(code, &err, &["campaign.yaml:", "sweep", "combinations"]);
    let twice = format!("{CAMPAIGN}sweep:\n  instrument.pulse_energy_j: [0.001, 0.002, 0.001]\n");
    let (code, err, _) = check("sweep_twice", &twice, SCENE);
    assert_one_message(
        code,
        &err,
        &["sweep.instrument.pulse_energy_j", "listed twice"],
    );
    let scene = format!("{CAMPAIGN}sweep:\n  scene: [scene.yaml, other.yaml]\n");
    let (code, err, _) = check("sweep_scene", &scene, SCENE);
    assert_one_message(code, &err, &["sweep.scene", "cannot be swept"]);
    // a key the campaign does not know is named at its entry, as a bad value is; the sweep
    // cannot sweep itself, nor a key with no name
    for (entry, words) in [
        (
            "platform.nope: [1, 2]",
            &[
                "campaign.yaml:",
                "sweep.platform.nope",
                "unknown field `nope`",
            ][..],
        ),
        ("sweep: [1]", &["sweep.sweep", "its own"]),
        ("\"\": [1]", &["campaign.yaml:", "a key is empty"]),
        // a combination whose run no memory holds is refused before any runs, at its value
        (
            "instrument.bin_ns: [1, 1e-9]",
            &[
                "campaign.yaml:",
                "sweep.instrument.bin_ns",
                "value 1e-9",
                "in memory",
            ],
        ),
        // two values that would name one folder; a mapping's value on the message's one line
        (
            "name: ['a b', 'a-b']",
            &["sweep.name", "would name one folder (a-b)"],
        ),
        // a band the scene's materials do not give, before any run
        (
            "wavelength_nm: [1064, 1550]",
            &[
                "campaign.yaml:",
                "sweep.wavelength_nm",
                "value 1550",
                "no value for 1550 nm",
            ][..],
        ),
        // a path's separator too (two trajectory files, dir/t.csv and dir-t.csv)
        (
            "name: ['a/b', 'a-b']",
            &["sweep.name", "would name one folder (a-b)"],
        ),
        (
            "instrument.range_gate: [{ start_ns: 0, bins: 20000000000 }]",
            &["sweep.instrument.range_gate", "value {\"start_ns\":0,\"bins\":20000000000}: expected a whole number from 0 to 4294967295"],
        ),
    ] {
        let text = format!("{CAMPAIGN}sweep:\n  {entry}\n");
        let (code, err, _) = check("sweep_key", &text, SCENE);
        assert_one_message(code, &err, words);
    }
    // no key at all; a folder name past what a file system holds
    let (code, err, _) = check("sweep_empty", &format!("{CAMPAIGN}sweep: {{}}\n"), SCENE);
    assert_one_message(code, &err, &["campaign.yaml:", "sweep", "no key to sweep"]);
    // (a name of 252 bytes is a name, but its folder `name=...` is 257)
    let long = format!("{CAMPAIGN}sweep:\n  name: ['{}', b]\n", "n".repeat(252));
    let (code, err, _) = check("sweep_long", &long, SCENE);
    assert_one_message(code, &err, &["campaign.yaml:", "more than 255"]);
}

/// A byte-order mark before the text is no part of it; a folder given as the campaign is
/// named as one; a bad flag is one line, not clap's usage.
#[test]
fn byte_order_marks_folders_and_bad_flags() {
    let (code, err, dir) = check("bom", &format!("\u{feff}{CAMPAIGN}"), SCENE);
    assert_eq!(code, 0, "{err}");
    let (code, _out, err) = lidarsim(&["check", dir.to_str().unwrap()]);
    assert_one_message(code, &err, &["is a folder, not a file"]);
    let camp = dir.join("campaign.yaml");
    for (flags, word) in [
        (&["--threads", "two"][..], "two"),
        (&["--threads", "-1"], "-1"),
        (&["--stages", "plan,bake"], "bake"),
        (&["--bogus"], "--bogus"),
    ] {
        let mut args = vec!["run", camp.to_str().unwrap()];
        args.extend_from_slice(flags);
        let (code, _out, err) = lidarsim(&args);
        assert_one_message(code, &err, &[word]);
    }
}

/// A standard output that cannot be written (full, or a pipe closed by `head`) ends a command
/// whose output is its report with exit code 1 and one message, never a panic; a run, whose
/// files are its result, still writes them and exits 0 when its standard error is full.
#[test]
fn full_standard_output_or_error() {
    let full = std::path::Path::new("/dev/full");
    if !full.exists() {
        eprintln!("SKIPPED: this system has no /dev/full to write to");
        return;
    }
    let dir = tmp("bad_full_output");
    write(&dir, "scene.yaml", SCENE);
    let campaign = write(&dir, "campaign.yaml", CAMPAIGN);
    let to_full = || std::fs::OpenOptions::new().write(true).open(full).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lidarsim"))
        .args(["check", campaign.to_str().unwrap()])
        .stdout(to_full())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_one_message(
        out.status.code().unwrap_or(-1),
        &err,
        &["cannot write to standard output"],
    );
    let run = dir.join("run");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lidarsim"))
        .args([
            "run",
            campaign.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ])
        .stderr(to_full())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    assert!(run.join("waveforms/part-00000.parquet").exists());
    assert!(!run.join("run.lock").exists());
}

/// Flags that used to fail only after minutes of work, or to fail at all: a bench's campaign
/// folder without its files and a RAMI scene named but absent (found after the ray
/// experiments, or skipped without a word), a forest stand of 100 km with two trees (whose
/// placement grid asked for 107 GB and aborted) and more trees than can stand apart on it
/// (which searched for minutes).
#[test]
fn flags_found_wrong_at_once() {
    let dir = tmp("bad_flags_early");
    let empty = dir.join("no_campaigns");
    std::fs::create_dir_all(&empty).unwrap();
    let out = dir.join("bench");
    let report = dir.join("report.md");
    let bench = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            "--out",
            out.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
            "--reference-rays",
            "1000",
        ];
        args.extend(extra);
        lidarsim(&args)
    };
    let (code, _, err) = bench(&["--campaigns", empty.to_str().unwrap()]);
    assert_one_message(code, &err, &["--campaigns", "quick.yaml"]);
    let missing = dir.join("nowhere/rami_wco.yaml");
    let (code, _, err) = bench(&["--no-campaigns", "--rami", missing.to_str().unwrap()]);
    assert_one_message(code, &err, &["--rami", "not found"]);
    assert!(!report.exists(), "the bench ran");

    let stand = dir.join("stand");
    let (code, _, err) = lidarsim(&[
        "scene",
        "generate",
        "forest",
        "--size",
        "100000",
        "--trees",
        "2",
        "--templates",
        "1",
        "--leaves",
        "50",
        "--out",
        stand.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stand.join("forest.yaml").is_file());
    let crowded = dir.join("crowded");
    let (code, _, err) = lidarsim(&[
        "scene",
        "generate",
        "forest",
        "--size",
        "5",
        "--trees",
        "1000000",
        "--templates",
        "1",
        "--leaves",
        "1",
        "--out",
        crowded.to_str().unwrap(),
    ]);
    assert_one_message(code, &err, &["1000000 trees", "no more than"]);
    // a town of 5·10^6 buildings, which searched for minutes before giving up
    let (code, _, err) = lidarsim(&[
        "scene",
        "generate",
        "town",
        "--size",
        "100000",
        "--out",
        crowded.to_str().unwrap(),
    ]);
    assert_one_message(code, &err, &["--size", "buildings", "2000 ha"]);
}

/// A table or report written to a symbolic link replaces the file it names and keeps the
/// link; to a device it is written as it is (`--csv /dev/stdout`), where it used to replace
/// the device with a file.
#[test]
fn outputs_written_through_links_and_devices() {
    let dir = tmp("bad_write_through");
    write(&dir, "scene.yaml", SCENE);
    let campaign = write(&dir, "campaign.yaml", CAMPAIGN);
    let run_dir = dir.join("run");
    let (code, _, err) = lidarsim(&[
        "run",
        campaign.to_str().unwrap(),
        "--out",
        run_dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let target = write(&dir, "target.csv", "old\n");
    let link = dir.join("link.csv");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let (code, _, err) = lidarsim(&[
        "compare",
        run_dir.to_str().unwrap(),
        "--csv",
        link.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    let table = std::fs::read_to_string(&target).unwrap();
    assert!(table.starts_with("run,") || table.contains(','), "{table}");
    assert_ne!(table, "old\n");
    let (code, _, err) = lidarsim(&["compare", run_dir.to_str().unwrap(), "--csv", "/dev/null"]);
    assert_eq!(code, 0, "{err}");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
}
