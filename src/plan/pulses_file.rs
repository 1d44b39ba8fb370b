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
        let b = table(&plan.pulses(start..start + CHUNK), plan.records_pose());
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

/// The columns of outputs.md; with `recorded`, the recorded pose after them.
fn table(pulses: &[Pulse], recorded: bool) -> RecordBatch {
    let f64col = |f: fn(&Pulse) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(pulses.iter().map(f)))
    };
    let mut columns: Vec<(&str, ArrayRef)> = vec![
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
    ];
    if recorded {
        columns.extend([
            ("rec_origin_x", f64col(|p| p.rec_origin().x)),
            ("rec_origin_y", f64col(|p| p.rec_origin().y)),
            ("rec_origin_z", f64col(|p| p.rec_origin().z)),
            ("rec_dir_x", f64col(|p| p.rec_direction().x)),
            ("rec_dir_y", f64col(|p| p.rec_direction().y)),
            ("rec_dir_z", f64col(|p| p.rec_direction().z)),
        ]);
    }
    batch(columns)
}
