//! Several bands in one pass (campaign.md, `wavelength_nm: [..]`): every path traced once with
//! one throughput per band. Each band must equal the closed forms and a single-band run of
//! its wavelength within its standard error, and the tables gain a `wavelength_nm` column.

mod common;
use common::*;
use lidarsim::waveform::Waveform;

const BANDS: [f64; 3] = [532.0, 1064.0, 1550.0];
const BANDS_YAML: &str = "wavelength_nm: [532, 1064, 1550]";

/// Photon energy hν at `nm`, J.
fn hv(nm: f64) -> f64 {
    6.626_070_15e-34 * C / (nm * 1e-9)
}

/// A campaign text (written for 1064 nm) turned into a run of `bands`.
fn with_bands(text: &str, bands: &str) -> String {
    assert!(text.contains("wavelength_nm: 1064\n"));
    text.replace("wavelength_nm: 1064\n", &format!("{bands}\n"))
}

/// The rows of one pulse, one per band in the campaign's order, each labelled.
fn rows_by_band(rows: &[Waveform], pulse: u64) -> Vec<&Waveform> {
    let mine: Vec<&Waveform> = rows.iter().filter(|w| w.pulse_id == pulse).collect();
    assert_eq!(mine.len(), BANDS.len(), "one row per band");
    for (w, nm) in mine.iter().zip(BANDS) {
        assert_eq!(w.wavelength_nm, Some(nm));
    }
    mine
}

/// A plane of reflectance `rho` at 532, 1064 and 1550 nm, `half` metres each way.
fn spectral_plane(dir: &std::path::Path, rho: [f64; 3], half: f64) -> std::path::PathBuf {
    write(
        dir,
        "plane.yaml",
        &format!(
            "name: p\nmaterials:\n  soil: {{ reflectance: {{ 532: {}, 1064: {}, 1550: {} }} }}\nobjects:\n  - plane: {{ z: 0, extent: [[{}, {}], [{half}, {half}]], material: soil }}\n",
            rho[0], rho[1], rho[2], -half, -half
        ),
    )
}

/// `plane.yaml` in `dir`: soil of reflectance 0.1 at 532 nm and 0.4 at 1064 nm.
fn two_band_plane(dir: &std::path::Path) {
    write(
        dir,
        "plane.yaml",
        "name: p\nmaterials:\n  soil: { reflectance: { 532: 0.1, 1064: 0.4 } }\nobjects:\n  - plane: { z: 0, extent: [[-50, -50], [50, 50]], material: soil }\n",
    );
}

/// The first record batch of a Parquet file, read by the parquet crate's reader.
fn first_batch(path: &std::path::Path) -> arrow_array::RecordBatch {
    let file = std::fs::File::open(path).unwrap();
    parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
}

/// Closed form 1 with the atmosphere, per band: a nadir pulse from 419 km over a plane whose
/// reflectance differs by band, through an atmosphere whose optical depth does, gives
/// Q_1(ρ_b) e^(-2 τ_b) in each band within 1 % (3 SE under 1 %), all of it in the bin of 2H/c,
/// and laser photons of that band's photon energy.
#[test]
fn plane_through_the_atmosphere_holds_in_every_band() {
    let dir = tmp("bands_plane");
    let rho = [0.1, 0.45, 0.3];
    let tau: [[f64; 3]; 2] = [[0.12, 0.008, 0.003], [0.20, 0.10, 0.06]];
    let scene = spectral_plane(&dir, rho, 400.0);
    let inst = Inst {
        fp_mrad: 0.03,
        fov_mrad: 0.3,
        area: 0.5,
        energy: 0.0105,
        ..Inst::default()
    };
    let h = 419_000.0;
    let text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, h],
        [0.0, 0.0, -1.0],
        "forward",
        1_000_000,
        3,
    );
    let atmosphere = format!(
        "atmosphere:\n  layers:\n    - {{ scale_height_m: 8000, optical_depth: {{ 532: {}, 1064: {}, 1550: {} }} }}\n    - {{ scale_height_m: 1500, optical_depth: {{ 532: {}, 1064: {}, 1550: {} }} }}\n",
        tau[0][0], tau[0][1], tau[0][2], tau[1][0], tau[1][1], tau[1][2]
    );
    let rows = run(
        &dir,
        &format!("{}{atmosphere}", with_bands(&text, BANDS_YAML)),
        None,
    );
    assert_eq!(rows.len(), 3);
    for (b, w) in rows_by_band(&rows, 0).into_iter().enumerate() {
        let column: f64 = [8000.0, 1500.0]
            .iter()
            .zip(&tau)
            .map(|(&hs, t)| t[b] * (1.0 - (-h / hs).exp()))
            .sum();
        let expect = plane_energy(&inst, rho[b], h) * (-2.0 * column).exp();
        let (got, se) = (w.received_energy_j, w.received_energy_se_j / expect);
        let rel = got / expect - 1.0;
        println!(
            "{} nm: got {got:.5e} expect {expect:.5e} rel {rel:+.4} se {se:.4}",
            BANDS[b]
        );
        assert!(
            3.0 * se < 0.01,
            "standard error {se} too large for a 1% test"
        );
        assert!(rel.abs() < 0.01, "{} nm: relative error {rel}", BANDS[b]);
        assert!(w.order_energy_j[1..].iter().all(|&e| e == 0.0));
        let bin = ((2.0 * h / C - w.t0_ns * 1e-9) / (w.bin_ns as f64 * 1e-9)).floor() as usize;
        let total: f64 = w.impulse_energy_j.iter().map(|&e| e as f64).sum();
        assert!(w.impulse_energy_j[bin] as f64 / total > 1.0 - 1e-6);
        let photons: f64 = w.laser_photons.iter().map(|&p| p as f64).sum();
        assert!(
            (photons * hv(BANDS[b]) / got - 1.0).abs() < 1e-4,
            "{} nm: photons of another band's energy",
            BANDS[b]
        );
    }
}

/// Closed form 3 per band: an integrating sphere whose albedo differs by band (0.5, 0.9,
/// 0.7) gives ρ_b^k per order k in each band within 2 % (3 SE under 2 %), although every path
/// is sampled with the largest albedo: the factor (ρ_b / ρ_max)^k corrects it.
#[test]
fn integrating_sphere_orders_hold_in_every_band() {
    let dir = tmp("bands_sphere");
    let albedo = [0.5, 0.9, 0.7];
    let mesh = repo().join("scenes/meshes/sphere_r10.obj");
    let scene = write(
        &dir,
        "sphere.yaml",
        &format!(
            "name: s\nmaterials:\n  wall: {{ reflectance: {{ 532: {}, 1064: {}, 1550: {} }} }}\nobjects:\n  - mesh: {{ file: {}, material: wall }}\n",
            albedo[0],
            albedo[1],
            albedo[2],
            mesh.display()
        ),
    );
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad: 300.0,
        area: 0.01,
        energy: 0.001,
        ..Inst::default()
    };
    let text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, 0.0],
        [0.3, -0.2, -1.0],
        "bdpt",
        40_000,
        100,
    );
    let rows = run(&dir, &with_bands(&text, BANDS_YAML), None);
    for (b, w) in rows_by_band(&rows, 0).into_iter().enumerate() {
        for k in 1..=5u32 {
            let expect = sphere_order_energy(&inst, albedo[b], 10.0, k);
            let got = w.order_energy_j[k as usize - 1];
            let se = w.order_energy_se_j[k as usize - 1] / expect;
            let rel = got / expect - 1.0;
            println!(
                "{} nm order {k}: got {got:.5e} expect {expect:.5e} rel {rel:+.4} se {se:.4}",
                BANDS[b]
            );
            assert!(3.0 * se < 0.02, "order {k}: standard error {se} too large");
            assert!(rel.abs() < 0.02, "{} nm order {k}: {rel}", BANDS[b]);
        }
    }
}

/// Closed form 4 per band: the sun's signal over a plane is ρ_b E Δλ cos θ_s A sin²θ_fov in
/// watts in every band, counted in each band's photons, within 1 % (3 SE under 1 %).
#[test]
fn solar_signal_holds_in_every_band() {
    let rho = [0.2, 0.4, 0.3];
    let dir = tmp("bands_sun");
    let scene = spectral_plane(&dir, rho, 600.0);
    let inst = sun_inst(5.0);
    let zenith = 40.0;
    let text = with_sun_selected(
        &campaign(
            &scene,
            &inst,
            [10.0, -20.0, 1000.0],
            [0.0, 0.0, -1.0],
            "bdpt",
            100_000,
            3,
        ),
        zenith,
        180.0,
        "fixed",
    );
    let rows = run(&dir, &with_bands(&text, BANDS_YAML), None);
    for (b, w) in rows_by_band(&rows, 0).into_iter().enumerate() {
        let (p_sun, _) = solar_closed_form(&inst, rho[b], zenith);
        let expect = p_sun * w.bin_ns as f64 * 1e-9 / hv(BANDS[b]);
        let got = w.solar_photons_per_bin as f64;
        let se = w.solar_power_se_w / p_sun;
        let rel = got / expect - 1.0;
        println!(
            "{} nm sun: {got:.5} photons/bin, expect {expect:.5}, rel {rel:+.4}, se {se:.4}",
            BANDS[b]
        );
        assert!(
            3.0 * se < 0.01,
            "standard error {se} too large for a 1% test"
        );
        assert!(rel.abs() < 0.01, "{} nm: relative error {rel}", BANDS[b]);
    }
}

/// Each band of a 3-band run over a layer of leaves (reflectance and transmittance differing
/// by band, a soil below) equals a single-band run of that wavelength, order by order and bin
/// by bin, within 3 combined standard errors: the shared paths change no band's expectation.
/// The leaves reflect most at 1550 nm and transmit most at 1064 nm, so paths are sampled
/// with ρ_max + τ_max = 1.15 > 1 (no roulette, weights above 1 per bounce) and no band's run
/// shares the multi-band run's draws.
#[test]
fn each_band_equals_a_run_of_its_own_wavelength() {
    let dir = tmp("bands_leaves");
    let scene = leaf_layer_of(
        &dir,
        "{ reflectance: { 532: 0.08, 1064: 0.3, 1550: 0.35 } }",
        "{ reflectance: { 532: 0.1, 1064: 0.4, 1550: 0.6 }, transmittance: { 532: 0.05, 1064: 0.55, 1550: 0.1 } }",
    );
    let inst = Inst {
        fp_mrad: 5.0,
        fov_mrad: 7.5,
        area: 0.1,
        fwhm_ns: 0.0,
        bin_ns: 0.5,
        ..Inst::default()
    };
    let text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, 500.0],
        [0.0, 0.0, -1.0],
        "bdpt",
        60_000,
        3,
    );
    compare_bands_with_single_runs("leaves", &dir, &text, &BANDS, 3);
}

/// The output contract of several bands: waveform rows per pulse and band (in the campaign's
/// band order, the `wavelength_nm` column beside pulse_id), points of every band with their
/// band in points.las, the same bytes whatever the thread count, and a run of one band with
/// none of it.
#[test]
fn tables_of_several_bands_carry_the_band() {
    use arrow_array::cast::AsArray;
    use arrow_array::types::Float64Type;
    let dir = tmp("bands_tables");
    two_band_plane(&dir);
    let text = "name: two\nscene: plane.yaml\nseed: 8\nwavelength_nm: [532, 1064]\ninstrument: { kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [10, 0] }, along_track_step_m: 1 }\nsimulation: { method: bdpt, rays_per_pulse: 50, max_order: 2 }\nproducts: { points: true, dsm: { resolution_m: 2 } }\n";
    let campaign_path = write(&dir, "two.yaml", text);
    let (one, two) = (dir.join("t1"), dir.join("t2"));
    run_cli(&campaign_path, &one, Some(1));
    run_cli(&campaign_path, &two, Some(2));
    for f in ["waveforms/part-00000.parquet", "points.las"] {
        assert_eq!(
            std::fs::read(one.join(f)).unwrap(),
            std::fs::read(two.join(f)).unwrap(),
            "{f} differs between 1 and 2 threads"
        );
    }
    let rows = lidarsim::waveform::file::read_waveforms(&one.join("waveforms/part-00000.parquet"))
        .unwrap();
    let pulses = rows.len() / 2;
    assert!(
        pulses >= 5 && rows.len() == 2 * pulses,
        "{} rows",
        rows.len()
    );
    for (i, w) in rows.iter().enumerate() {
        assert_eq!(w.pulse_id, i as u64 / 2);
        assert_eq!(w.wavelength_nm, Some([532.0, 1064.0][i % 2]));
    }
    // the column's place and type, read by the Parquet reader, not ours
    let batch = first_batch(&one.join("waveforms/part-00000.parquet"));
    assert_eq!(batch.schema().field(1).name(), "wavelength_nm");
    let nm = batch.column(1).as_primitive::<Float64Type>();
    assert_eq!((nm.value(0), nm.value(1)), (532.0, 1064.0));
    // the brighter band returns more energy from the same paths
    for pair in rows.chunks(2) {
        assert!(pair[1].received_energy_j > 3.0 * pair[0].received_energy_j);
    }
    let points = lidarsim::products::points::las::read_las(&one.join("points.las")).unwrap();
    for nm in [532.0f32, 1064.0] {
        let n = points
            .iter()
            .filter(|p| p.wavelength_nm == Some(nm))
            .count();
        assert_eq!(n, pulses, "one return per pulse at {nm} nm");
    }
    // one band: none of it
    let single = write(&dir, "one.yaml", &text.replace("[532, 1064]", "1064"));
    let out = dir.join("single");
    run_cli(&single, &out, None);
    let batch = first_batch(&out.join("waveforms/part-00000.parquet"));
    assert!(batch.column_by_name("wavelength_nm").is_none());
    assert_eq!(batch.num_rows(), pulses);
    let points = lidarsim::products::points::las::read_las(&out.join("points.las")).unwrap();
    assert!(points.iter().all(|p| p.wavelength_nm.is_none()));
}

/// Photon counting in two bands: photons.parquet gains the `wavelength_nm` column, and each
/// band counts its own laser photons: Poisson with mean QE × Σ laser photons of that band's
/// waveforms (no dead time here), within 4 standard deviations, with independent draws.
#[test]
fn photons_of_several_bands_carry_the_band() {
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float64Type, UInt64Type};
    let dir = tmp("bands_photons");
    two_band_plane(&dir);
    let path = write(
        &dir,
        "pc.yaml",
        "name: pc\nscene: plane.yaml\nseed: 5\nwavelength_nm: [532, 1064]\ninstrument:\n  kind: photon_counting\n  pulse_energy_j: 1.0e-10\n  pulse_fwhm_ns: 1.0\n  footprint_half_angle_mrad: 0.1\n  fov_half_angle_mrad: 0.5\n  receiver_area_m2: 0.01\n  bin_ns: 1.0\n  quantum_efficiency: 0.5\n  dead_time_ns: 0\n  dark_count_hz: 2.0e8\nplatform: { kind: track, altitude_m: 200, track: { start: [0, 0], end: [10, 0] }, along_track_step_m: 0.1 }\nsimulation: { method: forward, rays_per_pulse: 100, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_cli(&path, &out, None);
    assert!(out.join("photons_atl03.h5").exists());
    let file = std::fs::File::open(out.join("photons.parquet")).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap();
    let (mut by_band, mut dark) = ([0usize; 2], [0usize; 2]);
    for batch in reader {
        let batch = batch.unwrap();
        let nm = batch
            .column_by_name("wavelength_nm")
            .expect("photons.parquet has a wavelength_nm column")
            .as_primitive::<Float64Type>();
        let source = batch.column_by_name("source").unwrap();
        let source = source.as_primitive::<arrow_array::types::UInt8Type>();
        let _ids = batch
            .column_by_name("pulse_id")
            .unwrap()
            .as_primitive::<UInt64Type>();
        for i in 0..batch.num_rows() {
            let b = match nm.value(i) {
                532.0 => 0,
                1064.0 => 1,
                x => panic!("photon of band {x} nm"),
            };
            if source.value(i) == 0 {
                by_band[b] += 1;
            } else {
                dark[b] += 1;
            }
        }
    }
    let mut expect = [0.0f64; 2];
    for w in
        lidarsim::waveform::file::read_waveforms(&out.join("waveforms/part-00000.parquet")).unwrap()
    {
        let b = usize::from(w.wavelength_nm == Some(1064.0));
        expect[b] += 0.5 * w.laser_photons.iter().map(|&p| p as f64).sum::<f64>();
    }
    println!("laser photons by band {by_band:?} (expected {expect:?}), dark {dark:?}");
    for b in 0..2 {
        let z = (by_band[b] as f64 - expect[b]) / expect[b].sqrt();
        assert!(expect[b] > 50.0 && z.abs() < 4.0, "band {b}: z {z}");
    }
    // hν at 1064 nm is half that at 532 and ρ is 4 times: about 8 times the photons
    assert!(expect[1] / expect[0] > 7.0 && expect[1] / expect[0] < 9.0);
    assert!(dark[0] > 0 && dark[1] > 0 && dark[0] != dark[1], "{dark:?}");
}

/// laspy reads the band of each point of a run of several bands.
#[test]
fn laspy_reads_the_band_of_each_point() {
    if !python_with("laspy", "laspy") {
        return;
    }
    let dir = tmp("bands_laspy");
    two_band_plane(&dir);
    let campaign_path = write(
        &dir,
        "two.yaml",
        "name: two\nscene: plane.yaml\nseed: 8\nwavelength_nm: [1064, 532]\ninstrument: { kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [4, 0] }, along_track_step_m: 1 }\nsimulation: { method: forward, rays_per_pulse: 50, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_cli(&campaign_path, &out, None);
    run_python(
        r#"
import sys, laspy, numpy as np
f = laspy.read(sys.argv[1] + "/points.las")
names = list(f.point_format.extra_dimension_names)
assert names == ["apparent_reflectance", "pulse_id", "wavelength_nm"], names
nm = np.asarray(f["wavelength_nm"])
assert nm.dtype == np.float32
assert sorted(set(nm.tolist())) == [532.0, 1064.0], set(nm.tolist())
# pulse order, then the campaign's band order (1064 first here)
assert nm[0] == 1064.0 and nm[1] == 532.0, nm[:4]
rho = np.asarray(f["apparent_reflectance"])
assert np.all(rho[nm == 1064.0] > 2.0 * rho[nm == 532.0]), rho
"#,
        &out,
    );
}

/// Bad band lists end with exit code 1 and one message naming the file, line and key.
#[test]
fn bad_band_lists_are_located_errors() {
    let dir = tmp("bands_bad");
    two_band_plane(&dir);
    let base = "name: bad\nscene: plane.yaml\nwavelength_nm: BANDS\ninstrument: { pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [2, 0] }, along_track_step_m: 1 }\n";
    for (bands, says) in [
        ("[]", "empty"),
        ("[532, 532]", "listed twice"),
        ("[532, 50]", "wavelength_nm[1]"),
        ("[532, 1064, 1550]", "1550"),
        ("[1, 2, 3, 4, 5, 6, 7, 8, 9]", "at most 8"),
        ("[532, abc]", "wavelength_nm"),
    ] {
        let path = write(&dir, "bad.yaml", &base.replace("BANDS", bands));
        // the list's errors are the campaign's; a band a material lacks, the scene's
        let file = if bands.contains("1550") {
            "plane.yaml"
        } else {
            "bad.yaml"
        };
        assert_bad_input(&path, file, says);
    }
}
