//! `pulses.parquet` (outputs.md): the planned pulses.

use super::Pulse;
use crate::error::Result;
use crate::parquet_io::{batch, write_batch};
use arrow_array::{ArrayRef, Float32Array, Float64Array, UInt32Array, UInt64Array};
use std::path::Path;
use std::sync::Arc;

pub fn write_pulses(path: &Path, pulses: &[Pulse]) -> Result<()> {
    let f64col = |f: fn(&Pulse) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(pulses.iter().map(f)))
    };
    let b = batch(vec![
        (
            "pulse_id",
            Arc::new(UInt64Array::from_iter_values(pulses.iter().map(|p| p.id))),
        ),
        ("gps_time_s", f64col(|p| p.gps_time_s)),
        ("origin_x", f64col(|p| p.origin.x)),
        ("origin_y", f64col(|p| p.origin.y)),
        ("origin_z", f64col(|p| p.origin.z)),
        ("dir_x", f64col(|p| p.direction.x)),
        ("dir_y", f64col(|p| p.direction.y)),
        ("dir_z", f64col(|p| p.direction.z)),
        (
            "scan_angle_deg",
            Arc::new(Float32Array::from_iter_values(
                pulses.iter().map(|p| p.scan_angle_deg),
            )),
        ),
        (
            "line",
            Arc::new(UInt32Array::from_iter_values(pulses.iter().map(|p| p.line))),
        ),
    ]);
    write_batch(path, b)
}
