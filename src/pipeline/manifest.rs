//! `manifest.json`: per stage, its status, the fingerprint of its inputs, its outputs and
//! wall time; what `--resume` trusts.

use super::Stage;
use crate::error::Result;
use crate::fsutil::write_text_atomic;
use crate::progress::StageClock;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StageRecord {
    pub status: String,
    pub fingerprint: String,
    pub outputs: Vec<String>,
    pub wall_time_s: f64,
    /// The version of lidarsim that ran the stage: a resumed run's stages may be of several
    /// (empty in manifests written before it was recorded).
    #[serde(default)]
    pub tool_version: String,
    /// Process CPU time over the stage, all threads, s: over `wall_time_s` and the threads,
    /// the share of the cores it kept busy (absent where the OS does not tell, and in
    /// manifests written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_time_s: Option<f64>,
    /// Peak resident memory of the process that ran the stage, from its start to the
    /// stage's end, MiB: the last stage's is the run's peak (absent where the OS does not
    /// tell).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_memory_mib: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// The simulate stage: the pulses simulated by the invocation that wrote the record,
    /// fewer than the plan's when shards or an earlier invocation simulated the rest (its
    /// wall time is of those alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulses_simulated: Option<u64>,
    /// The checksum (`file_checksum`) of each output file as the stage wrote it (waveform parts excepted: each has
    /// its own beside it, written with it, see `waveform::file`), so that `--resume` never
    /// trusts a file damaged or replaced since.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub checksums: BTreeMap<String, String>,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Manifest {
    pub tool_version: String,
    pub campaign: String,
    pub stages: BTreeMap<String, StageRecord>,
}

impl Manifest {
    /// A run folder's manifest; None when it is absent or not a manifest.
    pub fn read(path: &Path) -> Option<Manifest> {
        serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
    }

    pub(super) fn done(&self, stage: Stage, fingerprint: &str) -> bool {
        self.stages
            .get(stage.name())
            .is_some_and(|r| r.status == "done" && r.fingerprint == fingerprint)
    }
}

pub(super) use crate::fsutil::{file_checksum, fingerprint};

pub(super) fn record(
    m: &mut Manifest,
    out: &Path,
    stage: Stage,
    fp: &str,
    outputs: Vec<String>,
    clock: StageClock,
    note: Option<String>,
) {
    let checksums = outputs
        .iter()
        .filter(|o| !o.starts_with("waveforms/"))
        .filter_map(|o| Some((o.clone(), file_checksum(&out.join(o))?)))
        .collect();
    m.stages.insert(
        stage.name().into(),
        StageRecord {
            status: "done".into(),
            fingerprint: fp.into(),
            outputs,
            wall_time_s: (clock.wall_s() * 1000.0).round() / 1000.0,
            tool_version: env!("CARGO_PKG_VERSION").into(),
            cpu_time_s: clock.cpu_s().map(|c| (c * 1000.0).round() / 1000.0),
            peak_memory_mib: crate::progress::peak_rss_bytes()
                .map(|b| (b as f64 / (1024.0 * 102.4)).round() / 10.0),
            note,
            pulses_simulated: None,
            checksums,
        },
    );
}

/// Forgets every stage one of whose files no longer matches what it wrote (damaged,
/// truncated, replaced), with every later stage; returns each such stage and its file.
pub(super) fn forget_damaged(m: &mut Manifest, out: &Path) -> Vec<(Stage, String)> {
    let mut damaged = Vec::new();
    for stage in Stage::ALL {
        let Some(r) = m.stages.get(stage.name()) else {
            continue;
        };
        let bad = r
            .checksums
            .iter()
            .find(|(f, sum)| file_checksum(&out.join(f)).as_deref() != Some(sum.as_str()));
        if let Some((f, _)) = bad {
            damaged.push((stage, f.clone()));
            if let Some(r) = m.stages.remove(stage.name()) {
                remove_products(out, stage, &r);
            }
            invalidate_after(m, out, stage);
        }
    }
    damaged
}

/// A stage redone makes every later stage stale; the files the products and report stages
/// wrote go with their records, so that no reader (`compare`, Python's `Run`) takes an older
/// run's points or DSM for this one's.
pub(super) fn invalidate_after(m: &mut Manifest, out: &Path, stage: Stage) {
    for s in Stage::ALL.into_iter().filter(|s| *s > stage) {
        if let Some(r) = m.stages.remove(s.name()) {
            remove_products(out, s, &r);
        }
    }
}

/// Removes the files a products or report stage's record lists (the waveform parts and the
/// plan stay: a resume checks those one by one). Only names inside the run folder.
pub(super) fn remove_products(out: &Path, stage: Stage, r: &StageRecord) {
    if stage < Stage::Products {
        return;
    }
    for o in &r.outputs {
        let rel = Path::new(o);
        let inside = rel
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
        if inside {
            let _ = std::fs::remove_file(out.join(rel));
            // a sub-folder it leaves empty (dsm/) goes too; one holding anything else stays
            if let Some(dir) = rel.parent().filter(|d| !d.as_os_str().is_empty()) {
                let _ = std::fs::remove_dir(out.join(dir));
            }
        }
    }
}

pub(super) fn save(path: &Path, m: &Manifest) -> Result<()> {
    write_text_atomic(path, &serde_json::to_string_pretty(m).unwrap_or_default())
}
