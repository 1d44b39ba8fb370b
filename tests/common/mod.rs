//! Shared helpers for the integration tests: temporary run folders, campaign text, and the
//! closed forms of ../shared/spec/physics.md computed by quadrature.
#![allow(dead_code)]

use lidarsim::pipeline::{self, RunOptions};
use lidarsim::waveform::file as parquet;
use lidarsim::waveform::Waveform;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::process::Command;

pub use lidarsim::C;

/// A fresh, empty folder for one test under cargo's folder for tests' files, removed with
/// everything in it when the value is dropped (at the end of the test, passed or failed): a
/// test run leaves nothing behind. It derefs to its path.
pub type Tmp = lidarsim::testdata::TempDir;

pub fn tmp(name: &str) -> Tmp {
    Tmp::at(Path::new(env!("CARGO_TARGET_TMPDIR")).join(name))
}

pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

pub use lidarsim::testdata::repo;

/// Instrument block of a campaign, in YAML flow style.
#[derive(Clone, Debug)]
pub struct Inst {
    pub energy: f64,
    pub fwhm_ns: f64,
    pub fp_mrad: f64,
    pub fov_mrad: f64,
    pub area: f64,
    pub bin_ns: f64,
    pub eta: f64,
}

impl Default for Inst {
    fn default() -> Self {
        Inst {
            energy: 0.01,
            fwhm_ns: 0.0,
            fp_mrad: 1.0,
            fov_mrad: 1.5,
            area: 0.1,
            bin_ns: 1.0,
            eta: (-2.0f64).exp(),
        }
    }
}

/// Campaign text with one static pulse.
pub fn campaign(
    scene: &Path,
    inst: &Inst,
    pos: [f64; 3],
    dir: [f64; 3],
    method: &str,
    rays: u64,
    max_order: u32,
) -> String {
    format!(
        "name: t\nscene: {}\nseed: 3\nwavelength_nm: 1064\ninstrument:\n  pulse_energy_j: {}\n  pulse_fwhm_ns: {}\n  footprint_half_angle_mrad: {}\n  edge_energy_fraction: {}\n  fov_half_angle_mrad: {}\n  receiver_area_m2: {}\n  bin_ns: {}\nplatform:\n  kind: static\n  pulses:\n    - {{ position: [{}, {}, {}], direction: [{}, {}, {}] }}\nsimulation: {{ method: {method}, rays_per_pulse: {rays}, max_order: {max_order} }}\n",
        scene.display(),
        inst.energy,
        inst.fwhm_ns,
        inst.fp_mrad,
        inst.eta,
        inst.fov_mrad,
        inst.area,
        inst.bin_ns,
        pos[0],
        pos[1],
        pos[2],
        dir[0],
        dir[1],
        dir[2]
    )
}

/// A campaign text from [`campaign`] with `simulation.sampler` set.
pub fn with_sampler(campaign: &str, sampler: &str) -> String {
    let head = campaign
        .trim_end()
        .strip_suffix(" }")
        .expect("the campaign ends with its simulation map");
    format!("{head}, sampler: {sampler} }}\n")
}

/// Runs a campaign text through the library pipeline into `dir/run`; returns that folder.
pub fn run_campaign(dir: &Path, campaign_text: &str, threads: Option<usize>) -> PathBuf {
    let path = write(dir, "campaign.yaml", campaign_text);
    let out = dir.join("run");
    pipeline::run(
        &path,
        &RunOptions {
            out: Some(out.clone()),
            threads,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    out
}

/// Runs a campaign text through the library pipeline and reads its waveforms back.
pub fn run(dir: &Path, campaign_text: &str, threads: Option<usize>) -> Vec<Waveform> {
    let out = run_campaign(dir, campaign_text, threads);
    parquet::read_waveforms(&out.join("waveforms/part-00000.parquet")).unwrap()
}

/// Every waveform row of a run folder's parts, part after part.
pub fn all_waveforms(out: &Path) -> Vec<Waveform> {
    let mut rows = Vec::new();
    for k in 0.. {
        let part = out.join(parquet::part_name(k));
        if !part.is_file() {
            break;
        }
        rows.extend(parquet::read_waveforms(&part).unwrap());
    }
    rows
}

/// The row of a run folder's report.md labelled `label` ("| label | figure: ..."), and the
/// figure it opens with.
pub fn report_figure(out: &Path, label: &str) -> (String, f64) {
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let line = md
        .lines()
        .find(|l| l.starts_with(&format!("| {label} |")))
        .unwrap_or_else(|| panic!("no '{label}' row in report.md:\n{md}"));
    let figure = line
        .split('|')
        .nth(2)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .trim_end_matches(':')
        .parse()
        .unwrap();
    (line.to_string(), figure)
}

/// Runs the binary; returns (exit code, stdout, stderr).
pub fn lidarsim(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_lidarsim"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `lidarsim run CAMPAIGN --out DIR/out`, which must fail as bad input does: exit code 1, a
/// message that says `says` and names the file `file` (with its line), no panic.
pub fn assert_bad_input(campaign: &Path, file: &str, says: &str) {
    let out = campaign.with_file_name("out");
    let (code, _, err) = lidarsim(&[
        "run",
        campaign.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    println!("{says}: {err}");
    assert_eq!(code, 1, "{err}");
    assert!(err.contains(says), "expected \"{says}\" in: {err}");
    assert!(
        err.contains(&format!("{file}:")),
        "expected {file}: in: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

/// `lidarsim run CAMPAIGN --out OUT [--threads N]`, which must succeed; returns its stderr.
pub fn run_cli(campaign: &Path, out: &Path, threads: Option<usize>) -> String {
    let threads = threads.map(|n| n.to_string());
    let mut args = vec![
        "run",
        campaign.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    if let Some(n) = &threads {
        args.extend(["--threads", n.as_str()]);
    }
    let (code, _, err) = lidarsim(&args);
    assert_eq!(code, 0, "{err}");
    err
}

/// Whether python3 imports `modules` (as an import statement lists them); if not, the test
/// says so on stderr, or fails under `LIDARSIM_REQUIRE_TOOLS=1`.
pub fn python_with(modules: &str, pip: &str) -> bool {
    let ok = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        lidarsim::testdata::skip_tool(&format!(
            "python3 with {modules} is not available (pip install {pip})"
        ));
    }
    ok
}

/// Runs a Python script with `arg` as sys.argv[1]; a failure fails the test with its output.
pub fn run_python(script: &str, arg: &Path) {
    let o = Command::new("python3")
        .args(["-c", script, arg.to_str().unwrap()])
        .output()
        .unwrap();
    print!("{}", String::from_utf8_lossy(&o.stdout));
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

pub fn plane_scene(dir: &Path, rho: f64, half: f64) -> PathBuf {
    write(
        dir,
        "plane.yaml",
        &format!(
            "name: p\nmaterials:\n  soil: {{ reflectance: {rho} }}\nobjects:\n  - plane: {{ z: 0, extent: [[{}, {}], [{}, {}]], material: soil }}\n",
            -half, -half, half, half
        ),
    )
}

/// σ of the footprint's Gaussian in tan-space (Appendix B).
pub fn sigma(fp_mrad: f64, eta: f64) -> f64 {
    (fp_mrad * 1e-3).tan() / (-2.0 * eta.ln()).sqrt()
}

/// Laser pdf in tan-space (per unit tan-plane area), truncated at tan θ_fp.
pub fn p_tan(u: f64, fp_mrad: f64, eta: f64) -> f64 {
    let s = sigma(fp_mrad, eta);
    if u > (fp_mrad * 1e-3).tan() {
        0.0
    } else {
        (-u * u / (2.0 * s * s)).exp() / (2.0 * PI * s * s * (1.0 - eta))
    }
}

/// Area shared by two disks of radii a and b whose centres are d apart.
pub fn disk_overlap(a: f64, b: f64, d: f64) -> f64 {
    if d >= a + b {
        return 0.0;
    }
    let (small, big) = if a < b { (a, b) } else { (b, a) };
    if d <= big - small {
        return PI * small * small;
    }
    let alpha = ((d * d + a * a - b * b) / (2.0 * d * a))
        .clamp(-1.0, 1.0)
        .acos();
    let beta = ((d * d + b * b - a * a) / (2.0 * d * b))
        .clamp(-1.0, 1.0)
        .acos();
    a * a * (alpha - alpha.sin() * alpha.cos()) + b * b * (beta - beta.sin() * beta.cos())
}

/// Closed form 1 (physics.md), with the aperture's finite size:
/// Q_r = (Q_e ρ / (π H²)) ∫ p_ground(g) A_overlap(|g|) dA_g.
pub fn plane_energy(inst: &Inst, rho: f64, h: f64) -> f64 {
    let r_tel = (inst.area / PI).sqrt();
    let r_fov = h * (inst.fov_mrad * 1e-3).tan();
    let g_max = h * (inst.fp_mrad * 1e-3).tan();
    let n = 200_000;
    let dg = g_max / n as f64;
    let mut sum = 0.0;
    for i in 0..n {
        let g = (i as f64 + 0.5) * dg;
        let p_ground = p_tan(g / h, inst.fp_mrad, inst.eta) / (h * h);
        sum += p_ground * disk_overlap(r_tel, r_fov, g) * 2.0 * PI * g * dg;
    }
    inst.energy * rho / (PI * h * h) * sum
}

/// Closed form 1 with the telescope's centre offset horizontally by (ox, oy) from the laser
/// (bistatic, small angles): a ground point g is seen by the part of the aperture inside the
/// disk of radius H tan θ_fov around g, which now lies |g - o| from the aperture's centre, so
/// Q_r = (Q_e ρ / (π H²)) ∫ p_ground(g) A_overlap(|g - o|) dA_g, by quadrature in polar
/// coordinates over the footprint.
pub fn plane_energy_offset(inst: &Inst, rho: f64, h: f64, offset: [f64; 2]) -> f64 {
    let r_tel = (inst.area / PI).sqrt();
    let r_fov = h * (inst.fov_mrad * 1e-3).tan();
    let g_max = h * (inst.fp_mrad * 1e-3).tan();
    let (nr, na) = (2000, 720);
    let (dr, da) = (g_max / nr as f64, 2.0 * PI / na as f64);
    let mut sum = 0.0;
    for i in 0..nr {
        let g = (i as f64 + 0.5) * dr;
        let p_ground = p_tan(g / h, inst.fp_mrad, inst.eta) / (h * h);
        for j in 0..na {
            let a = (j as f64 + 0.5) * da;
            let d = (g * a.cos() - offset[0]).hypot(g * a.sin() - offset[1]);
            sum += p_ground * disk_overlap(r_tel, r_fov, d) * g * dr * da;
        }
    }
    inst.energy * rho / (PI * h * h) * sum
}

/// The sun of the solar tests: E (W m⁻² µm⁻¹) over a band of `SUN_BAND_NM`.
pub const SUN_E: f64 = 640.0;
pub const SUN_BAND_NM: f64 = 0.8;

/// A campaign text with the sun's band and a `sun:` section at `zenith`, `azimuth`.
pub fn with_sun_selected(campaign: &str, zenith: f64, azimuth: f64, selection: &str) -> String {
    campaign.replace("instrument:\n", &format!("instrument:\n  bandwidth_nm: {SUN_BAND_NM}\n"))
        + &format!(
            "sun: {{ zenith_deg: {zenith}, azimuth_deg: {azimuth}, irradiance_w_m2_um: {SUN_E}, selection: {selection} }}\n"
        )
}

/// The instrument of the solar closed-form tests (1 mrad footprint, 1 mJ, 2 ns).
pub fn sun_inst(fov_mrad: f64) -> Inst {
    Inst {
        fp_mrad: 1.0,
        fov_mrad,
        area: 0.1,
        energy: 0.001,
        fwhm_ns: 2.0,
        ..Inst::default()
    }
}

/// Closed form 4 at 1064 nm: (P_sun, N_SN per 1 ns bin) of a Lambertian plane filling the
/// field of view, nadir view, P_sun = ρ E Δλ cos θ_s A_tel sin²θ_fov.
pub fn solar_closed_form(inst: &Inst, rho: f64, zenith_deg: f64) -> (f64, f64) {
    let hv = 6.626_070_15e-34 * C / 1064e-9;
    let s2 = (inst.fov_mrad * 1e-3).sin().powi(2);
    let p_sun = rho * SUN_E * SUN_BAND_NM * 1e-3 * zenith_deg.to_radians().cos() * inst.area * s2;
    (p_sun, p_sun * 1e-9 / hv)
}

/// E_footprint[cos θ] of the laser's directions.
pub fn footprint_mean_cos(fp_mrad: f64, eta: f64) -> f64 {
    let u_max = (fp_mrad * 1e-3).tan();
    let n = 100_000;
    let du = u_max / n as f64;
    (0..n)
        .map(|i| {
            let u = (i as f64 + 0.5) * du;
            p_tan(u, fp_mrad, eta) / (1.0 + u * u).sqrt() * 2.0 * PI * u * du
        })
        .sum()
}

/// Closed form 3: energy of scattering order k (1-based) in an integrating sphere.
pub fn sphere_order_energy(inst: &Inst, albedo: f64, radius: f64, k: u32) -> f64 {
    if k == 1 {
        albedo * inst.energy * inst.area / (PI * radius * radius)
            * footprint_mean_cos(inst.fp_mrad, inst.eta)
    } else {
        let s = (inst.fov_mrad * 1e-3).sin();
        albedo.powi(k as i32) * inst.energy * inst.area * s * s / (4.0 * PI * radius * radius)
    }
}

/// A closed icosphere of radius `r` with `subdiv` subdivisions, normals facing the centre,
/// as OBJ text (the same construction as tools/icosphere.py).
pub fn icosphere_obj(r: f64, subdiv: u32) -> String {
    use std::collections::HashMap;
    use std::fmt::Write;
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / n, p[1] / n, p[2] / n]
    })
    .collect();
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdiv {
        let mut cache: HashMap<(usize, usize), usize> = HashMap::new();
        let mut mid = |a: usize, b: usize, v: &mut Vec<[f64; 3]>| {
            *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let p = [
                    (v[a][0] + v[b][0]) / 2.0,
                    (v[a][1] + v[b][1]) / 2.0,
                    (v[a][2] + v[b][2]) / 2.0,
                ];
                let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                v.push([p[0] / n, p[1] / n, p[2] / n]);
                v.len() - 1
            })
        };
        let mut nf = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let (ab, bc, ca) = (mid(a, b, &mut v), mid(b, c, &mut v), mid(c, a, &mut v));
            nf.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    let mut out = String::new();
    for p in &v {
        writeln!(out, "v {} {} {}", r * p[0], r * p[1], r * p[2]).unwrap();
    }
    for [a, b, c] in f {
        writeln!(out, "f {} {} {}", a + 1, c + 1, b + 1).unwrap();
    }
    out
}

/// The integrating sphere of radius 10 m, tessellated finely enough that its facets'
/// near-field exchange is negligible even for a narrow field of view.
pub fn fine_sphere_scene(dir: &Path, albedo: f64, subdiv: u32) -> PathBuf {
    write(dir, "fine_sphere.obj", &icosphere_obj(10.0, subdiv));
    write(
        dir,
        "fine_sphere.yaml",
        &format!("name: s\nmaterials:\n  wall: {{ reflectance: {albedo} }}\nobjects:\n  - mesh: {{ file: fine_sphere.obj, material: wall }}\n"),
    )
}

pub fn sphere_scene(dir: &Path, albedo: f64) -> PathBuf {
    let mesh = repo().join("scenes/meshes/sphere_r10.obj");
    write(
        dir,
        "sphere.yaml",
        &format!(
            "name: s\nmaterials:\n  wall: {{ reflectance: {albedo} }}\nobjects:\n  - mesh: {{ file: {}, material: wall }}\n",
            mesh.display()
        ),
    )
}

/// Per-order agreement: |a - b| < 3 combined standard errors, with standard errors small
/// enough that a 10% disagreement could not hide.
pub fn compare_orders(name: &str, a: &Waveform, b: &Waveform, orders: usize) {
    for k in 0..orders {
        let (ea, eb) = (a.order_energy_j[k], b.order_energy_j[k]);
        let se = (a.order_energy_se_j[k].powi(2) + b.order_energy_se_j[k].powi(2)).sqrt();
        let z = (ea - eb) / se;
        println!(
            "{name} order {}: {ea:.5e} vs {eb:.5e} z {z:+.2} rel se {:.4}",
            k + 1,
            se / ea
        );
        assert!(
            se / ea.max(eb) < 0.033,
            "{name} order {}: standard error too large",
            k + 1
        );
        assert!(
            z.abs() < 3.0,
            "{name} order {}: the methods differ by {z:.2} standard errors",
            k + 1
        );
    }
    let se = (a.received_energy_se_j.powi(2) + b.received_energy_se_j.powi(2)).sqrt();
    let z = (a.received_energy_j - b.received_energy_j) / se;
    println!("{name} total: z {z:+.2}");
    assert!(z.abs() < 3.0);
}

/// A campaign `text` of one pulse at 1064 nm traced in all of `bands` at once (in `dir/all`)
/// and in each alone (in `dir/<nm>`): each band of the first run equals the run of its own
/// wavelength per order (`orders`) and per bin within 3 combined SE ([`compare_orders`],
/// [`compare_bins`]), rows in the list's order, the single runs without a band column.
pub fn compare_bands_with_single_runs(
    name: &str,
    dir: &Path,
    text: &str,
    bands: &[f64],
    orders: usize,
) {
    let list: Vec<String> = bands.iter().map(|nm| nm.to_string()).collect();
    let with = |wavelengths: &str| {
        assert!(text.contains("wavelength_nm: 1064\n"));
        text.replace(
            "wavelength_nm: 1064\n",
            &format!("wavelength_nm: {wavelengths}\n"),
        )
    };
    let all_dir = dir.join("all");
    std::fs::create_dir_all(&all_dir).unwrap();
    let all = run(&all_dir, &with(&format!("[{}]", list.join(", "))), None);
    assert_eq!(all.len(), bands.len(), "one row per band");
    for (row, &nm) in all.iter().zip(bands) {
        assert_eq!(row.wavelength_nm, Some(nm));
        let one_dir = dir.join(nm.to_string());
        std::fs::create_dir_all(&one_dir).unwrap();
        let one = run(&one_dir, &with(&nm.to_string()), None).remove(0);
        assert_eq!(one.wavelength_nm, None, "a single band has no band column");
        let label = format!("{name} {nm} nm");
        compare_orders(&label, row, &one, orders);
        compare_bins(&label, row, &one);
    }
}

/// Per-bin agreement of the impulse waveforms over the bins that hold 99.9% of the energy.
/// Each bin's z-score must stay within 3 (a bin beyond is reported; with many bins one in a
/// few hundred may be, so at most 1% of them), and Σz² must stay under the 99.9% quantile of
/// its χ² distribution (Wilson-Hilferty), which a systematic shift of the shape would break.
pub fn compare_bins(name: &str, a: &Waveform, b: &Waveform) {
    let total: f64 = a.impulse_energy_j.iter().map(|&e| e as f64).sum();
    let mut bins: Vec<usize> = (0..a.impulse_energy_j.len()).collect();
    bins.sort_by(|&i, &j| a.impulse_energy_j[j].total_cmp(&a.impulse_energy_j[i]));
    let mut acc = 0.0;
    let mut kept = Vec::new();
    for i in bins {
        if acc >= 0.999 * total {
            break;
        }
        acc += a.impulse_energy_j[i] as f64;
        kept.push(i);
    }
    let mut chi2 = 0.0;
    let mut beyond = 0;
    for &i in &kept {
        let se = ((a.impulse_se(i) as f64).powi(2) + (b.impulse_se(i) as f64).powi(2)).sqrt();
        let z = (a.impulse_energy_j[i] as f64 - b.impulse_energy_j[i] as f64) / se;
        chi2 += z * z;
        if z.abs() >= 3.0 {
            beyond += 1;
        }
    }
    let k = kept.len() as f64;
    let q999 = k * (1.0 - 2.0 / (9.0 * k) + 3.09 * (2.0 / (9.0 * k)).sqrt()).powi(3);
    println!(
        "{name}: {} bins, {beyond} beyond 3 SE, chi2 {chi2:.1} (99.9% quantile {q999:.1})",
        kept.len()
    );
    assert!(kept.len() >= 5);
    assert!(
        beyond as f64 <= (0.01 * k).max(1.0),
        "{name}: {beyond} of {} bins beyond 3 SE",
        kept.len()
    );
    assert!(chi2 < q999, "{name}: chi2 {chi2} over {k} bins");
}

/// A layer of small leaves (ρ = τ = 0.45 at 1064 nm, LAI about 1.7) between 5 and 8 m over a
/// soil plane: multiple scattering carries a fifth of the signal.
/// OBJ text of `n` random leaves: triangles with two random edges of about 10 cm from a corner
/// uniform in the box `lo..hi` (a fixed xorshift sequence from `seed`).
pub fn random_leaves(n: usize, seed: u64, lo: [f64; 3], hi: [f64; 3]) -> String {
    use std::fmt::Write;
    let mut obj = String::new();
    let mut state = seed;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..n {
        let mut c = [0.0; 3];
        for k in 0..3 {
            c[k] = lo[k] + rnd() * (hi[k] - lo[k]);
        }
        let mut e = [[0.0; 3]; 2];
        for v in &mut e {
            for x in v.iter_mut() {
                *x = (rnd() - 0.5) * 0.2;
            }
        }
        for p in [[0.0; 3], e[0], e[1]] {
            writeln!(obj, "v {} {} {}", c[0] + p[0], c[1] + p[1], c[2] + p[2]).unwrap();
        }
        writeln!(obj, "f {} {} {}", 3 * i + 1, 3 * i + 2, 3 * i + 3).unwrap();
    }
    obj
}

pub fn leaf_layer(dir: &std::path::Path) -> std::path::PathBuf {
    leaf_layer_of(
        dir,
        "{ reflectance: { 1064: 0.3 } }",
        "{ reflectance: { 1064: 0.45 }, transmittance: { 1064: 0.45 } }",
    )
}

/// The leaf layer of [`leaf_layer`] with the soil and leaf materials given (YAML flow maps).
pub fn leaf_layer_of(dir: &std::path::Path, soil: &str, leaf: &str) -> std::path::PathBuf {
    let obj = random_leaves(
        100_000,
        0x2545F4914F6CDD1D,
        [-6.0, -6.0, 5.0],
        [6.0, 6.0, 8.0],
    );
    write(dir, "leaves.obj", &obj);
    write(
        dir,
        "canopy.yaml",
        &format!("name: canopy\nmaterials:\n  soil: {soil}\n  leaf: {leaf}\nobjects:\n  - plane: {{ z: 0, extent: [[-20, -20], [20, 20]], material: soil }}\n  - mesh: {{ file: leaves.obj, material: leaf }}\n"),
    )
}

/// OBJ text of a square of half-width `half` m through the origin, tilted by `alpha` (radians)
/// about the x axis: normal (0, −sin α, cos α).
pub fn tilted_square_obj(half: f64, alpha: f64) -> String {
    let (s, c) = (alpha.sin(), alpha.cos());
    let v = |x: f64, y: f64| format!("v {x} {} {}\n", y * c, y * s);
    format!(
        "{}{}{}{}f 1 2 3\nf 1 3 4\n",
        v(-half, -half),
        v(half, -half),
        v(half, half),
        v(-half, half)
    )
}
