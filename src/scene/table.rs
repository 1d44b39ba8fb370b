//! Plain numeric tables: instance placements and heightfield grids.

use crate::error::{Error, Result};
use std::path::Path;

/// One placement of a mesh: world position of the mesh origin, rotation about z, uniform scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceRow {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub rotation_deg: f64,
    pub scale: f64,
}

const COLUMNS: [&str; 5] = ["x", "y", "z", "rotation_deg", "scale"];

/// Fields of one line, separated by commas and/or white space, `#` starting a comment.
/// Returns `None` for blank and comment-only lines.
fn fields(line: &str) -> Option<impl Iterator<Item = &str>> {
    let content = match line.find('#') {
        Some(i) => &line[..i],
        None => line,
    };
    if content.trim().is_empty() {
        return None;
    }
    Some(
        content
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|f| !f.is_empty()),
    )
}

/// Parses an instance table (`x y [z [rotation_deg [scale]]]` per row).
pub fn parse_instances(path: &Path, text: &str) -> Result<Vec<InstanceRow>> {
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let Some(fs) = fields(line) else { continue };
        let mut v = [0.0, 0.0, 0.0, 0.0, 1.0];
        let mut count = 0;
        for f in fs {
            if count < 5 {
                v[count] = parse_number(path, n, count, f)?;
            }
            count += 1;
        }
        if !(2..=5).contains(&count) {
            return Err(Error::line(
                path,
                n,
                format!("expected 2 to 5 columns (x y [z [rotation_deg [scale]]]), found {count}"),
            ));
        }
        let row = InstanceRow {
            x: v[0],
            y: v[1],
            z: v[2],
            rotation_deg: v[3],
            scale: v[4],
        };
        if row.scale.is_nan() || row.scale <= 0.0 || row.scale > super::MAX_SCALE {
            return Err(Error::line(
                path,
                n,
                format!(
                    "column 5 (scale) must be a positive number up to {}, found {}",
                    super::MAX_SCALE,
                    row.scale
                ),
            ));
        }
        if let Some(c) = (0..3).find(|&c| v[c].abs() > super::MAX_COORDINATE_M) {
            return Err(Error::line(
                path,
                n,
                format!(
                    "column {} ({}): {} m lies beyond ±{} km of the scene's origin: coordinates are metres in the scene's local frame",
                    c + 1,
                    COLUMNS[c],
                    v[c],
                    super::MAX_COORDINATE_M / 1e3
                ),
            ));
        }
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(Error::file(
            path,
            "the instance table has no rows (expected x y [z [rotation_deg [scale]]] per line)",
        ));
    }
    Ok(rows)
}

fn parse_number(path: &Path, line: usize, col: usize, field: &str) -> Result<f64> {
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Error::line(
            path,
            line,
            format!(
                "column {} ({}): expected a number, found \"{field}\"",
                col + 1,
                COLUMNS[col]
            ),
        )),
    }
}

/// A grid of z values, rows in file order (row 0 first).
pub struct HeightGrid {
    pub rows: usize,
    pub cols: usize,
    pub z: Vec<f64>,
}

/// Parses a heightfield: one row of z values per line, commas or white space between them.
pub fn parse_grid(path: &Path, text: &str) -> Result<HeightGrid> {
    let mut z = Vec::new();
    let mut cols = 0;
    let mut rows = 0;
    let mut first_line = 0;
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let Some(fs) = fields(line) else { continue };
        let before = z.len();
        for (c, f) in fs.enumerate() {
            match f.parse::<f64>() {
                Ok(v) if v.is_finite() && v.abs() <= super::MAX_COORDINATE_M => z.push(v),
                _ => {
                    return Err(Error::line(
                        path,
                        n,
                        format!(
                            "column {}: expected a height in metres within ±{} km, found \"{f}\"",
                            c + 1,
                            super::MAX_COORDINATE_M / 1e3
                        ),
                    ))
                }
            }
        }
        let count = z.len() - before;
        if rows == 0 {
            cols = count;
            first_line = n;
        } else if count != cols {
            return Err(Error::line(
                path,
                n,
                format!("this row has {count} values but the first row (line {first_line}) has {cols}: rows must all have the same length"),
            ));
        }
        rows += 1;
    }
    if rows < 2 || cols < 2 {
        return Err(Error::file(
            path,
            format!("a heightfield needs at least 2 rows and 2 columns of heights, found {rows} × {cols}"),
        ));
    }
    Ok(HeightGrid { rows, cols, z })
}
