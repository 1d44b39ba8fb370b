//! Waveform part files of a run folder (outputs.md): `waveforms/part-NNNNN.parquet`, one row
//! per pulse.

use super::Waveform;
use crate::error::{Error, Result};
use crate::parquet_io::{batch, list_f32, list_f64, write_batch};
use arrow_array::{Float32Array, Float64Array, UInt32Array, UInt64Array};
use std::path::Path;
use std::sync::Arc;

/// The path of part `k` inside a run folder.
pub fn part_name(k: usize) -> String {
    format!("waveforms/part-{k:05}.parquet")
}

pub fn write_waveforms(path: &Path, w: &[Waveform]) -> Result<()> {
    let b = batch(vec![
        (
            "pulse_id",
            Arc::new(UInt64Array::from_iter_values(w.iter().map(|r| r.pulse_id))),
        ),
        (
            "t0_ns",
            Arc::new(Float64Array::from_iter_values(w.iter().map(|r| r.t0_ns))),
        ),
        (
            "bin_ns",
            Arc::new(Float32Array::from_iter_values(w.iter().map(|r| r.bin_ns))),
        ),
        (
            "laser_photons",
            list_f32(w.iter().map(|r| r.laser_photons.clone())),
        ),
        (
            "impulse_energy_j",
            list_f32(w.iter().map(|r| r.impulse_energy_j.clone())),
        ),
        (
            "impulse_energy_se_j",
            list_f32(w.iter().map(|r| r.impulse_energy_se_j.clone())),
        ),
        (
            "ground_energy_j",
            list_f32(w.iter().map(|r| r.class_energy_j[0].clone())),
        ),
        (
            "vegetation_energy_j",
            list_f32(w.iter().map(|r| r.class_energy_j[1].clone())),
        ),
        (
            "building_energy_j",
            list_f32(w.iter().map(|r| r.class_energy_j[2].clone())),
        ),
        (
            "other_energy_j",
            list_f32(w.iter().map(|r| r.class_energy_j[3].clone())),
        ),
        (
            "received_energy_j",
            Arc::new(Float64Array::from_iter_values(
                w.iter().map(|r| r.received_energy_j),
            )),
        ),
        (
            "outside_gate_energy_j",
            Arc::new(Float64Array::from_iter_values(
                w.iter().map(|r| r.outside_gate_energy_j),
            )),
        ),
        (
            "order_energy_j",
            list_f64(w.iter().map(|r| r.order_energy_j.clone())),
        ),
        (
            "order_energy_se_j",
            list_f64(w.iter().map(|r| r.order_energy_se_j.clone())),
        ),
        (
            "received_energy_se_j",
            Arc::new(Float64Array::from_iter_values(
                w.iter().map(|r| r.received_energy_se_j),
            )),
        ),
        (
            "solar_photons_per_bin",
            Arc::new(Float32Array::from_iter_values(
                w.iter().map(|r| r.solar_photons_per_bin),
            )),
        ),
        (
            "solar_power_w",
            Arc::new(Float64Array::from_iter_values(
                w.iter().map(|r| r.solar_power_w),
            )),
        ),
        (
            "solar_power_se_w",
            Arc::new(Float64Array::from_iter_values(
                w.iter().map(|r| r.solar_power_se_w),
            )),
        ),
        (
            "brf_fov_solar",
            Arc::new(Float32Array::from_iter_values(
                w.iter().map(|r| r.brf_fov_solar),
            )),
        ),
        (
            "brf_footprint_laser",
            Arc::new(Float32Array::from_iter_values(
                w.iter().map(|r| r.brf_footprint_laser),
            )),
        ),
        (
            "rays",
            Arc::new(UInt32Array::from_iter_values(w.iter().map(|r| r.rays))),
        ),
        (
            "paths_per_ray",
            Arc::new(Float32Array::from_iter_values(
                w.iter().map(|r| r.paths_per_ray),
            )),
        ),
    ]);
    write_batch(path, b)
}

/// Reads a waveform part back (used by tests and later stages).
pub fn read_waveforms(path: &Path) -> Result<Vec<Waveform>> {
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float32Type, Float64Type, UInt32Type, UInt64Type};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let err = |e: &dyn std::fmt::Display| Error::file(path, format!("cannot read Parquet: {e}"));
    let file = std::fs::File::open(path).map_err(|e| err(&e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| err(&e))?
        .build()
        .map_err(|e| err(&e))?;
    let mut out = Vec::new();
    for b in reader {
        let b = b.map_err(|e| err(&e))?;
        let col = |name: &str| {
            b.column_by_name(name)
                .ok_or_else(|| err(&format!("column {name} missing")))
        };
        let ids = col("pulse_id")?.as_primitive::<UInt64Type>().clone();
        let t0 = col("t0_ns")?.as_primitive::<Float64Type>().clone();
        let bin = col("bin_ns")?.as_primitive::<Float32Type>().clone();
        let lp = col("laser_photons")?.as_list::<i32>().clone();
        let ie = col("impulse_energy_j")?.as_list::<i32>().clone();
        let ise = col("impulse_energy_se_j")?.as_list::<i32>().clone();
        let rec = col("received_energy_j")?
            .as_primitive::<Float64Type>()
            .clone();
        let out_g = col("outside_gate_energy_j")?
            .as_primitive::<Float64Type>()
            .clone();
        let oe = col("order_energy_j")?.as_list::<i32>().clone();
        let ose = col("order_energy_se_j")?.as_list::<i32>().clone();
        let rse = col("received_energy_se_j")?
            .as_primitive::<Float64Type>()
            .clone();
        let sol = col("solar_photons_per_bin")?
            .as_primitive::<Float32Type>()
            .clone();
        let cls: Vec<arrow_array::ListArray> = [
            "ground_energy_j",
            "vegetation_energy_j",
            "building_energy_j",
            "other_energy_j",
        ]
        .iter()
        .map(|n| col(n).map(|c| c.as_list::<i32>().clone()))
        .collect::<Result<_>>()?;
        let spw = col("solar_power_w")?.as_primitive::<Float64Type>().clone();
        let sps = col("solar_power_se_w")?
            .as_primitive::<Float64Type>()
            .clone();
        let bfs = col("brf_fov_solar")?.as_primitive::<Float32Type>().clone();
        let bfl = col("brf_footprint_laser")?
            .as_primitive::<Float32Type>()
            .clone();
        let rays = col("rays")?.as_primitive::<UInt32Type>().clone();
        let ppr = col("paths_per_ray")?.as_primitive::<Float32Type>().clone();
        let f32s = |l: &arrow_array::ListArray, i: usize| {
            l.value(i).as_primitive::<Float32Type>().values().to_vec()
        };
        let f64s = |l: &arrow_array::ListArray, i: usize| {
            l.value(i).as_primitive::<Float64Type>().values().to_vec()
        };
        for i in 0..b.num_rows() {
            out.push(Waveform {
                pulse_id: ids.value(i),
                t0_ns: t0.value(i),
                bin_ns: bin.value(i),
                laser_photons: f32s(&lp, i),
                impulse_energy_j: f32s(&ie, i),
                impulse_energy_se_j: f32s(&ise, i),
                received_energy_j: rec.value(i),
                outside_gate_energy_j: out_g.value(i),
                order_energy_j: f64s(&oe, i),
                order_energy_se_j: f64s(&ose, i),
                received_energy_se_j: rse.value(i),
                solar_photons_per_bin: sol.value(i),
                solar_power_w: spw.value(i),
                solar_power_se_w: sps.value(i),
                brf_fov_solar: bfs.value(i),
                brf_footprint_laser: bfl.value(i),
                class_energy_j: [
                    f32s(&cls[0], i),
                    f32s(&cls[1], i),
                    f32s(&cls[2], i),
                    f32s(&cls[3], i),
                ],
                rays: rays.value(i),
                paths_per_ray: ppr.value(i),
            });
        }
    }
    Ok(out)
}
