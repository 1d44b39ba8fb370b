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

/// Fields of one line, separated by commas or white space, `#` starting a comment; `None`
/// for blank and comment-only lines. Between commas a field may not be empty: `10,,20` is a
/// missing value, not two columns.
fn fields<'a>(path: &Path, n: usize, line: &'a str) -> Result<Option<Vec<&'a str>>> {
    let content = match line.find('#') {
        Some(i) => &line[..i],
        None => line,
    };
    if content.trim().is_empty() {
        return Ok(None);
    }
    if !content.contains(',') {
        return Ok(Some(content.split_whitespace().collect()));
    }
    let mut out = Vec::new();
    let cells: Vec<&str> = content
        .trim_end()
        .trim_end_matches(',')
        .split(',')
        .collect();
    for (k, cell) in cells.iter().enumerate() {
        let words: Vec<&str> = cell.split_whitespace().collect();
        if words.is_empty() {
            return Err(Error::line(
                path,
                n,
                format!(
                    "column {}: empty (two commas with no value between them)",
                    k + 1
                ),
            ));
        }
        out.extend(words);
    }
    Ok(Some(out))
}

/// Parses an instance table (`x y [z [rotation_deg [scale]]]` per row).
pub fn parse_instances(path: &Path, text: &str) -> Result<Vec<InstanceRow>> {
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let Some(fs) = fields(path, n, line)? else {
            continue;
        };
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
        let Some(fs) = fields(path, n, line)? else {
            continue;
        };
        let before = z.len();
        for (c, f) in fs.into_iter().enumerate() {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Commas and white space both separate columns, but two commas with nothing between
    /// them are a missing value, named by line and column, not a shorter row.
    #[test]
    fn an_empty_field_between_commas_is_an_error() {
        let p = Path::new("t.csv");
        let rows = parse_instances(p, "1, 2, 3\n4 5 6\n7,8,9,\n").unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!((rows[2].x, rows[2].y, rows[2].z), (7.0, 8.0, 9.0));
        let e = parse_instances(p, "1,2\n10,,20\n").unwrap_err().to_string();
        assert!(
            e.starts_with("t.csv:2:") && e.contains("column 2: empty"),
            "{e}"
        );
        let e = match parse_grid(p, "1,2\n,3\n") {
            Err(e) => e.to_string(),
            Ok(_) => panic!("a grid with an empty field"),
        };
        assert!(
            e.starts_with("t.csv:2:") && e.contains("column 1: empty"),
            "{e}"
        );
    }
}
