//! `sweep:`: one sub-run per combination of values, in sub-folders named after them, sharing
//! one scene load; `sweep.csv`, `sweep.json` and plots against a single swept key.

use super::{run_single, RunOptions, RunSummary, SceneCache};
use crate::campaign::yaml::inline;
use crate::campaign::{Campaign, Loaded};
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan;
use crate::products::figures::plot::{line_plot, Series};
use crate::progress::log;
use crate::scene::Scene;
use crate::waveform::file::{part_name, read_waveforms};
use std::collections::BTreeMap;
use std::path::Path;

/// One sub-run per combination of the sweep's values, in sub-folders named after them.
pub(super) fn run_sweep(
    loaded: &Loaded,
    sweep: &BTreeMap<String, Vec<serde_yaml::Value>>,
    out: &Path,
    opts: &RunOptions,
) -> Result<RunSummary> {
    let (keys, combos) = combinations(loaded, sweep)?;
    // every combination is checked before any runs, its memory too: a bad value ends the
    // run at once
    let subs = sub_campaigns(loaded, &keys, &combos)?;
    let mut cache = SceneCache::default();
    let scene = cache.get(&loaded.scene_path, loaded.campaign.wavelength_nm.all())?;
    fits_each(loaded, &keys, &combos, &subs, scene)?;
    let mut total = RunSummary {
        out: out.to_path_buf(),
        pulses: 0,
        rays: 0,
        seconds: 0.0,
        parts_done: 0,
        complete: true,
    };
    // the index first: a sweep stopped midway is a sweep `compare` reads (its runs not begun
    // are empty rows)
    let index = SweepIndex {
        campaign: loaded.campaign.name.clone(),
        sweep: subs.iter().map(|(_, name)| name.clone()).collect(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
    };
    write_text_atomic(
        &out.join("sweep.json"),
        &serde_json::to_string_pretty(&index).unwrap_or_default(),
    )?;
    let mut rows: Vec<(Vec<serde_yaml::Value>, RunTotals)> = Vec::new();
    for (combo, (sub, name)) in combos.iter().zip(subs) {
        log(&format!("sweep: {name}"));
        let s = run_single(&sub, &out.join(&name), opts, &mut cache)?;
        total.pulses += s.pulses;
        total.rays += s.rays;
        total.seconds += s.seconds;
        total.parts_done += s.parts_done;
        total.complete &= s.complete;
        // a run whose simulation is not whole (a plan alone, a shard's share) is a row of its
        // planned pulses and empty cells, as `compare` gives it, not of zeros
        let simulated = super::Manifest::read(&out.join(&name).join("manifest.json"))
            .and_then(|m| m.stages.get(super::Stage::Simulate.name()).cloned())
            .is_some_and(|r| r.status == "done");
        let totals = if simulated {
            RunTotals::read(&out.join(&name))?
        } else {
            RunTotals {
                pulses: s.pulses,
                received_energy_j: f64::NAN,
                solar_photons_per_bin: f64::NAN,
                brf_fov_solar: f64::NAN,
                brf_footprint_laser: f64::NAN,
            }
        };
        rows.push((combo.iter().map(|v| (*v).clone()).collect(), totals));
    }
    write_sweep_summary(out, &keys, &rows)?;
    Ok(total)
}

/// Every sub-run of a sweep over `scene`, checked as the run checks them (its memory bound
/// included), with its sub-folder's name, in the order the run takes them (`lidarsim check`
/// estimates them all).
pub fn sweep_runs(
    loaded: &Loaded,
    sweep: &BTreeMap<String, Vec<serde_yaml::Value>>,
    scene: &Scene,
) -> Result<Vec<(Loaded, String)>> {
    let (keys, combos) = combinations(loaded, sweep)?;
    let subs = sub_campaigns(loaded, &keys, &combos)?;
    fits_each(loaded, &keys, &combos, &subs, scene)?;
    Ok(subs)
}

/// Each combination's bands against the scene's materials, and its memory bound against the
/// machine's ([`super::memory::fits`]); one that cannot run is refused at the swept value
/// (the scene is the same for every combination: a sweep cannot sweep it).
fn fits_each(
    loaded: &Loaded,
    keys: &[&String],
    combos: &[Vec<&serde_yaml::Value>],
    subs: &[(Loaded, String)],
    scene: &Scene,
) -> Result<()> {
    for (combo, (sub, name)) in combos.iter().zip(subs) {
        // a swept band the scene's materials do not give
        let bands = sub.campaign.wavelength_nm.all();
        if bands != loaded.campaign.wavelength_nm.all() {
            Scene::check_bands(&sub.scene_path, bands).map_err(|e| {
                match keys
                    .iter()
                    .zip(combo)
                    .find(|(k, _)| k.as_str() == "wavelength_nm")
                {
                    Some((k, v)) => loaded
                        .doc
                        .sweep_error(k, format!("value {}: the scene: {e}", inline(v))),
                    None => e.within(format!("in the sweep combination {name}")),
                }
            })?;
        }
        let plan = plan::Plan::new(&sub.campaign)?;
        super::memory::fits(sub, scene, &plan)
            .map_err(|e| at_swept_key(loaded, keys, combo, name, e))?;
    }
    Ok(())
}

/// An error in one combination's campaign, at the entry under `sweep:` of the swept key it
/// names (or a key within it), else said to be of that combination.
fn at_swept_key(
    loaded: &Loaded,
    keys: &[&String],
    combo: &[&serde_yaml::Value],
    name: &str,
    e: Error,
) -> Error {
    let swept = e.key.as_deref().and_then(|ek| {
        keys.iter()
            .zip(combo)
            .find(|(k, _)| ek == k.as_str() || ek.starts_with(&format!("{k}.")))
    });
    match swept {
        Some((k, v)) => loaded
            .doc
            .sweep_error(k, format!("value {}: {}", inline(v), e.message)),
        None => e.within(format!("in the sweep combination {name}")),
    }
}

fn sub_campaigns(
    loaded: &Loaded,
    keys: &[&String],
    combos: &[Vec<&serde_yaml::Value>],
) -> Result<Vec<(Loaded, String)>> {
    let subs: Vec<(Loaded, String)> = combos
        .iter()
        .map(|combo| sub_campaign(loaded, keys, combo))
        .collect::<Result<_>>()?;
    // a folder's name is at most 255 bytes on the usual file systems: a long list of values
    // would end the sweep at its run, not here
    if let Some((_, name)) = subs.iter().find(|(_, n)| n.len() > MAX_FOLDER_NAME) {
        return Err(loaded.doc.error(
            "sweep",
            format!(
                "a combination's folder name is {} bytes, more than {MAX_FOLDER_NAME}: sweep \
                 shorter values, or fewer keys at once ({}...)",
                name.len(),
                name.chars().take(60).collect::<String>()
            ),
        ));
    }
    Ok(subs)
}

/// The longest name a sub-run's folder may take, bytes.
const MAX_FOLDER_NAME: usize = 255;

/// Most runs one sweep makes: each is a whole run with its own folder, and every
/// combination is checked (and held) before the first starts.
const MAX_SWEEP_RUNS: usize = 10_000;

/// The swept keys in the order the file gives them, and every combination of their values
/// (the last key varying fastest).
#[allow(clippy::type_complexity)]
fn combinations<'a>(
    loaded: &Loaded,
    sweep: &'a BTreeMap<String, Vec<serde_yaml::Value>>,
) -> Result<(Vec<&'a String>, Vec<Vec<&'a serde_yaml::Value>>)> {
    let mut keys: Vec<&String> = sweep.keys().collect();
    // (a dotted key is one YAML key here, so look for its text after `sweep:`)
    let sweep_at = loaded.doc.text.find("sweep:").unwrap_or(0);
    keys.sort_by_key(|k| {
        loaded.doc.text[sweep_at..]
            .find(k.as_str())
            .unwrap_or(usize::MAX)
    });
    for k in &keys {
        let values = &sweep[*k];
        if values.is_empty() {
            return Err(loaded.doc.sweep_error(k, "the list of values is empty"));
        }
        if k.is_empty() {
            return Err(loaded.doc.sweep_error(
                k,
                "a key is empty: name a campaign key, such as platform.altitude_m",
            ));
        }
        if k.as_str() == "sweep" || k.starts_with("sweep.") {
            return Err(loaded
                .doc
                .sweep_error(k, "a sweep cannot sweep its own `sweep:` section"));
        }
        if k.as_str() == "scene" || k.starts_with("scene.") {
            return Err(loaded.doc.sweep_error(
                k,
                "the scene cannot be swept (a sweep's runs share one scene): run one campaign per scene",
            ));
        }
        // two equal values would name one sub-folder twice
        if let Some(v) = values
            .iter()
            .enumerate()
            .find_map(|(i, v)| values[..i].contains(v).then_some(v))
        {
            return Err(loaded
                .doc
                .sweep_error(k, format!("value {} is listed twice", inline(v))));
        }
        // two values would name one sub-folder ('a b' and 'a-b' both make a-b)
        if let Some((a, b)) = values.iter().enumerate().find_map(|(i, v)| {
            values[..i]
                .iter()
                .find(|u| in_folder_name(u) == in_folder_name(v))
                .map(|u| (u, v))
        }) {
            return Err(loaded.doc.sweep_error(
                k,
                format!(
                    "values {} and {} would name one folder ({}): give values that differ \
                     in more than spaces and slashes",
                    inline(a),
                    inline(b),
                    in_folder_name(a)
                ),
            ));
        }
    }
    if keys.is_empty() {
        return Err(loaded.doc.error(
            "sweep",
            "no key to sweep: give keys and their values (platform.altitude_m: [250, 500]), or \
             leave `sweep:` out",
        ));
    }
    let runs = keys
        .iter()
        .try_fold(1usize, |n, k| n.checked_mul(sweep[*k].len()))
        .filter(|&n| n <= MAX_SWEEP_RUNS);
    if runs.is_none() {
        let lens: Vec<String> = keys.iter().map(|k| sweep[*k].len().to_string()).collect();
        return Err(loaded.doc.error(
            "sweep",
            format!(
                "{} combinations: a sweep runs at most {MAX_SWEEP_RUNS}; split it into several campaigns",
                lens.join(" × ")
            ),
        ));
    }
    let mut combos: Vec<Vec<&serde_yaml::Value>> = vec![vec![]];
    for k in &keys {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                sweep[*k].iter().map(move |v| {
                    let mut c = c.clone();
                    c.push(v);
                    c
                })
            })
            .collect();
    }
    Ok((keys, combos))
}

/// The campaign of one combination, checked, and its sub-folder's name (`key=value_...`). A
/// value the campaign rejects is reported at its entry under `sweep:`.
fn sub_campaign(
    loaded: &Loaded,
    keys: &[&String],
    combo: &[&serde_yaml::Value],
) -> Result<(Loaded, String)> {
    let mut tree = serde_yaml::to_value(&loaded.campaign).map_err(|e| Error::msg(e.to_string()))?;
    let mut names = Vec::new();
    for (k, v) in keys.iter().zip(combo) {
        crate::campaign::yaml::set_path(&mut tree, k, (*v).clone())
            .map_err(|m| loaded.doc.sweep_error(k, m))?;
        names.push(format!(
            "{}={}",
            k.rsplit('.').next().unwrap_or(k),
            folder_value(v)
        ));
    }
    if let serde_yaml::Value::Mapping(m) = &mut tree {
        m.remove("sweep");
    }
    let mut campaign: Campaign = serde_path_to_error::deserialize(tree).map_err(|e| {
        // at the swept key the value went to, or whose field it does not know
        let at = e.path().to_string();
        let message = crate::campaign::yaml::plain_words(&e.into_inner().to_string());
        let swept = keys.iter().zip(combo).find(|(k, _)| {
            at == k.as_str()
                || at.starts_with(&format!("{k}."))
                || message.contains(&format!("`{}`", k.rsplit('.').next().unwrap_or(k)))
        });
        match swept {
            Some((k, v)) => loaded
                .doc
                .sweep_error(k, format!("value {}: {message}", inline(v))),
            None => loaded.doc.error(
                "sweep",
                format!("a combination does not make a valid campaign: {at}: {message}"),
            ),
        }
    })?;
    campaign.resolve_files(&loaded.doc);
    plan::check_campaign(&loaded.doc, &campaign)
        .map_err(|e| at_swept_key(loaded, keys, combo, &names.join(", "), e))?;
    let sub = Loaded {
        campaign,
        doc: loaded.doc.clone(),
        scene_path: loaded.scene_path.clone(),
        method_note: None,
    };
    let name = names.join("_").replace(FOLDER_UNSAFE, "-");
    Ok((sub, name))
}

/// What a sub-folder's name writes as `-`: a path's separators, and spaces.
const FOLDER_UNSAFE: [char; 3] = ['/', '\\', ' '];

/// A swept value as it ends up in the sub-folder's name ([`folder_value`], its separators and
/// spaces made `-`): two values equal here would name one folder.
fn in_folder_name(v: &serde_yaml::Value) -> String {
    folder_value(v).replace(FOLDER_UNSAFE, "-")
}

/// A swept value as it stands in a sub-folder's name: a scalar as YAML writes it, a list's
/// items joined by commas (`[-4.5, 4.5]` → `-4.5,4.5`), a mapping's as `key:value`; never a
/// line break or a space, which YAML's block style would put in a name.
fn folder_value(v: &serde_yaml::Value) -> String {
    use serde_yaml::Value;
    match v {
        Value::Sequence(items) => items.iter().map(folder_value).collect::<Vec<_>>().join(","),
        Value::Mapping(m) => m
            .iter()
            .map(|(k, v)| format!("{}:{}", folder_value(k), folder_value(v)))
            .collect::<Vec<_>>()
            .join(","),
        Value::Tagged(t) => folder_value(&t.value),
        v => serde_yaml::to_string(v)
            .unwrap_or_default()
            .trim()
            .chars()
            .map(|c| {
                if c.is_whitespace() || c.is_control() {
                    '-'
                } else {
                    c
                }
            })
            .collect(),
    }
}

/// `sweep.json`: the sub-runs of a sweep, in order (fields in the file's sorted key order).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepIndex {
    pub campaign: String,
    /// Sub-folder of each combination.
    pub sweep: Vec<String>,
    pub tool_version: String,
}

impl SweepIndex {
    /// A sweep folder's `sweep.json`; None when it is absent or not ours. Each run is a
    /// sub-folder of the sweep's by a plain name (no separator, not `..`): an index naming
    /// anything else is not one a sweep wrote.
    pub fn read(path: &Path) -> Option<SweepIndex> {
        let index: SweepIndex = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
        let plain =
            |n: &str| !n.is_empty() && n != "." && n != ".." && !n.contains(['/', '\\', '\0']);
        index.sweep.iter().all(|n| plain(n)).then_some(index)
    }
}

/// Means over a run's pulses of what a sweep compares.
#[derive(Clone, Debug, Default)]
pub struct RunTotals {
    pub pulses: usize,
    pub received_energy_j: f64,
    pub solar_photons_per_bin: f64,
    pub brf_fov_solar: f64,
    pub brf_footprint_laser: f64,
}

impl RunTotals {
    pub fn read(run: &Path) -> Result<RunTotals> {
        let mut t = RunTotals::default();
        // with several bands, the first band's rows (the first row's band: pulse 0's first)
        let mut first_band = None;
        // a BRF is null (read as NaN) where it has no meaning (no sun; a pulse that received
        // no laser energy): its mean is over the pulses that have one, as report.md's
        let (mut solar_n, mut laser_n) = (0usize, 0usize);
        // the parts by index (part-00000, part-00001, ...), as every stage reads them
        for k in 0.. {
            let f = run.join(part_name(k));
            if !f.is_file() {
                break;
            }
            for w in read_waveforms(&f)? {
                if *first_band.get_or_insert(w.wavelength_nm) != w.wavelength_nm {
                    continue;
                }
                t.pulses += 1;
                t.received_energy_j += w.received_energy_j;
                t.solar_photons_per_bin += w.solar_photons_per_bin as f64;
                if w.brf_fov_solar.is_finite() {
                    t.brf_fov_solar += w.brf_fov_solar as f64;
                    solar_n += 1;
                }
                if w.brf_footprint_laser.is_finite() {
                    t.brf_footprint_laser += w.brf_footprint_laser as f64;
                    laser_n += 1;
                }
            }
        }
        let n = t.pulses.max(1) as f64;
        t.received_energy_j /= n;
        t.solar_photons_per_bin /= n;
        // NaN (an empty cell, no point on a plot) where no pulse has one
        let mean = |sum: f64, n: usize| if n > 0 { sum / n as f64 } else { f64::NAN };
        t.brf_fov_solar = mean(t.brf_fov_solar, solar_n);
        t.brf_footprint_laser = mean(t.brf_footprint_laser, laser_n);
        Ok(t)
    }
}

/// `sweep.csv`, one row per combination, and with a single numeric swept key, plots of the
/// signal and the BRFs against it.
pub(super) fn write_sweep_summary(
    out: &Path,
    keys: &[&String],
    rows: &[(Vec<serde_yaml::Value>, RunTotals)],
) -> Result<()> {
    let mut header: Vec<&str> = keys.iter().map(|k| k.as_str()).collect();
    header.extend([
        "pulses",
        "received_energy_j",
        "solar_photons_per_bin",
        "brf_fov_solar",
        "brf_footprint_laser",
    ]);
    // a value with no meaning for the run is an empty cell, not "NaN"
    let cell = |v: f64, e: bool| match (v.is_finite(), e) {
        (false, _) => String::new(),
        (true, true) => format!("{v:.6e}"),
        (true, false) => format!("{v:.6}"),
    };
    let table = rows.iter().map(|(vals, t)| {
        let mut row: Vec<String> = vals.iter().map(inline).collect();
        row.extend([
            t.pulses.to_string(),
            cell(t.received_energy_j, true),
            cell(t.solar_photons_per_bin, true),
            cell(t.brf_fov_solar, false),
            cell(t.brf_footprint_laser, false),
        ]);
        row
    });
    crate::fsutil::write_csv_atomic(&out.join("sweep.csv"), &header, table)?;
    if keys.len() != 1 || rows.len() < 2 {
        return Ok(());
    }
    let xs: Option<Vec<f64>> = rows.iter().map(|(v, _)| v[0].as_f64()).collect();
    let Some(xs) = xs else { return Ok(()) };
    let key = keys[0].as_str();
    let series = |name: &str, f: &dyn Fn(&RunTotals) -> f64| Series {
        name: name.into(),
        points: xs.iter().zip(rows).map(|(x, (_, t))| (*x, f(t))).collect(),
    };
    let plot = |name: &str, title: &str, y_label: &str, series: &[Series]| {
        let path = out.join(name);
        let svg = line_plot(&path, title, key, y_label, series)?;
        write_text_atomic(&path, &svg)
    };
    plot(
        "sweep_energy.svg",
        "Received laser energy",
        "J per pulse",
        &[series("laser", &|t| t.received_energy_j)],
    )?;
    if rows.iter().any(|(_, t)| t.solar_photons_per_bin > 0.0) {
        plot(
            "sweep_solar.svg",
            "Solar background",
            "solar photons per bin",
            &[series("N_SN", &|t| t.solar_photons_per_bin)],
        )?;
        plot(
            "sweep_brf.svg",
            "Scene BRF",
            "BRF",
            &[
                series("field of view, solar (Eq. 20)", &|t| t.brf_fov_solar),
                series("footprint, laser", &|t| t.brf_footprint_laser),
            ],
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::folder_value;

    /// A swept value names its sub-folder on one line and without spaces: a list's items
    /// joined by commas (YAML's block style would put a line break in the name), a
    /// mapping's as key:value, a scalar as YAML writes it.
    #[test]
    fn swept_values_name_folders_on_one_line() {
        let v = |t: &str| serde_yaml::from_str::<serde_yaml::Value>(t).unwrap();
        assert_eq!(folder_value(&v("250")), "250");
        assert_eq!(folder_value(&v("-4.5")), "-4.5");
        assert_eq!(folder_value(&v("[-4.5, 4.5]")), "-4.5,4.5");
        assert_eq!(folder_value(&v("[[0, 1], [2, 3]]")), "0,1,2,3");
        assert_eq!(folder_value(&v("{ a: 1, b: [2, 3] }")), "a:1,b:2,3");
        assert_eq!(folder_value(&v("'two words'")), "two-words");
        assert_eq!(folder_value(&v("line")), "line");
    }
}
