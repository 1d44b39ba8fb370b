//! Waveform part files of a run folder (outputs.md): `waveforms/part-NNNNN.parquet`, one row
//! per pulse, or per pulse and band with several bands (a `wavelength_nm` column then).

use super::Waveform;
use crate::error::{Error, Result};
use crate::fsutil::Pending;
use crate::parquet_io::{Column, Table};
use crate::scene::SurfaceClass;
use arrow_array::Array;
use arrow_schema::DataType;
use std::path::Path;

/// Fewest and most pulses a part file holds.
const MIN_PART_PULSES: usize = 1000;
const MAX_PART_PULSES: usize = 4000;
/// Rays a part is traced with, about: at more rays per pulse a part of the fewest pulses
/// is already seconds of work, whose files cost nothing beside it.
const PART_RAYS: f64 = 100_000.0;
/// Bytes of waveforms a part holds in memory, at most beyond the fewest pulses: a few parts
/// are in memory at once in either stage (see `pipeline::memory`).
const PART_BYTES: f64 = 64e6;

/// How a run's pulses are cut into part files: parts of `size` pulses, the last one shorter.
/// Each part costs the same few milliseconds whatever it holds (its files created, synced and
/// renamed, a compression context per column written and read, the workers meeting at its
/// end), which on a survey of cheap pulses is a measurable share of the run's CPU and wall
/// time (the figures are in the commit that made the choice).
/// So a part holds a thousand pulses, or up to four thousand where they are cheap: few rays
/// and short gates. The size is a function of the campaign, scene and plan, which the
/// simulation's fingerprint covers, so a resume and every shard cut the same parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Parts {
    pulses: usize,
    size: usize,
}

impl Parts {
    /// The parts of a run: sized by its rays per pulse and its waveforms' bytes per pulse
    /// ([`pulse_bytes`] of its first pulse's gate).
    pub fn of_run(
        loaded: &crate::campaign::Loaded,
        scene: &crate::scene::Scene,
        plan: &crate::plan::Plan,
    ) -> Parts {
        let bytes = pulse_bytes(loaded, gate_bins(loaded, scene, plan));
        let size = part_size(loaded.campaign.simulation.rays_per_pulse, bytes);
        Parts::with_size(plan.len(), size)
    }

    /// `pulses` cut into parts of `size` (at least one pulse each).
    pub fn with_size(pulses: usize, size: usize) -> Parts {
        Parts {
            pulses,
            size: size.max(1),
        }
    }

    /// Pulses a part holds (the last may hold fewer).
    pub fn size(self) -> usize {
        self.size
    }

    /// Pulses of the run.
    pub fn pulses(self) -> usize {
        self.pulses
    }

    /// Part files of the run.
    pub fn count(self) -> usize {
        self.pulses.div_ceil(self.size)
    }

    /// The pulses of part `k`.
    pub fn range(self, k: usize) -> std::ops::Range<usize> {
        (k * self.size).min(self.pulses)..((k + 1) * self.size).min(self.pulses)
    }
}

/// Pulses of a part of pulses of `rays` rays and `bytes` of waveforms each (see [`Parts`]): as
/// many thousands as [`PART_RAYS`] and [`PART_BYTES`] allow, within the fewest and most.
fn part_size(rays: u64, bytes: f64) -> usize {
    let fits = (PART_RAYS / rays.max(1) as f64).min(PART_BYTES / bytes.max(1.0));
    // in thousands, so that part k starts at a round pulse
    let thousands = (fits / 1000.0).floor() as usize * 1000;
    thousands.clamp(MIN_PART_PULSES, MAX_PART_PULSES)
}

/// Bins of the gate of a run's first pulse (0 without pulses).
pub fn gate_bins(
    loaded: &crate::campaign::Loaded,
    scene: &crate::scene::Scene,
    plan: &crate::plan::Plan,
) -> usize {
    if plan.is_empty() {
        return 0;
    }
    let p = plan.pulse(0);
    let near = scene.bounds_near(p.origin, p.direction);
    crate::sensor::Gate::for_pulse(&loaded.campaign.instrument, p.origin, p.direction, near).bins
}

/// Bytes of a pulse's waveform rows in memory, about: one row ([`waveform_bytes`]) per band,
/// over a gate of `bins`.
pub fn pulse_bytes(loaded: &crate::campaign::Loaded, bins: usize) -> f64 {
    let c = &loaded.campaign;
    waveform_bytes(bins, c.simulation.max_order.cap()) * c.wavelength_nm.all().len() as f64
}

/// Bytes of one waveform row in memory, about: photons, impulse energy and its error, four
/// classes (f32 each, a gate of `bins`), and energies by order with their errors (f64).
pub fn waveform_bytes(bins: usize, max_order: u32) -> f64 {
    bins as f64 * 4.0 * (3.0 + 4.0) + max_order as f64 * 16.0
}

/// The path of part `k` inside a run folder.
pub fn part_name(k: usize) -> String {
    format!("waveforms/part-{k:05}.parquet")
}

/// Writes a waveform part.
pub fn write_waveforms(path: &Path, w: &[Waveform], fingerprint: &str) -> Result<()> {
    waveforms_pending(path, w, fingerprint)?
        .into_iter()
        .try_for_each(Pending::commit)
}

/// [`write_waveforms`] but for the commits, which are the caller's, in the order given: the
/// part, then its checksum and the fingerprint of the simulation that made it. A part without
/// them, whose bytes disagree, or made for other inputs (another campaign, scene or version
/// in the same folder) is no part (`part_is_whole`).
pub fn waveforms_pending(path: &Path, w: &[Waveform], fingerprint: &str) -> Result<[Pending; 2]> {
    let part = waveform_table(w).write_pending(path)?;
    let sum = crate::fsutil::file_checksum(part.tmp())
        .ok_or_else(|| Error::data(path, "cannot read back the part just written"))?;
    let record = format!("{sum} {fingerprint}\n");
    let sidecar = crate::fsutil::text_pending(&checksum_path(path), &record)?;
    Ok([part, sidecar])
}

/// Where a part's checksum is kept: `part-NNNNN.parquet` → `part-NNNNN.fnv`.
pub fn checksum_path(part: &Path) -> std::path::PathBuf {
    part.with_extension("fnv")
}

/// The waveforms as the table a part file holds. One statement per column of the output
/// contract (docs/outputs.md, "Waveform parts"), in the file's column order: the function is as long as the
/// contract, and splitting it would scatter the contract over several places.
pub fn waveform_table(w: &[Waveform]) -> Table<'_> {
    let list = |f: fn(&Waveform) -> &[f32]| Column::ListF32(w.iter().map(f).collect());
    let f64s = |f: fn(&Waveform) -> f64| Column::F64(w.iter().map(f).collect());
    let f32s = |f: fn(&Waveform) -> f32| Column::F32(w.iter().map(f).collect());
    let mut columns = vec![
        (
            "pulse_id",
            Column::U64(w.iter().map(|r| r.pulse_id).collect()),
        ),
        ("t0_ns", f64s(|r| r.t0_ns)),
        ("bin_ns", f32s(|r| r.bin_ns)),
        ("laser_photons", list(|r| &r.laser_photons)),
        ("impulse_energy_j", list(|r| &r.impulse_energy_j)),
        (
            "span_first_bin",
            Column::U32(w.iter().map(|r| r.span_first_bin as u32).collect()),
        ),
        ("impulse_energy_se_j", list(|r| &r.impulse_energy_se_j)),
    ];
    columns.extend(SurfaceClass::ALL.map(|c| {
        let bins = w.iter().map(|r| r.class_energy_j[c.index()].as_slice());
        (c.energy_column(), Column::ListF32(bins.collect()))
    }));
    columns.extend([
        ("received_energy_j", f64s(|r| r.received_energy_j)),
        ("outside_gate_energy_j", f64s(|r| r.outside_gate_energy_j)),
        (
            "order_energy_j",
            Column::ListF64(w.iter().map(|r| r.order_energy_j.as_slice()).collect()),
        ),
        (
            "order_energy_se_j",
            Column::ListF64(w.iter().map(|r| r.order_energy_se_j.as_slice()).collect()),
        ),
        ("received_energy_se_j", f64s(|r| r.received_energy_se_j)),
        ("solar_photons_per_bin", f32s(|r| r.solar_photons_per_bin)),
        ("solar_power_w", f64s(|r| r.solar_power_w)),
        ("solar_power_se_w", f64s(|r| r.solar_power_se_w)),
        // null without a sun, and without laser energy in the gate: no meaning, not NaN
        (
            "brf_fov_solar",
            Column::F32OrNull(w.iter().map(|r| r.brf_fov_solar).collect()),
        ),
        (
            "brf_footprint_laser",
            Column::F32OrNull(w.iter().map(|r| r.brf_footprint_laser).collect()),
        ),
        ("rays", Column::U32(w.iter().map(|r| r.rays).collect())),
        ("paths_per_ray", f32s(|r| r.paths_per_ray)),
    ]);
    // a run of several bands: one row per pulse and band, the band beside the pulse id
    if w.iter().any(|r| r.wavelength_nm.is_some()) {
        let nm = w.iter().map(|r| r.wavelength_nm.unwrap_or(f64::NAN));
        columns.insert(1, ("wavelength_nm", Column::F64(nm.collect())));
    }
    Table { columns }
}

/// Reads a waveform part back (used by tests and later stages).
/// As long as the contract for the same reason as [`write_waveforms`]: every column is
/// checked for its type, then read, in the file's order.
pub fn read_waveforms(path: &Path) -> Result<Vec<Waveform>> {
    read_waveforms_with(path, true, true, Vec::new())
}

/// [`read_waveforms`] but for the impulse energies, left empty: what the products stage reads,
/// as it decomposes photons. The impulse energies are a column as long as the gate, like the
/// photons: a third of the bins a part holds.
/// The rows of `spare` (a part done with) lend their buffers to the rows read: a part's
/// thousands of bin lists, allocated and freed part after part, would be a measurable share
/// of the products stage.
pub fn read_waveforms_but_impulse(path: &Path, spare: Vec<Waveform>) -> Result<Vec<Waveform>> {
    read_waveforms_with(path, true, false, spare)
}

/// The columns of a waveform's bins, in [`Waveform`]'s order: laser photons, impulse energy
/// (the whole gate), then those stored from `span_first_bin` on
/// ([`Waveform::span_first_bin`]): its standard error and the four classes' energies.
const BIN_COLUMNS: [&str; 7] = {
    let c = SurfaceClass::ALL;
    [
        "laser_photons",
        "impulse_energy_j",
        "impulse_energy_se_j",
        c[0].energy_column(),
        c[1].energy_column(),
        c[2].energy_column(),
        c[3].energy_column(),
    ]
};

/// [`read_waveforms`]; with `pages`, the bins of a file laid out as lidarsim writes it are read
/// straight from its pages (`parquet_io::read_f32_lists`) and the other columns through
/// Arrow's reader, which reads every column of any other file.
///
/// Long because it is one pass over the file's columns in the contract's order: each checked
/// for its type, then read into the rows (bins from the pages or through Arrow), so that only
/// one column's values are held beside the rows.
fn read_waveforms_with(
    path: &Path,
    pages: bool,
    impulse: bool,
    spare: Vec<Waveform>,
) -> Result<Vec<Waveform>> {
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float32Type, Float64Type, UInt32Type, UInt64Type};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    use parquet::arrow::ProjectionMask;
    let err = |e: &dyn std::fmt::Display| Error::data(path, format!("cannot read Parquet: {e}"));
    let file = std::fs::File::open(path).map_err(|e| err(&e))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file.try_clone().map_err(|e| err(&e))?)
        .map_err(|e| err(&e))?;
    let schema = builder.parquet_schema();
    let leaves: Option<Vec<usize>> = BIN_COLUMNS
        .iter()
        .map(|n| crate::parquet_io::f32_list_leaf(schema, n))
        .collect::<Option<_>>()
        .filter(|_| pages);
    // The rows, made as their bins are read; the bins of each column go straight into them,
    // one column after another, so only one column's values are ever held besides the rows.
    // They are made in the rows of `spare`, emptied where they lie, then in rows reserved
    // whole: rows of a few hundred bytes each, moved from one vector to the other or grown
    // row by row, would be copied over and over (a reservation, not a promise: a damaged
    // footer must not ask for the moon).
    let rows = usize::try_from(builder.metadata().file_metadata().num_rows()).unwrap_or(0);
    let mut out = spare;
    out.iter_mut().for_each(empty);
    out.reserve(rows.min(1 << 16).saturating_sub(out.len()));
    // rows of `out` made so far: those past them are spare rows not (yet) used
    let mut made = 0usize;
    // rows each bin column held
    let mut held = [0usize; BIN_COLUMNS.len()];
    let builder = match &leaves {
        Some(leaves) => {
            let rest = (0..schema.num_columns()).filter(|c| !leaves.contains(c));
            let mask = ProjectionMask::leaves(schema, rest);
            // the impulse energies, when not wanted, read as no lists at all
            let read: Vec<usize> = (0..leaves.len()).filter(|&c| impulse || c != 1).collect();
            let at: Vec<usize> = read.iter().map(|&c| leaves[c]).collect();
            crate::parquet_io::read_f32_lists(&file, &at, |k, i, bins| {
                let c = read[k];
                let into = bins_of(row(&mut out, &mut made, i), c);
                refill(into, bins);
                held[c] = held[c].max(i + 1);
            })
            .map_err(|e| err(&e))?;
            if !impulse {
                held[1] = usize::MAX;
            }
            builder.with_projection(mask)
        }
        None => builder,
    };
    let reader = builder.build().map_err(|e| err(&e))?;
    // rows of the batches before
    let mut done = 0usize;
    for b in reader {
        let b = b.map_err(|e| err(&e))?;
        // a file that is not ours (another tool's, or another version's) is an error, never
        // a panic: every column's type is checked before it is read as that type
        let typed = |name: &str, want: &DataType| {
            let c = b
                .column_by_name(name)
                .ok_or_else(|| err(&format!("column {name} missing")))?;
            let found = match c.data_type() {
                DataType::List(f) => f.data_type(),
                t => t,
            };
            let list = matches!(c.data_type(), DataType::List(_));
            let want_list = name_is_list(name);
            if found != want || list != want_list {
                return Err(err(&format!(
                    "column {name} is {}, not the {}{want} lidarsim writes",
                    c.data_type(),
                    if want_list { "list of " } else { "" }
                )));
            }
            Ok(c)
        };
        let (u64t, u32t, f32t, f64t) = (
            DataType::UInt64,
            DataType::UInt32,
            DataType::Float32,
            DataType::Float64,
        );
        let ids = typed("pulse_id", &u64t)?
            .as_primitive::<UInt64Type>()
            .clone();
        let t0 = typed("t0_ns", &f64t)?.as_primitive::<Float64Type>().clone();
        let bin = typed("bin_ns", &f32t)?
            .as_primitive::<Float32Type>()
            .clone();
        // a file laid out otherwise: its bins through Arrow's reader
        if leaves.is_none() {
            for (c, name) in BIN_COLUMNS.iter().enumerate() {
                let l = typed(name, &f32t)?.as_list::<i32>().clone();
                for i in 0..b.num_rows() {
                    let bins = l.value(i);
                    let into = bins_of(row(&mut out, &mut made, done + i), c);
                    refill(into, bins.as_primitive::<Float32Type>().values());
                }
                held[c] = done + b.num_rows();
            }
        }
        let rec = typed("received_energy_j", &f64t)?
            .as_primitive::<Float64Type>()
            .clone();
        let out_g = typed("outside_gate_energy_j", &f64t)?
            .as_primitive::<Float64Type>()
            .clone();
        let oe = typed("order_energy_j", &f64t)?.as_list::<i32>().clone();
        let ose = typed("order_energy_se_j", &f64t)?.as_list::<i32>().clone();
        let rse = typed("received_energy_se_j", &f64t)?
            .as_primitive::<Float64Type>()
            .clone();
        let sol = typed("solar_photons_per_bin", &f32t)?
            .as_primitive::<Float32Type>()
            .clone();
        let spw = typed("solar_power_w", &f64t)?
            .as_primitive::<Float64Type>()
            .clone();
        let sps = typed("solar_power_se_w", &f64t)?
            .as_primitive::<Float64Type>()
            .clone();
        let bfs = typed("brf_fov_solar", &f32t)?
            .as_primitive::<Float32Type>()
            .clone();
        let bfl = typed("brf_footprint_laser", &f32t)?
            .as_primitive::<Float32Type>()
            .clone();
        let rays = typed("rays", &u32t)?.as_primitive::<UInt32Type>().clone();
        let ppr = typed("paths_per_ray", &f32t)?
            .as_primitive::<Float32Type>()
            .clone();
        // a column only some parts have, checked like the others where it is
        let optional = |name: &str, want: &DataType| {
            b.column_by_name(name)
                .map(|_| typed(name, want))
                .transpose()
        };
        let bands =
            optional("wavelength_nm", &f64t)?.map(|c| c.as_primitive::<Float64Type>().clone());
        // a row's values straight from the list's buffers: `value(i)` makes an array (two
        // allocations) a row
        let f64s = |l: &arrow_array::ListArray, i: usize, mut into: Vec<f64>| {
            let offsets = l.value_offsets();
            let (a, b) = (offsets[i] as usize, offsets[i + 1] as usize);
            let values = l.values().as_primitive::<Float64Type>().values();
            into.clear();
            into.extend_from_slice(values.get(a..b).unwrap_or_default());
            into
        };
        // parts written by older versions, before the spans, hold the whole gate in every
        // bin column
        let first =
            optional("span_first_bin", &u32t)?.map(|c| c.as_primitive::<UInt32Type>().clone());
        for i in 0..b.num_rows() {
            let r = done + i;
            if let Some(c) = (0..BIN_COLUMNS.len()).find(|&c| held[c] <= r) {
                return Err(err(&format!("column {} has fewer rows", BIN_COLUMNS[c])));
            }
            let w = &mut out[r];
            let bins = w.laser_photons.len();
            let span_first_bin = first.as_ref().map_or(0, |f| f.value(i) as usize);
            for (c, name) in BIN_COLUMNS.iter().enumerate().skip(2) {
                if span_first_bin.saturating_add(bins_of(w, c).len()) > bins {
                    return Err(err(&format!(
                        "row {i} of column {name} runs past the gate's {bins} bins"
                    )));
                }
            }
            // whole, so that a field Waveform gains cannot be left unread
            *w = Waveform {
                pulse_id: ids.value(i),
                t0_ns: t0.value(i),
                bin_ns: bin.value(i),
                laser_photons: std::mem::take(&mut w.laser_photons),
                impulse_energy_j: std::mem::take(&mut w.impulse_energy_j),
                impulse_energy_se_j: std::mem::take(&mut w.impulse_energy_se_j),
                received_energy_j: rec.value(i),
                outside_gate_energy_j: out_g.value(i),
                order_energy_j: f64s(&oe, i, std::mem::take(&mut w.order_energy_j)),
                order_energy_se_j: f64s(&ose, i, std::mem::take(&mut w.order_energy_se_j)),
                received_energy_se_j: rse.value(i),
                solar_photons_per_bin: sol.value(i),
                solar_power_w: spw.value(i),
                solar_power_se_w: sps.value(i),
                brf_fov_solar: if bfs.is_null(i) {
                    f32::NAN
                } else {
                    bfs.value(i)
                },
                brf_footprint_laser: if bfl.is_null(i) {
                    f32::NAN
                } else {
                    bfl.value(i)
                },
                class_energy_j: std::mem::take(&mut w.class_energy_j),
                span_first_bin,
                rays: rays.value(i),
                paths_per_ray: ppr.value(i),
                wavelength_nm: bands.as_ref().map(|a| a.value(i)),
                // not in the files: the simulate stage's log reports them
                non_finite: 0,
                underflows: 0,
            };
        }
        done += b.num_rows();
    }
    // bins of rows the other columns do not have
    if made > done {
        return Err(err(&format!(
            "the bin columns hold {made} rows, the others {done}"
        )));
    }
    out.truncate(made);
    Ok(out)
}

/// Row `i` of `out`, made with those before it where it is not yet (`made` of them are):
/// in an emptied spare row where there is one, else a new one.
fn row<'o>(out: &'o mut Vec<Waveform>, made: &mut usize, i: usize) -> &'o mut Waveform {
    while *made <= i {
        if *made == out.len() {
            out.push(Waveform::default());
        }
        *made += 1;
    }
    &mut out[i]
}

/// `into` made `bins`, in its own buffer unless that is more than twice as large: a buffer
/// lent row after row would otherwise grow to the widest span it ever held (on a forest
/// survey's long gates, a large addition to the products stage's peak).
fn refill<T: Copy>(into: &mut Vec<T>, bins: &[T]) {
    if into.capacity() > 2 * bins.len() + 16 {
        *into = bins.to_vec();
    } else {
        into.clear();
        into.extend_from_slice(bins);
    }
}

/// A row's lists emptied, their buffers kept: every other field is written whole before the
/// row is read.
fn empty(w: &mut Waveform) {
    w.laser_photons.clear();
    w.impulse_energy_j.clear();
    w.impulse_energy_se_j.clear();
    w.order_energy_j.clear();
    w.order_energy_se_j.clear();
    w.class_energy_j.iter_mut().for_each(Vec::clear);
}

/// A waveform's list of bin column `c` ([`BIN_COLUMNS`]).
fn bins_of(w: &mut Waveform, c: usize) -> &mut Vec<f32> {
    match c {
        0 => &mut w.laser_photons,
        1 => &mut w.impulse_energy_j,
        2 => &mut w.impulse_energy_se_j,
        c => &mut w.class_energy_j[SurfaceClass::ALL[(c - 3).min(3)].index()],
    }
}

/// Whether a part file is whole: its bytes match the checksum written beside it, it was made
/// for the simulation whose `fingerprint` is given, its Parquet footer reads, it holds `rows`
/// rows and its pulse ids span `pulses` (the `pulse_id` statistics of its row groups). A part
/// cut short or changed in the middle (a kill mid-write that escaped the atomic rename, a full
/// disk, a bad copy, a flipped bit), left by another campaign in the same folder, or another
/// part's file under its name, fails; `--resume` and shards redo such a part instead of
/// trusting it.
pub fn part_is_whole(
    path: &Path,
    pulses: std::ops::Range<usize>,
    rows: usize,
    fingerprint: &str,
) -> bool {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let Ok(record) = std::fs::read_to_string(checksum_path(path)) else {
        return false;
    };
    let (sum, made_for) = record
        .trim_end()
        .split_once(' ')
        .unwrap_or((record.as_str(), ""));
    if made_for != fingerprint || Some(sum) != crate::fsutil::file_checksum(path).as_deref() {
        return false;
    }
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let Ok(reader) = SerializedFileReader::new(file) else {
        return false;
    };
    let meta = reader.metadata();
    let want = (pulses.start as u64, pulses.end.saturating_sub(1) as u64);
    meta.file_metadata().num_rows() == rows as i64
        && (pulses.is_empty() || pulse_span(meta) == Some(want))
}

/// Whether a part's bytes are those its checksum file (written after it) records: a part
/// read back for a caller (Python's `Run.waveforms`) is refused when damaged, as `--resume`
/// refuses it.
pub fn part_matches_checksum(path: &Path) -> bool {
    let Ok(record) = std::fs::read_to_string(checksum_path(path)) else {
        return false;
    };
    let sum = record.split_whitespace().next().unwrap_or_default();
    Some(sum) == crate::fsutil::file_checksum(path).as_deref()
}

/// The least and greatest `pulse_id` of a Parquet file, from its row groups' statistics;
/// None when a row group has none.
fn pulse_span(meta: &parquet::file::metadata::ParquetMetaData) -> Option<(u64, u64)> {
    use parquet::file::statistics::Statistics;
    let schema = meta.file_metadata().schema_descr();
    let column = (0..schema.num_columns()).find(|&c| schema.column(c).name() == "pulse_id")?;
    let mut span: Option<(u64, u64)> = None;
    for group in meta.row_groups() {
        let Some(Statistics::Int64(s)) = group.column(column).statistics() else {
            return None;
        };
        // u64 ids are stored as INT64 with the UINT_64 annotation: the same bits
        let (lo, hi) = (*s.min_opt()? as u64, *s.max_opt()? as u64);
        span = Some(span.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
    }
    span
}

/// Whether a column of the waveform files holds one list per pulse.
fn name_is_list(name: &str) -> bool {
    BIN_COLUMNS.contains(&name) || matches!(name, "order_energy_j" | "order_energy_se_j")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parts hold more pulses only where pulses are cheap (few rays, short gates), always in
    /// thousands, and cut every pulse into exactly one part.
    #[test]
    fn parts_grow_only_where_pulses_are_cheap() {
        // the town survey: 19 rays, a gate of ~700 bins
        assert_eq!(part_size(19, waveform_bytes(700, 5)), 3000);
        // one ray, a short gate: the most
        assert_eq!(part_size(1, waveform_bytes(100, 1)), MAX_PART_PULSES);
        // a photon-counting track at 1000 rays, a forest's 3152-bin gate at 32: the fewest
        assert_eq!(part_size(1000, waveform_bytes(100, 10)), MIN_PART_PULSES);
        assert_eq!(part_size(32, waveform_bytes(3152, 5)), MIN_PART_PULSES);
        // no rays and no bins: the cheapest pulses, and no division by zero
        assert_eq!(part_size(0, 0.0), MAX_PART_PULSES);
        for (pulses, size) in [
            (0, 1000),
            (1, 1000),
            (999, 1000),
            (8001, 4000),
            (12000, 3000),
        ] {
            let parts = Parts::with_size(pulses, size);
            let cut: Vec<usize> = (0..parts.count()).flat_map(|k| parts.range(k)).collect();
            assert_eq!(
                cut,
                (0..pulses).collect::<Vec<_>>(),
                "{pulses} in parts of {size}"
            );
            assert!((0..parts.count()).all(|k| !parts.range(k).is_empty()));
        }
    }

    fn waveform(id: u64, brf_fov: f32, brf_footprint: f32) -> Waveform {
        Waveform {
            pulse_id: id,
            t0_ns: 10.0,
            bin_ns: 1.0,
            laser_photons: vec![0.0, 2.0],
            impulse_energy_j: vec![0.0, 1e-15],
            impulse_energy_se_j: vec![0.0, 1e-16],
            received_energy_j: 1e-15,
            outside_gate_energy_j: 0.0,
            order_energy_j: vec![1e-15],
            order_energy_se_j: vec![1e-16],
            received_energy_se_j: 1e-16,
            solar_photons_per_bin: 0.0,
            solar_power_w: 0.0,
            solar_power_se_w: 0.0,
            brf_fov_solar: brf_fov,
            brf_footprint_laser: brf_footprint,
            class_energy_j: std::array::from_fn(|_| vec![0.0, 2.5e-16]),
            span_first_bin: 0,
            rays: 4,
            paths_per_ray: 1.0,
            wavelength_nm: None,
            non_finite: 0,
            underflows: 0,
        }
    }

    /// A BRF with no meaning (no sun; no laser energy in the gate) is null in the file, never
    /// NaN, and comes back as NaN in memory; the columns are nullable in every part, with or
    /// without a null in it, so the parts of a run share one schema.
    #[test]
    fn meaningless_brfs_are_null_in_the_file() {
        use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
        let dir = crate::testdata::TempDir::new("wfnull");
        let (a, b) = (dir.join("a.parquet"), dir.join("b.parquet"));
        let with_nulls = vec![waveform(0, f32::NAN, 0.3), waveform(1, f32::NAN, f32::NAN)];
        write_waveforms(&a, &with_nulls, "fp").unwrap();
        write_waveforms(&b, &[waveform(2, 0.2, 0.3)], "fp").unwrap();
        let table = |p: &Path| {
            let r = ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(p).unwrap())
                .unwrap()
                .build()
                .unwrap();
            r.map(|b| b.unwrap()).collect::<Vec<_>>()
        };
        let ta = table(&a);
        for (name, nulls) in [("brf_fov_solar", 2), ("brf_footprint_laser", 1)] {
            let col = ta[0].column_by_name(name).unwrap();
            assert_eq!(col.null_count(), nulls, "{name}");
        }
        assert_eq!(ta[0].schema(), table(&b)[0].schema());
        let back = read_waveforms(&a).unwrap();
        assert!(back[0].brf_fov_solar.is_nan() && back[1].brf_footprint_laser.is_nan());
        assert_eq!(back[0].brf_footprint_laser, 0.3);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The columns stored from `span_first_bin` on read back as they were written: spans at
    /// either end of the gate, in the middle, one bin wide, and none; a part of the layout
    /// before the spans (no such column, every bin stored) reads back with the span at bin 0;
    /// a span that runs past its gate is an error.
    #[test]
    fn span_stored_columns_read_back() {
        let dir = crate::testdata::TempDir::new("wfspan");
        let path = dir.join("part.parquet");
        let bins = 40;
        let spans = [
            (0, 40),
            (0, 3),
            (37, 40),
            (5, 6),
            (17, 33),
            (0, 0),
            (16, 32),
        ];
        let rows: Vec<Waveform> = (0..spans.len())
            .map(|i| {
                let (a, b) = spans[i];
                let lit = |k: f32| -> Vec<f32> { (a..b).map(|j| j as f32 + k).collect() };
                let mut w = waveform(i as u64, f32::NAN, 0.5);
                w.laser_photons = vec![1.0; bins];
                w.impulse_energy_j = (0..bins).map(|j| j as f32).collect();
                w.impulse_energy_se_j = lit(1.0);
                w.class_energy_j = std::array::from_fn(|c| lit(2.0 + c as f32));
                w.span_first_bin = a;
                w
            })
            .collect();
        write_waveforms(&path, &rows, "fp").unwrap();
        // as text: the rows' null BRF is NaN, unequal to itself
        let text = |w: &[Waveform]| format!("{w:?}");
        let back = read_waveforms(&path).unwrap();
        assert_eq!(text(&back), text(&rows));
        // the products' read: every column but the impulse energies, left empty
        let without: Vec<Waveform> = rows
            .iter()
            .map(|w| Waveform {
                impulse_energy_j: Vec::new(),
                ..w.clone()
            })
            .collect();
        let products = read_waveforms_but_impulse(&path, Vec::new()).unwrap();
        assert_eq!(text(&products), text(&without));
        // the same read into the buffers of rows done with: more rows than the part has, of
        // other lengths, the impulse energies among them filled
        let mut spare = back.clone();
        spare.extend(back.iter().rev().cloned());
        spare[0].impulse_energy_j = vec![9.0; 3 * bins];
        let lent = read_waveforms_but_impulse(&path, spare).unwrap();
        assert_eq!(text(&lent), text(&without));
        for (w, &(a, b)) in back.iter().zip(&spans) {
            for j in 0..bins {
                let inside = (a..b).contains(&j);
                let want = if inside { j as f32 + 1.0 } else { 0.0 };
                assert_eq!(w.impulse_se(j), want, "bin {j} of {a}..{b}");
            }
            let all: f64 = (a..b).map(|j| (j as f32 + 3.0) as f64).sum();
            assert_eq!(w.class_energy_sum(1, 0, bins), all);
            assert_eq!(w.class_energy_sum(1, 0, a), 0.0);
        }
        // the layout before the spans: no span_first_bin, every bin of every column stored
        let dense: Vec<Waveform> = rows
            .iter()
            .map(|w| {
                let mut d = w.clone();
                let whole = |v: &[f32]| -> Vec<f32> {
                    let mut g = vec![0.0; w.span_first_bin];
                    g.extend_from_slice(v);
                    g.resize(bins, 0.0);
                    g
                };
                d.impulse_energy_se_j = whole(&w.impulse_energy_se_j);
                d.class_energy_j = std::array::from_fn(|c| whole(&w.class_energy_j[c]));
                d.span_first_bin = 0;
                d
            })
            .collect();
        let mut table = waveform_table(&dense);
        table.columns.retain(|(name, _)| *name != "span_first_bin");
        table.write(&path).unwrap();
        let back = read_waveforms(&path).unwrap();
        assert_eq!(text(&back), text(&dense));
        for (d, w) in back.iter().zip(&rows) {
            for j in 0..bins {
                assert_eq!(d.impulse_se(j), w.impulse_se(j));
            }
        }
        // a span that runs past its row's gate: laser photons shortened to 10 bins
        let mut table = waveform_table(&rows[4..5]);
        for (name, c) in &mut table.columns {
            if *name == "laser_photons" {
                *c = Column::ListF32(vec![&rows[4].laser_photons[..10]]);
            }
        }
        table.write(&path).unwrap();
        let e = read_waveforms(&path).unwrap_err().to_string();
        assert!(e.contains("runs past the gate's 10 bins"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The bins read straight from the pages equal what Arrow's reader gives, row for row:
    /// gates of different lengths (long rows, short rows, empty rows), over more rows than
    /// one of Arrow's batches; and a file laid out otherwise (nullable items, as pyarrow
    /// writes lists) is read through Arrow's reader to the same waveforms.
    #[test]
    fn bins_from_the_pages_equal_arrows_reading() {
        let dir = crate::testdata::TempDir::new("wfpages");
        let path = dir.join("part.parquet");
        let rows: Vec<Waveform> = (0..1100u64)
            .map(|i| {
                let len = [0, 1, 7, 1023, 1024, 1500][i as usize % 6];
                let bins = |k: f32| (0..len).map(|b| k * (b as f32 + i as f32)).collect();
                let mut w = waveform(i, f32::NAN, 0.5);
                w.laser_photons = bins(1.0);
                w.impulse_energy_j = bins(2.0);
                w.impulse_energy_se_j = bins(3.0);
                w.class_energy_j = std::array::from_fn(|c| bins(4.0 + c as f32));
                w
            })
            .collect();
        write_waveforms(&path, &rows, "fp").unwrap();
        let text = |w: &[Waveform]| format!("{w:?}");
        assert_eq!(
            text(&read_waveforms_with(&path, true, true, Vec::new()).unwrap()),
            text(&rows)
        );
        assert_eq!(
            // Arrow's reader, into the buffers of rows done with
            text(
                &read_waveforms_with(&path, false, true, rows.iter().rev().cloned().collect())
                    .unwrap()
            ),
            text(&rows)
        );
        // nullable items: not the layout read from the pages
        let mut batch = waveform_table(&rows[..50]).batch();
        let fields: Vec<arrow_schema::Field> = batch
            .schema()
            .fields()
            .iter()
            .map(|f| match f.data_type() {
                DataType::List(item) => {
                    f.as_ref()
                        .clone()
                        .with_data_type(DataType::List(std::sync::Arc::new(
                            item.as_ref().clone().with_nullable(true),
                        )))
                }
                _ => f.as_ref().clone(),
            })
            .collect();
        let columns: Vec<arrow_array::ArrayRef> = batch
            .columns()
            .iter()
            .zip(&fields)
            .map(|(c, f)| {
                arrow_array::make_array(
                    c.to_data()
                        .into_builder()
                        .data_type(f.data_type().clone())
                        .build()
                        .unwrap(),
                )
            })
            .collect();
        batch = arrow_array::RecordBatch::try_new(
            std::sync::Arc::new(arrow_schema::Schema::new(fields)),
            columns,
        )
        .unwrap();
        let other = dir.join("other.parquet");
        std::fs::write(
            &other,
            crate::parquet_io::encode(&batch, crate::parquet_io::props()).unwrap(),
        )
        .unwrap();
        assert_eq!(text(&read_waveforms(&other).unwrap()), text(&rows[..50]));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A damaged part (bytes flipped, cut or copied, as a full disk or a bad copy leaves it)
    /// reads as an error or as waveforms, never as a panic, through either reader.
    #[test]
    fn damaged_parts_never_panic() {
        let dir = crate::testdata::TempDir::new("wfdamage");
        let path = dir.join("part.parquet");
        let rows: Vec<Waveform> = (0..40u64)
            .map(|i| {
                let mut w = waveform(i, 0.1, f32::NAN);
                w.laser_photons = (0..(i as usize * 37) % 1500).map(|b| b as f32).collect();
                w
            })
            .collect();
        write_waveforms(&path, &rows, "fp").unwrap();
        let good = std::fs::read(&path).unwrap();
        let mut r = crate::rng::SplitMix64::new(5);
        let bad = dir.join("bad.parquet");
        for case in 0..300 {
            let mut data = good.clone();
            let at = (r.next_u64() % data.len() as u64) as usize;
            match case % 3 {
                0 => data[at] ^= 1 << (r.next_u64() % 8),
                1 => data.truncate(at),
                _ => {
                    let len = (r.next_u64() % 64) as usize;
                    let from = (r.next_u64() % data.len() as u64) as usize;
                    let chunk: Vec<u8> = data[from..(from + len).min(data.len())].to_vec();
                    let end = (at + chunk.len()).min(data.len());
                    data[at..end].copy_from_slice(&chunk[..end - at]);
                }
            }
            std::fs::write(&bad, &data).unwrap();
            for (pages, impulse) in [(true, true), (false, true), (true, false)] {
                let read = std::panic::catch_unwind(|| {
                    read_waveforms_with(&bad, pages, impulse, vec![Waveform::default(); 3]).is_ok()
                });
                assert!(
                    read.is_ok(),
                    "case {case} (pages {pages}, impulse {impulse}): the reader panicked"
                );
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
