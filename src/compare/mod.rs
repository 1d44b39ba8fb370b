//! `lidarsim compare RUN_DIR...`: one table of products across runs (a sweep's folder stands
//! for all its sub-runs), as markdown, CSV, and plots of DSM error against altitude and pulse
//! rate (the paper's Fig. 6 f and h).

use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::pipeline::manifest::Manifest;
use crate::pipeline::sweep::SweepIndex;
use crate::products::figures::plot::{line_plot, Series};
use crate::products::raster::DsmReport;
use crate::products::report::summary::ProductsSummary;
use std::path::{Path, PathBuf};

/// One run's row.
#[derive(Clone, Debug, Default)]
pub struct RunRow {
    pub run: String,
    pub altitude_m: Option<f64>,
    pub prf_hz: Option<f64>,
    /// The planned pulses (`products.json`, or before the products `pulses.parquet`).
    pub pulses: Option<u64>,
    pub points: Option<u64>,
    pub points_per_pulse: Option<f64>,
    pub pulse_density_m2: Option<f64>,
    /// `simulation.rays_per_pulse` and `simulation.sampler` of the resolved campaign.
    pub rays_per_pulse: Option<u64>,
    pub sampler: Option<String>,
    /// The points' distance to the nearest surface (`products.json`, `surface_distance`).
    pub within_5cm: Option<f64>,
    pub within_25cm: Option<f64>,
    pub median_distance_m: Option<f64>,
    pub dsm_bias_m: Option<f64>,
    pub dsm_rmse_m: Option<f64>,
    pub dsm_coverage: Option<f64>,
    /// Overlapping strips' height differences over smooth cells (`products.json`, `strips`).
    pub strip_cells: Option<u64>,
    pub strip_rms_dz_m: Option<f64>,
    pub strip_max_mean_dz_m: Option<f64>,
    /// The stages' wall times, summed; none for a sweep's run not yet begun.
    pub run_time_s: Option<f64>,
}

/// The run folders a path stands for: itself, or a sweep's sub-runs in order.
pub fn expand(dir: &Path) -> Result<Vec<PathBuf>> {
    let index = dir.join("sweep.json");
    if let Some(sweep) = SweepIndex::read(&index) {
        return Ok(sweep.sweep.iter().map(|r| dir.join(r)).collect());
    }
    if index.is_file() {
        return Err(Error::data(
            &index,
            "not a sweep's index (cut short, edited, or naming folders outside the sweep's)",
        )
        .advise("run the sweep's campaign again with --resume: it writes the index"));
    }
    if dir.join("manifest.json").is_file() {
        return Ok(vec![dir.to_path_buf()]);
    }
    Err(Error::file(
        dir,
        "not a run folder: it has no manifest.json (nor sweep.json); run `lidarsim run` first",
    ))
}

/// The rows of the runs and sweeps `runs` names, in order (see [`expand`]). A run is named
/// by its folder's name, or by its path as given where two runs' folders share a name
/// (`a/run` and `b/run`).
pub fn rows(runs: &[PathBuf]) -> Result<Vec<RunRow>> {
    let mut rows = Vec::new();
    let mut dirs = Vec::new();
    for r in runs {
        for dir in expand(r)? {
            rows.push(read_row(&dir)?);
            if let Some(why) = unfinished(&dir) {
                crate::progress::log(&format!(
                    "compare: {}: {why}: its empty cells are figures not made yet (`lidarsim run` with --resume finishes it)",
                    dir.display()
                ));
            }
            dirs.push(dir);
        }
    }
    let names: Vec<String> = rows.iter().map(|r| r.run.clone()).collect();
    for (row, dir) in rows.iter_mut().zip(&dirs) {
        if names.iter().filter(|n| **n == row.run).count() > 1 {
            row.run = dir.display().to_string();
        }
    }
    Ok(rows)
}

/// Why a run's row is not whole, if it is not: no manifest (not begun), or the last stage
/// that has not run to its end.
fn unfinished(dir: &Path) -> Option<String> {
    let Some(m) = Manifest::read(&dir.join("manifest.json")) else {
        return Some("not begun".into());
    };
    crate::pipeline::Stage::ALL
        .iter()
        .find(|s| m.stages.get(s.name()).is_none_or(|r| r.status != "done"))
        .map(|s| format!("stage {} not done", s.name()))
}

/// One run's row. A sweep's sub-run not yet begun (no folder, or no manifest in it) is a row
/// of empty cells: a sweep stopped early is compared as far as it went.
pub fn read_row(dir: &Path) -> Result<RunRow> {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let manifest_path = dir.join("manifest.json");
    if !manifest_path.exists() {
        return Ok(RunRow {
            run: name,
            ..RunRow::default()
        });
    }
    let manifest = Manifest::read(&manifest_path)
        .ok_or_else(|| Error::data(&manifest_path, "missing or not a lidarsim manifest"))?;
    // a run stopped before its plan has none (its cells stay empty); one that is there but
    // damaged is said, not shown as empty cells
    let resolved_path = dir.join("campaign.resolved.yaml");
    let resolved: serde_yaml::Value = match std::fs::read_to_string(&resolved_path) {
        Err(_) => serde_yaml::Value::Null,
        Ok(t) => match serde_yaml::from_str::<serde_yaml::Value>(&t) {
            Ok(v) if v.is_mapping() => v,
            _ => {
                return Err(
                    Error::data(&resolved_path, "damaged: not a resolved campaign")
                        .advise("run the campaign again with --resume: its plan stage writes it"),
                )
            }
        },
    };
    // a figure with no meaning for the run (NaN in memory, null in JSON) is an empty cell
    let finite = |x: f64| Some(x).filter(|x| x.is_finite());
    let mut row = RunRow {
        run: name,
        altitude_m: resolved["platform"]["altitude_m"].as_f64(),
        prf_hz: resolved["platform"]["prf_hz"].as_f64(),
        rays_per_pulse: resolved["simulation"]["rays_per_pulse"].as_u64(),
        sampler: resolved["simulation"]["sampler"]
            .as_str()
            .map(str::to_owned),
        run_time_s: Some(manifest.stages.values().map(|s| s.wall_time_s).sum()),
        ..RunRow::default()
    };
    // a file that is there but not ours (cut short, edited) is an error, not an empty row
    let present = |name: &str| Some(dir.join(name)).filter(|p| p.is_file());
    let unreadable = |path: &Path| {
        Error::data(
            path,
            "not a lidarsim file (cut short or edited?): run the products stage again with \
             `lidarsim run CAMPAIGN --out RUN --resume --stages products`",
        )
    };
    let products = match present("products.json") {
        Some(path) => Some(ProductsSummary::read(&path).ok_or_else(|| unreadable(&path))?),
        None => None,
    };
    let dsm = match present("dsm/report.json") {
        Some(path) => Some(DsmReport::read(&path).ok_or_else(|| unreadable(&path))?),
        None => None,
    };
    // before its products, a run's pulses are its plan's
    row.pulses = match present("pulses.parquet") {
        Some(path) if products.is_none() => Some(planned_pulses(&path).ok_or_else(|| {
            Error::data(&path, "not a lidarsim file (cut short or edited?)")
                .advise("run its plan again with `lidarsim run CAMPAIGN --out RUN --resume`")
        })?),
        _ => None,
    };
    if let Some(p) = products {
        row.pulses = Some(p.pulses as u64);
        if let Some(s) = &p.strips {
            row.strip_cells = Some(s.cells as u64);
            row.strip_rms_dz_m = s.rms_dz_m.and_then(finite);
            // the pair furthest apart on average: a strip's offset
            row.strip_max_mean_dz_m = s
                .pairs
                .iter()
                .map(|q| q.mean_dz_m)
                .max_by(|a, b| a.abs().total_cmp(&b.abs()));
        }
        if let Some(pts) = p.points {
            row.points = Some(pts.points as u64);
            row.points_per_pulse = finite(pts.points_per_pulse);
            row.pulse_density_m2 = pts.pulse_density_per_m2.and_then(finite);
            if let Some(d) = pts.surface_distance {
                row.within_5cm = finite(d.within_5cm);
                row.within_25cm = finite(d.within_25cm);
                row.median_distance_m = finite(d.median_m);
            }
        }
    }
    if let Some(d) = dsm {
        row.dsm_bias_m = finite(d.bias_m);
        row.dsm_rmse_m = finite(d.rmse_m);
        row.dsm_coverage = finite(d.coverage);
    }
    Ok(row)
}

/// The rows of a Parquet file, from its footer.
fn planned_pulses(path: &Path) -> Option<u64> {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let reader = SerializedFileReader::new(std::fs::File::open(path).ok()?).ok()?;
    u64::try_from(reader.metadata().file_metadata().num_rows()).ok()
}

fn cell(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite())
        .map(|x| format!("{x:.digits$}"))
        .unwrap_or_else(|| "–".into())
}

/// The table as markdown: the CSV's columns ([`CSV_COLUMNS`]) in its order, with units in
/// the headers, percentages, millimetres and fixed digits.
pub fn markdown(rows: &[RunRow]) -> String {
    let mut s = String::from(
        "| run | altitude m | PRF Hz | pulses | points | points/pulse | pulses/m² | DSM bias m | DSM RMSE m | coverage | run s | rays | sampler | within 5 cm | within 25 cm | median distance mm | strip cells | strip RMS dz m | strip max mean dz m |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    let percent =
        |v: Option<f64>| cell(v.map(|x| 100.0 * x), 2) + if v.is_some() { " %" } else { "" };
    let count = |n: Option<u64>| cell(n.map(|n| n as f64), 0);
    for r in rows {
        s += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.run,
            cell(r.altitude_m, 0),
            cell(r.prf_hz, 0),
            count(r.pulses),
            count(r.points),
            cell(r.points_per_pulse, 3),
            cell(r.pulse_density_m2, 1),
            cell(r.dsm_bias_m, 3),
            cell(r.dsm_rmse_m, 3),
            cell(r.dsm_coverage, 3),
            cell(r.run_time_s, 1),
            count(r.rays_per_pulse),
            r.sampler.as_deref().unwrap_or("–"),
            percent(r.within_5cm),
            percent(r.within_25cm),
            cell(r.median_distance_m.map(|m| 1e3 * m), 3),
            count(r.strip_cells),
            cell(r.strip_rms_dz_m, 3),
            cell(r.strip_max_mean_dz_m, 3),
        );
    }
    s
}

/// The columns of the CSV table, in order.
pub const CSV_COLUMNS: [&str; 19] = [
    "run",
    "altitude_m",
    "prf_hz",
    "pulses",
    "points",
    "points_per_pulse",
    "pulse_density_per_m2",
    "dsm_bias_m",
    "dsm_rmse_m",
    "dsm_coverage",
    "run_time_s",
    "rays_per_pulse",
    "sampler",
    "within_5cm",
    "within_25cm",
    "median_distance_m",
    "strip_cells",
    "strip_rms_dz_m",
    "strip_max_mean_dz_m",
];

/// The CSV table's columns as an Arrow table: text, unsigned counts and floats, null where
/// the CSV cell is empty.
pub fn table(rows: &[RunRow]) -> arrow_array::RecordBatch {
    use arrow_array::{ArrayRef, Float64Array, StringArray, UInt64Array};
    use std::sync::Arc;
    let f = |g: fn(&RunRow) -> Option<f64>| -> ArrayRef {
        Arc::new(Float64Array::from_iter(rows.iter().map(g)))
    };
    let u = |g: fn(&RunRow) -> Option<u64>| -> ArrayRef {
        Arc::new(UInt64Array::from_iter(rows.iter().map(g)))
    };
    let t = |g: fn(&RunRow) -> Option<String>| -> ArrayRef {
        Arc::new(StringArray::from_iter(rows.iter().map(g)))
    };
    let columns: [ArrayRef; 19] = [
        t(|r| Some(r.run.clone())),
        f(|r| r.altitude_m),
        f(|r| r.prf_hz),
        u(|r| r.pulses),
        u(|r| r.points),
        f(|r| r.points_per_pulse),
        f(|r| r.pulse_density_m2),
        f(|r| r.dsm_bias_m),
        f(|r| r.dsm_rmse_m),
        f(|r| r.dsm_coverage),
        f(|r| r.run_time_s),
        u(|r| r.rays_per_pulse),
        t(|r| r.sampler.clone()),
        f(|r| r.within_5cm),
        f(|r| r.within_25cm),
        f(|r| r.median_distance_m),
        u(|r| r.strip_cells),
        f(|r| r.strip_rms_dz_m),
        f(|r| r.strip_max_mean_dz_m),
    ];
    crate::parquet_io::batch(CSV_COLUMNS.iter().copied().zip(columns).collect())
}

/// Writes the table as CSV (run names quoted when they need it).
pub fn write_csv(path: &Path, rows: &[RunRow]) -> Result<()> {
    let o = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
    let header = CSV_COLUMNS;
    let table = rows.iter().map(|r| {
        vec![
            r.run.clone(),
            o(r.altitude_m),
            o(r.prf_hz),
            r.pulses.map(|x| x.to_string()).unwrap_or_default(),
            r.points.map(|x| x.to_string()).unwrap_or_default(),
            o(r.points_per_pulse),
            o(r.pulse_density_m2),
            o(r.dsm_bias_m),
            o(r.dsm_rmse_m),
            o(r.dsm_coverage),
            o(r.run_time_s),
            r.rays_per_pulse.map(|n| n.to_string()).unwrap_or_default(),
            r.sampler.clone().unwrap_or_default(),
            o(r.within_5cm),
            o(r.within_25cm),
            o(r.median_distance_m),
            r.strip_cells.map(|x| x.to_string()).unwrap_or_default(),
            o(r.strip_rms_dz_m),
            o(r.strip_max_mean_dz_m),
        ]
    });
    crate::fsutil::write_csv_atomic(path, &header, table)
}

/// DSM bias and RMSE against altitude (one line per pulse rate) and against pulse rate (one
/// line per altitude).
pub fn plots(rows: &[RunRow], dir: &Path) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for (name, x_of, group_of, x_label, group_label) in [
        (
            "dsm_error_vs_altitude.svg",
            0usize,
            1usize,
            "altitude (m)",
            "PRF",
        ),
        ("dsm_error_vs_prf.svg", 1, 0, "pulse rate (Hz)", "H"),
    ] {
        let key = |r: &RunRow, i: usize| if i == 0 { r.altitude_m } else { r.prf_hz };
        let mut groups: Vec<f64> = rows.iter().filter_map(|r| key(r, group_of)).collect();
        groups.sort_by(|a, b| a.total_cmp(b));
        groups.dedup();
        if groups.is_empty() {
            groups.push(f64::NAN);
        }
        let mut series = Vec::new();
        for g in &groups {
            let mut pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| key(r, group_of).is_none_or(|v| v == *g || g.is_nan()))
                .filter_map(|r| Some((key(r, x_of)?, r.dsm_rmse_m?)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            if pts.len() >= 2 {
                let label = if g.is_nan() {
                    "RMSE".to_string()
                } else {
                    format!("RMSE, {group_label} {g}")
                };
                series.push(Series {
                    name: label,
                    points: pts,
                });
            }
        }
        if series.is_empty() {
            continue;
        }
        let path = dir.join(name);
        let svg = line_plot(&path, "DSM error", x_label, "RMSE (m)", &series)?;
        write_text_atomic(&path, &svg)?;
        written.push(path);
    }
    Ok(written)
}
