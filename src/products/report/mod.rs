//! `report.md`: what ran, on what, how fast, and what came back, with the products' figures.

pub mod summary;

use crate::campaign::Loaded;
use crate::error::Result;
use crate::products::raster::{CellStats, DsmReport};
use crate::scene::Scene;
use crate::scene::SurfaceClass;
use crate::waveform::file::{part_name, read_waveforms, Parts};
use std::path::Path;
use summary::{ProductsSummary, WaveformTotals};

/// The simulate stage's wall time and rate: of the pulses its last invocation simulated,
/// when shards or an invocation before a resume simulated the others.
fn simulation_time(sim: f64, pulses: usize, simulated: Option<u64>) -> String {
    let now = simulated.map_or(pulses, |n| (n as usize).min(pulses));
    let rate = if sim > 0.0 { now as f64 / sim } else { 0.0 };
    if now == 0 && pulses > 0 {
        "none in the last invocation (its pulses were simulated by shards or before a resume: \
         per-pulse times in waveforms/part-NNNNN.stats.csv)"
            .to_string()
    } else if now < pulses {
        format!(
            "{sim:.2} s for the last invocation's {now} of {pulses} pulses ({rate:.1} pulses/s; the others were simulated by other shards or before a resume)"
        )
    } else {
        format!("{sim:.2} s ({rate:.1} pulses/s)")
    }
}

/// `report.md`: what ran, on what, how fast, and what came back.
///
/// Long because `report.md` is written top to bottom in the order a reader reads it, a few
/// lines per section.
pub fn report(
    loaded: &Loaded,
    scene: &Scene,
    parts: Parts,
    out: &Path,
    (simulate_s, pulses_simulated): (f64, Option<u64>),
) -> Result<String> {
    let c = &loaded.campaign;
    let pulses = parts.pulses();
    let totals =
        match ProductsSummary::read(&out.join("products.json")).and_then(|p| p.waveform_totals) {
            Some(t) => t,
            None => {
                // a products.json from before the totals: the parts by index, as the products
                // stage reads them (another file in the folder is not part of the run)
                let mut t = WaveformTotals::default();
                for k in 0..parts.count() {
                    crate::progress::release_after_part(k);
                    for w in read_waveforms(&out.join(part_name(k)))? {
                        if w.wavelength_nm
                            .is_none_or(|nm| nm == c.wavelength_nm.first())
                        {
                            t.add(&w);
                        }
                    }
                }
                t
            }
        };
    let (total, received, multiple) = (
        totals.received_energy_j,
        totals.pulses,
        totals.multiple_energy_j,
    );
    let (rays, paths, solar) = (totals.rays, totals.paths, totals.solar_photons_per_bin);
    let brf_fov = totals.brf_fov_solar.unwrap_or(f64::NAN);
    let (brf_fp, lit) = (totals.brf_footprint_laser, totals.lit);
    let sim = simulate_s;
    let s = scene.stats();
    let mut text = format!("# Run report: {}\n\n", c.name);
    text += &format!(
        "| | |\n| --- | --- |\n| scene | {} ({} instances, {} triangles) |\n| instrument | {}, {} nm, {} J, footprint {} mrad, field of view {} mrad |\n| method | {}, {} rays per pulse, max order {} |\n| pulses | {} |\n| rays | {} |\n| simulation wall time | {} |\n| effective paths per ray | {:.2} |\n| mean received energy per pulse | {:.4e} J |\n| multiple scattering share | {:.1}% |\n",
        scene.name,
        s.instances,
        s.instanced_triangles,
        as_written(&c.instrument.kind),
        c.wavelength_nm,
        c.instrument.pulse_energy_j,
        c.instrument.footprint_half_angle_mrad,
        c.instrument.fov_half_angle_mrad,
        as_written(&c.simulation.method),
        c.simulation.rays_per_pulse,
        c.simulation.max_order,
        pulses,
        rays,
        simulation_time(sim, pulses, pulses_simulated),
        paths / rays.max(1) as f64,
        total / received.max(1) as f64,
        if total > 0.0 { 100.0 * multiple / total } else { 0.0 },
    );
    if let Some(note) = &loaded.method_note {
        text += &format!("| pilot's choices | {note} |\n");
    }
    if c.wavelength_nm.several() {
        text += &format!(
            "| bands | {} nm traced in one pass; the figures of this report, the DSM and the mission files are of the first band, {} nm; waveforms, points and photons are in every band (column `wavelength_nm`) |\n",
            c.wavelength_nm,
            c.wavelength_nm.first()
        );
    }
    let n = received.max(1) as f64;
    text += &match lit {
        0 => "| scene BRF in the footprint, from the laser (π/ΔΩ)(Q_r/Q_e) | – (no laser energy in any gate) |\n".to_string(),
        _ => format!(
            "| scene BRF in the footprint, from the laser (π/ΔΩ)(Q_r/Q_e) | {:.4} (mean over the {lit} pulses with laser energy in their gate) |\n",
            brf_fp / lit as f64
        ),
    };
    if let Some(line) = noise_line(c, &totals) {
        text += &line;
    }
    if let Some(sun) = &c.sun {
        text += &format!(
            "| sun | zenith {}°, azimuth {}° |\n| solar photons per bin | {:.4} |\n| scene BRF in the field of view, from the sun (Eq. 20) | {:.4} |\n",
            sun.zenith_deg, sun.azimuth_deg, solar / n, brf_fov / n
        );
    }
    let crs = c.frame.as_ref().map(|f| f.crs.as_str());
    text += &products_section(out, c.points_format().file_name(), crs);
    text += &mission_section(out, &c.instrument, crs);
    Ok(text)
}

/// The simulation's noise against the photons' (for the first band): the variance of the
/// expected photons a pulse's rays estimate, Σ SE², over their own Poisson variance, Σ λ,
/// with λ the photons after the quantum efficiency (its share of those reaching the
/// detector, all of them for an instrument that has none). It falls as 1 / rays: under 0.01
/// the rays add under 1 % to the noise of any detected count, so fewer would do for counts
/// alone; at 10 or more a waveform is far smoother than a detector's own noise would let it
/// be, and its decomposition must weigh the simulation's noise (as it does). None before
/// products.json recorded the sum, or without light.
fn noise_line(c: &crate::campaign::Campaign, totals: &WaveformTotals) -> Option<String> {
    let var = totals.received_energy_var_j2?;
    let hv = crate::photon_energy_j(c.wavelength_nm.first());
    let qe = c.instrument.quantum_efficiency.unwrap_or(1.0);
    let photons = qe * totals.received_energy_j / hv;
    if !(photons > 0.0 && var.is_finite()) {
        return None;
    }
    let ratio = qe * qe * var / (hv * hv) / photons;
    let mut text = format!(
        "| simulation noise against photon noise | {ratio:.3e}: the Monte Carlo variance of the pulses' expected photons, summed, over their Poisson variance ({:.3e} photons per pulse after the quantum efficiency, before any dead time); it falls as 1 / rays. {} |\n",
        photons / totals.pulses.max(1) as f64,
        noise_advice(ratio, c.simulation.rays_per_pulse)
    );
    // the sun's photons over the gates, where there are any: a background whose simulation
    // noise matters against its own photon noise, not against the laser's
    let solar = totals.solar_photons_in_gates.map(|n| qe * n).unwrap_or(0.0);
    if let (true, Some(v)) = (solar > 0.0, totals.solar_photons_var) {
        text += &format!(
            "| solar simulation noise against photon noise | {:.3e}: the same for the solar photons over the gates ({:.3e} per pulse after the quantum efficiency) |\n",
            qe * qe * v / solar,
            solar / totals.pulses.max(1) as f64
        );
    }
    Some(text)
}

/// What a user should make of the simulation's noise against the photons' (`ratio`, at `rays`
/// a pulse): under 1, a recorded waveform's noise is mostly the photons' own; above, the rays
/// that would bring it to 1, and what the products do meanwhile.
fn noise_advice(ratio: f64, rays: u64) -> String {
    if !(ratio.is_finite() && ratio > 0.0) {
        return String::new();
    }
    if ratio <= 1.0 {
        return "At most 1: a recorded waveform's noise is mostly the photons' own.".into();
    }
    let needed = rays as f64 * ratio;
    format!(
        "Above 1, each simulated waveform is noisier than a detector would record it: about {needed:.3e} rays a pulse would bring the ratio to 1, for a study of single waveforms. Points and DSMs need far fewer: the decomposition weighs the simulation's noise when it judges a return (docs/outputs.md, \"Discrete returns\")."
    )
}

/// A campaign value as a user writes it in the campaign file (`discrete_return`, not the
/// type's own name).
fn as_written<T: serde::Serialize>(v: &T) -> String {
    match serde_yaml::to_value(v) {
        Ok(serde_yaml::Value::String(s)) => s,
        _ => String::from("?"),
    }
}

/// The mission-shaped files in a run folder, and what the waveform record holds.
fn mission_section(out: &Path, inst: &crate::campaign::Instrument, crs: Option<&str>) -> String {
    let place = crs.map_or(
        "local metres, no frame: latitude = y, longitude = x".to_string(),
        |c| format!("degrees on WGS 84 from {c}"),
    );
    let mut text = String::new();
    if out.join(crate::products::mission::L1B_FILE).is_file() {
        let mut record = vec![];
        match &inst.noise {
            Some(n) => record.push(format!(
                "Poisson shot noise and {} photoelectrons of electronic noise",
                n.electronic_sd_photons
            )),
            None => record.push("no noise (mean photoelectrons)".to_string()),
        }
        if let Some(f) = inst.detector_response_fwhm_ns {
            record.push(format!("a detector response of {f} ns FWHM"));
        }
        if let Some(d) = &inst.digitiser {
            record.push(format!(
                "digitised: {} counts per photoelectron, offset {}, {} bits, saturating at {}",
                d.gain,
                d.offset,
                d.bits,
                d.saturation()
            ));
        }
        text += &format!(
            "\nGEDI L1B- and L2A-like files for GEDI tools: `waveforms_l1b.h5` and `waveforms_l2a.h5` ({place}); the record has {}.\n",
            record.join(", ")
        );
        let l2a = ProductsSummary::read(&out.join("products.json")).and_then(|p| p.l2a);
        if let Some(l) = l2a {
            let m = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:+.2} m"));
            let sd = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2} m"));
            text += &format!(
                "\nL2A against the truth under the footprints, over the {} of {} shots of quality 1 (`waveforms_l2a.h5`: `elev_lowestmode + rh[:, 98] − truth_canopy_top` and `elev_lowestmode − truth_ground_elev`, per shot):\n\n| | mean | sd |\n| --- | --- | --- |\n| RH98 − true canopy top | {} | {} |\n| ground − true ground | {} | {} |\n",
                l.quality_shots, l.shots,
                m(l.rh98_minus_top_mean_m), sd(l.rh98_minus_top_sd_m),
                m(l.ground_minus_truth_mean_m), sd(l.ground_minus_truth_sd_m)
            );
        }
        if out.join("l2a_waveforms.png").is_file() {
            text += "\nA few records against elevation, with the L2A ground (lowest mode) and RH98 beside the truth under the footprint (the scene's ground and highest point; dashed):\n\n![Records with the L2A ground and RH98 against the truth](l2a_waveforms.png)\n";
        }
    }
    if out.join(crate::products::mission::ATL03_FILE).is_file() {
        text += &format!(
            "\nICESat-2 ATL03-like photons for ATL03 tools: `photons_atl03.h5` ({place}); `signal_conf_ph` is 4 for laser photons and 0 for solar and dark ones, and `truth_source` says which.\n"
        );
        if out.join("atl03_photons.png").is_file() {
            text += "\nThe first ground track's photons, height against along-track distance, coloured by their truth:\n\n![ATL03 photons by their truth](atl03_photons.png)\n";
        }
    }
    text
}

/// The products part of report.md: figures from products.json and dsm/report.json, and the
/// plots beside them.
fn products_section(out: &Path, points_file: &str, crs: Option<&str>) -> String {
    let mut text = String::new();
    let Some(p) = ProductsSummary::read(&out.join("products.json")) else {
        return text;
    };
    let num = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map_or("–".to_string(), |x| format!("{x:.3}"))
    };
    // a number as the JSON files print it (2.0, not 2), so the report quotes them alike
    let raw = |x: f64| serde_json::Value::from(x).to_string();
    if let Some(pts) = &p.points {
        let by = |class: SurfaceClass| {
            pts.points_by_class
                .get(class.las_name())
                .copied()
                .unwrap_or(0)
        };
        text += &format!(
            "\n## Discrete returns ({}{})\n\n| | |\n| --- | --- |\n| points | {} |\n| points per pulse | {} |\n| pulse density | {} per m² |\n| ground / vegetation / building / unclassified | {} / {} / {} / {} |\n",
            points_file,
            crs.map_or(String::new(), |c| format!(", in {c}")),
            pts.points, num(Some(pts.points_per_pulse)), num(pts.pulse_density_per_m2),
            by(SurfaceClass::Ground), by(SurfaceClass::Vegetation), by(SurfaceClass::Building), by(SurfaceClass::Other)
        );
        for (f, what) in [
            (
                "points_top.png",
                "Points from above, coloured by apparent reflectance",
            ),
            ("waveforms.png", "Waveforms with their fitted components"),
        ] {
            if out.join(f).exists() {
                text += &format!("\n{what}:\n\n![{what}]({f})\n");
            }
        }
    }
    if let Some(s) = &p.strips {
        text += &format!(
            "\n## Strip-to-strip height differences\n\nWhere strips (point source ids) overlap on smooth cells ({} m cells in which each strip has at least {} last returns within {} m of height), the difference of their mean heights, b less a:\n\n| a | b | cells | mean | RMS | largest |\n| --- | --- | --- | --- | --- | --- |\n",
            raw(s.cell_m),
            s.min_points,
            raw(s.flat_m)
        );
        for q in &s.pairs {
            text += &format!(
                "| {} | {} | {} | {} m | {} m | {} m |\n",
                q.a,
                q.b,
                q.cells,
                num(Some(q.mean_dz_m)),
                num(Some(q.rms_dz_m)),
                num(Some(q.max_abs_dz_m))
            );
        }
        if s.pairs.is_empty() {
            text += "| – | – | 0 | – | – | – |\n\nNo two strips overlap on a smooth cell.\n";
        }
    }
    if let Some(d) = DsmReport::read(&out.join("dsm/report.json")) {
        let row = |name: &str, c: &CellStats| {
            format!(
                "| {name} | {} m | {} m | {} m | {} | {} |\n",
                num(Some(c.bias_m)),
                num(Some(c.rmse_m)),
                num(Some(c.mae_m)),
                num(Some(c.coverage)),
                c.cells
            )
        };
        let headline = CellStats {
            cells: d.cells,
            cells_with_points: d.cells_with_points,
            coverage: d.coverage,
            bias_m: d.bias_m,
            rmse_m: d.rmse_m,
            mae_m: d.mae_m,
        };
        text += &format!(
            "\n## DSM error ({} m cells)\n\nThe headline is over the {}.\n\n| cells | bias | RMSE | MAE | coverage | cells |\n| --- | --- | --- | --- | --- | --- |\n{}{}{}{}\n| \\|scan angle\\| (°) | cells | coverage | bias (m) | RMSE (m) |\n| --- | --- | --- | --- | --- |\n",
            raw(d.resolution_m),
            d.headline,
            row("**headline**", &headline),
            row("the swath's edge", &d.edge),
            row("outside the swath (tops no pulse reaches)", &d.outside),
            row("all", &d.all),
        );
        for b in &d.by_scan_angle {
            text += &format!(
                "| {}–{} | {} | {} | {} | {} |\n",
                raw(b.bin_deg_lo),
                raw(b.bin_deg_hi),
                b.cells_surfaced,
                num(Some(b.coverage)),
                num(Some(b.bias_m)),
                num(Some(b.rmse_m))
            );
        }
        text += "\n![DSM error map](dsm/error_map.png)\n\n![DSM error and coverage against scan angle](dsm/error_vs_scan_angle.png)\n";
        if out.join("dsm/dsm.tif").is_file() {
            text += &format!(
                "\nRasters for GIS tools (GeoTIFF, float32, nodata −9999, {}): `dsm/dsm.tif`, `dsm/reference.tif`, `dsm/difference.tif`.\n",
                crs.map_or("local metres, no CRS".to_string(), |c| format!("{c}, heights in it"))
            );
        }
    }
    if let Some(ph) = &p.photons {
        text += &format!(
            "\n## Photon counting (photons.parquet)\n\n| total | laser | solar | dark | laser per shot |\n| --- | --- | --- | --- | --- |\n| {} | {} | {} | {} | {} |\n",
            ph.total, ph.laser, ph.solar, ph.dark, num(Some(ph.laser_per_shot))
        );
    }
    text
}
