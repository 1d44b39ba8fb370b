//! `pulses.parquet` (outputs.md): the planned pulses.

use super::{Plan, Pulse};
use crate::error::Result;
use crate::parquet_io::{batch, Sink};
use arrow_array::{ArrayRef, Float32Array, Float64Array, RecordBatch, UInt32Array, UInt64Array};
use std::path::Path;
use std::sync::Arc;

/// Pulses made and written at a time: a row group, so memory stays bounded whatever the
/// plan's length.
const CHUNK: usize = crate::parquet_io::ROW_GROUP_ROWS;

/// Writes every pulse of `plan`, a chunk at a time.
pub fn write_pulses(path: &Path, plan: &Plan) -> Result<()> {
    let mut sink = None;
    for start in (0..plan.len().max(1)).step_by(CHUNK) {
        let b = table(&plan.pulses(start..start + CHUNK));
        let s = match &mut sink {
            Some(s) => s,
            None => sink.insert(Sink::create(path, b.schema())?),
        };
        s.write(&b)?;
    }
    match sink {
        Some(s) => s.finish(),
        None => Ok(()),
    }
}

fn table(pulses: &[Pulse]) -> RecordBatch {
    let f64col = |f: fn(&Pulse) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(pulses.iter().map(f)))
    };
    batch(vec![
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
    ])
}
