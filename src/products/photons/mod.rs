//! Photon counting (section 2.5): detection events drawn from a waveform, and photons.parquet.

use crate::error::Result;
use crate::parquet_io::{batch, write_batch};
use crate::plan::Pulse;
use crate::rng::SplitMix64;
use crate::C;
use arrow_array::{ArrayRef, Float64Array, RecordBatch, UInt64Array, UInt8Array};
use std::path::Path;
use std::sync::Arc;

pub const SOURCE_LASER: u8 = 0;
pub const SOURCE_SOLAR: u8 = 1;
pub const SOURCE_DARK: u8 = 2;

/// One detected photon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonEvent {
    /// From the start of bin 0 of the waveform, s.
    pub time_s: f64,
    /// 0 laser, 1 solar, 2 dark.
    pub source: u8,
}

/// Detected photons of one pulse, in time order.
///
/// Per bin the expected count is μ = qe·(laser + solar) + dark_hz·Δt; arrivals are a
/// Poisson process (a Poisson count, uniform times within the bin, which is the same
/// process), each labelled in proportion to its source's share of μ. The detector is then
/// blind for `dead_time_s` after each detection (non-paralysable: lost arrivals do not extend
/// the blind time), which carries across bins. The result depends only on (seed, pulse_id).
#[allow(clippy::too_many_arguments)]
pub fn count_photons(
    laser_photons: &[f32],
    solar_photons_per_bin: f64,
    bin_s: f64,
    qe: f64,
    dark_hz: f64,
    dead_time_s: f64,
    seed: u64,
    pulse_id: u64,
) -> Vec<PhotonEvent> {
    let clean = |v: f64| if v.is_finite() && v > 0.0 { v } else { 0.0 };
    let (qe, bin_s, dead) = (clean(qe), clean(bin_s), clean(dead_time_s));
    let solar = qe * clean(solar_photons_per_bin);
    let dark = clean(dark_hz) * bin_s;
    let mut rng = SplitMix64::for_pulse(seed, pulse_id);
    let mut out = Vec::new();
    let mut arrivals: Vec<(f64, u8)> = Vec::new();
    let mut blind_until = f64::NEG_INFINITY;
    for (i, &l) in laser_photons.iter().enumerate() {
        let laser = qe * clean(l as f64);
        let mu = laser + solar + dark;
        if mu <= 0.0 {
            continue;
        }
        // bounded, so that absurd rates (an infinite mean gives u64::MAX) cannot exhaust
        // memory: no detector records more, and below the bound nothing changes
        let n = rng.poisson(mu).min(MAX_EVENTS_PER_PULSE as u64);
        if n == 0 {
            continue;
        }
        let start = i as f64 * bin_s;
        arrivals.clear();
        for _ in 0..n {
            let t = start + rng.uniform() * bin_s;
            let u = rng.uniform() * mu;
            let source = if u < laser {
                SOURCE_LASER
            } else if u < laser + solar {
                SOURCE_SOLAR
            } else {
                SOURCE_DARK
            };
            arrivals.push((t, source));
        }
        arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
        for &(t, source) in &arrivals {
            if t >= blind_until {
                out.push(PhotonEvent { time_s: t, source });
                blind_until = t + dead;
            }
        }
        if out.len() >= MAX_EVENTS_PER_PULSE {
            out.truncate(MAX_EVENTS_PER_PULSE);
            break;
        }
    }
    out
}

/// Most photon events one pulse records: far beyond any photon-counting detector (ATLAS
/// records a few per shot and beam), a bound only on rates no instrument has.
pub const MAX_EVENTS_PER_PULSE: usize = 1_000_000;

/// One row of photons.parquet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonRow {
    pub pulse_id: u64,
    /// After emission, ns.
    pub time_ns: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub along_track_m: f64,
    pub source: u8,
    /// The band, in a run of several bands.
    pub wavelength_nm: Option<f64>,
}

/// Rows for one pulse: each event placed at range c t / 2 along the pulse axis, with t the
/// time after emission (the waveform's t0 plus the event's time in the record).
pub fn photon_rows(
    pulse: &Pulse,
    t0_ns: f64,
    events: &[PhotonEvent],
    along_track_m: f64,
) -> Vec<PhotonRow> {
    events
        .iter()
        .map(|e| {
            let time_ns = t0_ns + e.time_s * 1e9;
            let p = pulse.rec_origin() + pulse.rec_direction() * (C * time_ns * 1e-9 / 2.0);
            PhotonRow {
                pulse_id: pulse.id,
                time_ns,
                x: p.x,
                y: p.y,
                z: p.z,
                along_track_m,
                source: e.source,
                wavelength_nm: None,
            }
        })
        .collect()
}

/// Writes photons.parquet (outputs.md): pulse_id u64, time_ns f64, x, y, z f64,
/// along_track_m f64, source u8 (and wavelength_nm f64 with `bands`).
pub fn write_photons(path: &Path, rows: &[PhotonRow], bands: bool) -> Result<()> {
    write_batch(path, photon_table(rows, bands))
}

/// The rows as `photons.parquet` holds them; with `bands` (a run of several bands), each
/// row's `wavelength_nm` last.
pub fn photon_table(rows: &[PhotonRow], bands: bool) -> RecordBatch {
    let f64col = |f: fn(&PhotonRow) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(rows.iter().map(f)))
    };
    let mut columns: Vec<(&str, ArrayRef)> = vec![
        (
            "pulse_id",
            Arc::new(UInt64Array::from_iter_values(
                rows.iter().map(|r| r.pulse_id),
            )),
        ),
        ("time_ns", f64col(|r| r.time_ns)),
        ("x", f64col(|r| r.x)),
        ("y", f64col(|r| r.y)),
        ("z", f64col(|r| r.z)),
        ("along_track_m", f64col(|r| r.along_track_m)),
        (
            "source",
            Arc::new(UInt8Array::from_iter_values(rows.iter().map(|r| r.source))),
        ),
    ];
    if bands {
        columns.push((
            "wavelength_nm",
            f64col(|r| r.wavelength_nm.unwrap_or(f64::NAN)),
        ));
    }
    batch(columns)
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::RecordBatch;
    use arrow_schema::DataType;
    use glam::DVec3;

    #[test]
    fn dead_time_gives_the_non_paralysable_rate() {
        let bin = 1e-9;
        let bins = 2_000_000;
        let dead = 2.5e-9;
        let mut worst = 0.0f64;
        for &rate in &[2e7, 1e8, 4e8] {
            // Laser photons set so that qe × laser / Δt = rate.
            let qe = 0.125;
            let laser = vec![(rate * bin / qe) as f32; bins];
            let ev = count_photons(&laser, 0.0, bin, qe, 0.0, dead, 42, 1);
            let measured = ev.len() as f64 / (bins as f64 * bin);
            let expected = rate / (1.0 + rate * dead);
            let e = (measured / expected - 1.0).abs();
            worst = worst.max(e);
            println!("rate {rate:.1e}/s: detected {measured:.4e}/s, expected {expected:.4e}/s, error {:.3}%", 100.0 * e);
            assert!(e < 0.02);
            assert!(ev.windows(2).all(|w| w[1].time_s - w[0].time_s >= dead));
            assert!(ev.iter().all(|e| e.source == SOURCE_LASER));
        }
        println!("dead time: worst relative rate error {:.3}%", 100.0 * worst);
    }

    #[test]
    fn dark_counts_alone_give_the_dark_rate() {
        let bin = 1e-9;
        let bins = 1_000_000;
        let dark = 2e6; // 2 MHz: 2000 expected events over 1 ms, dead time negligible
        let ev = count_photons(&vec![0.0; bins], 0.0, bin, 0.5, dark, 2.5e-9, 3, 9);
        let measured = ev.len() as f64 / (bins as f64 * bin);
        let e = (measured / dark - 1.0).abs();
        println!(
            "dark: {measured:.4e}/s for {dark:.1e}/s, error {:.2}%",
            100.0 * e
        );
        assert!(e < 0.02 * 2.5, "{measured}"); // 2% is 0.9 standard errors at 2000 events
        assert!(ev.iter().all(|e| e.source == SOURCE_DARK));
        // Over more pulses the mean is well inside 2%.
        let total: usize = (0..20)
            .map(|p| count_photons(&vec![0.0; bins], 0.0, bin, 0.5, dark, 2.5e-9, 3, p).len())
            .sum();
        let mean = total as f64 / (20.0 * bins as f64 * bin);
        let e = (mean / dark - 1.0).abs();
        println!("dark over 20 pulses: error {:.2}%", 100.0 * e);
        assert!(e < 0.02);
    }

    #[test]
    fn labels_follow_the_rates() {
        let bin = 1e-9;
        let bins = 200_000;
        let qe = 0.2;
        // Per bin: laser 0.06, solar 0.03, dark 0.01 expected detections.
        let laser = vec![(0.06 / qe) as f32; bins];
        let ev = count_photons(&laser, 0.03 / qe, bin, qe, 0.01 / bin, 0.0, 5, 2);
        let n = ev.len() as f64;
        let share = |s: u8| ev.iter().filter(|e| e.source == s).count() as f64 / n;
        let (l, s, d) = (share(0), share(1), share(2));
        println!("labels: laser {l:.4}, solar {s:.4}, dark {d:.4} (0.6, 0.3, 0.1), n {n}");
        assert!((l - 0.6).abs() < 0.01 && (s - 0.3).abs() < 0.01 && (d - 0.1).abs() < 0.005);
        assert!((n / (0.1 * bins as f64) - 1.0).abs() < 0.02);
    }

    #[test]
    fn deterministic_per_pulse_and_ordered() {
        let laser: Vec<f32> = (0..500)
            .map(|i| 3.0 * (-((i as f32 - 250.0) / 5.0).powi(2)).exp())
            .collect();
        let a = count_photons(&laser, 0.02, 1e-9, 0.3, 1e5, 2.5e-9, 9, 77);
        let b = count_photons(&laser, 0.02, 1e-9, 0.3, 1e5, 2.5e-9, 9, 77);
        let c = count_photons(&laser, 0.02, 1e-9, 0.3, 1e5, 2.5e-9, 9, 78);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.windows(2).all(|w| w[0].time_s < w[1].time_s));
        assert!(count_photons(&[f32::NAN, -1.0], f64::NAN, 1e-9, 0.5, -3.0, 1e-9, 0, 0).is_empty());
    }

    #[test]
    fn photons_parquet_has_the_contract_columns() {
        let pulse = Pulse {
            id: 5,
            gps_time_s: 1.0,
            origin: DVec3::new(1.0, 2.0, 500.0),
            direction: DVec3::new(0.0, 0.0, -1.0),
            scan_angle_deg: 0.0,
            line: 0,
            along: DVec3::X,
            up: DVec3::Z,
            recorded: None,
        };
        let ev = [
            PhotonEvent {
                time_s: 0.0,
                source: 0,
            },
            PhotonEvent {
                time_s: 2e-9,
                source: 2,
            },
        ];
        let t0 = 2.0 * 400.0 / C * 1e9;
        let rows = photon_rows(&pulse, t0, &ev, 12.5);
        assert!((rows[0].z - 100.0).abs() < 1e-9 && rows[0].x == 1.0);
        assert!((rows[1].time_ns - t0 - 2.0).abs() < 1e-9);
        let dir = crate::testdata::TempDir::new("photons");
        let path = dir.join("photons.parquet");
        write_photons(&path, &rows, false).unwrap();
        let file = std::fs::File::open(&path).unwrap();
        let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap()
            .build()
            .unwrap();
        let batches: Vec<RecordBatch> = reader.map(|b| b.unwrap()).collect();
        let schema = batches[0].schema();
        let got: Vec<(String, DataType)> = schema
            .fields()
            .iter()
            .map(|f| (f.name().clone(), f.data_type().clone()))
            .collect();
        let want = [
            ("pulse_id", DataType::UInt64),
            ("time_ns", DataType::Float64),
            ("x", DataType::Float64),
            ("y", DataType::Float64),
            ("z", DataType::Float64),
            ("along_track_m", DataType::Float64),
            ("source", DataType::UInt8),
        ];
        assert_eq!(got.len(), want.len());
        for ((gn, gt), (wn, wt)) in got.iter().zip(want) {
            assert_eq!((gn.as_str(), gt), (wn, &wt));
        }
        assert_eq!(batches.iter().map(|b| b.num_rows()).sum::<usize>(), 2);
        let src = batches[0]
            .column(6)
            .as_any()
            .downcast_ref::<UInt8Array>()
            .unwrap();
        assert_eq!(src.value(1), 2);
    }
}
