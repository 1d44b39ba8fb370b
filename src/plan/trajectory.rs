//! A recorded trajectory (`platform.trajectory`): epochs of GPS time, position and attitude
//! in a CSV file whose header row names its columns (`time_s`, `x`, `y`, `z`, `roll_deg`,
//! `pitch_deg`, `heading_deg`; others are ignored, as an SBET export has more).
//!
//! Streamed, not loaded: opening reads the file once, checks every row and keeps the time and
//! byte offset of every [`BLOCK`]-th epoch. A pose is interpolated from the block of epochs
//! around its time, read again from the open file when asked for (the last few blocks are
//! kept). Memory is a few blocks and one mark per block, however long the flight.
//!
//! Position is interpolated linearly, attitude spherically: the slerp, the shorter way round,
//! of the unit quaternions of R = Rz(90° − h)·Ry(−p)·Rx(r) (spec: campaign.md, Frames).

use crate::campaign::Trajectory as Spec;
use crate::error::{Error, Result};
use glam::{DQuat, DVec3};
use std::io::BufRead;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Epochs per block: a pose reads at most one block of rows again.
const BLOCK: usize = 256;
/// Blocks kept: the threads of a stage read a few neighbouring blocks at a time.
const KEPT: usize = 8;

/// The columns a trajectory needs, by name.
pub(crate) const COLUMNS: [&str; 7] = [
    "time_s",
    "x",
    "y",
    "z",
    "roll_deg",
    "pitch_deg",
    "heading_deg",
];

/// The attitude matrix's rotation as a unit quaternion: R = Rz(90° − h)·Ry(−p)·Rx(r).
pub(crate) fn attitude(roll_deg: f64, pitch_deg: f64, heading_deg: f64) -> DQuat {
    DQuat::from_rotation_z((90.0 - heading_deg).to_radians())
        * DQuat::from_rotation_y((-pitch_deg).to_radians())
        * DQuat::from_rotation_x(roll_deg.to_radians())
}

#[derive(Clone, Copy, Debug)]
struct Epoch {
    t: f64,
    position: DVec3,
    attitude: DQuat,
}

/// Epoch k·BLOCK: its time, where its row starts and where the row ends.
#[derive(Clone, Copy)]
struct Mark {
    t: f64,
    start: u64,
    end: u64,
    line: usize,
}

pub(crate) struct Trajectory {
    path: PathBuf,
    file: std::fs::File,
    /// Index in a row of each of [`COLUMNS`].
    columns: [usize; 7],
    width: usize,
    origin: DVec3,
    marks: Vec<Mark>,
    /// The last epoch (closes the last block).
    last: Mark,
    epochs: usize,
    kept: Mutex<Vec<(usize, Arc<Vec<Epoch>>)>>,
}

impl Trajectory {
    /// Opens and checks a campaign's trajectory. Errors name the CSV file, its line and column.
    pub(crate) fn open(spec: &Spec) -> Result<Trajectory> {
        let path = spec
            .resolved
            .clone()
            .unwrap_or_else(|| PathBuf::from(&spec.file));
        let file = std::fs::File::open(&path)
            .map_err(|e| Error::io(&path, "cannot open the trajectory file", e))?;
        let mut reader = std::io::BufReader::new(&file);
        let mut text = String::new();
        let (mut offset, mut line) = (0u64, 0usize);
        let mut header: Option<([usize; 7], usize)> = None;
        let (mut marks, mut last, mut count) = (Vec::new(), None::<Mark>, 0usize);
        loop {
            text.clear();
            let n = reader.read_line(&mut text).map_err(|e| {
                if e.kind() == std::io::ErrorKind::InvalidData {
                    // the line that is not UTF-8 text is the next one
                    Error::at(&path, Some((line + 1, 1)), "", "is not UTF-8 text")
                } else {
                    Error::io(&path, "cannot read the trajectory file", e)
                }
            })?;
            if n == 0 {
                break;
            }
            line += 1;
            let start = offset;
            offset += n as u64;
            let row = text.trim_end_matches(['\n', '\r']);
            // a line with no LF to end it holding a CR: the file's lines end in CR alone, and
            // it would otherwise read as one line, its header naming every row (a stray CR in
            // a field of an LF line is blank space, as before)
            if let Some(at) = row.find('\r').filter(|_| !text.ends_with('\n')) {
                return Err(Error::at(
                    &path,
                    Some((line, at + 1)),
                    "",
                    "its lines end in a carriage return alone (a classic Mac OS export): save \
                     the file with LF or CRLF line endings",
                ));
            }
            if row.trim().is_empty() {
                continue;
            }
            let Some((columns, width)) = header else {
                header = Some(read_header(&path, row)?);
                continue;
            };
            let epoch = parse_row(&path, line, row, &columns, width, spec.origin)?;
            if let Some(prev) = &last {
                if epoch.t <= prev.t {
                    return Err(Error::at(
                        &path,
                        Some((line, 1)),
                        "time_s",
                        format!(
                            "times must increase: {} s after {} s on line {}",
                            epoch.t, prev.t, prev.line
                        ),
                    ));
                }
            }
            let mark = Mark {
                t: epoch.t,
                start,
                end: offset,
                line,
            };
            if count % BLOCK == 0 {
                marks.push(mark);
            }
            last = Some(mark);
            count += 1;
        }
        let Some((columns, width)) = header else {
            return Err(Error::at(
                &path,
                Some((1, 1)),
                "",
                format!(
                    "the trajectory file is empty: it needs a header row naming the columns {}",
                    COLUMNS.join(", ")
                ),
            ));
        };
        let last = match last {
            Some(l) if count >= 2 => l,
            _ => {
                return Err(Error::at(
                    &path,
                    Some((line.max(1), 1)),
                    "",
                    "a trajectory needs at least two epochs (rows after the header)",
                ))
            }
        };
        Ok(Trajectory {
            path,
            file,
            columns,
            width,
            origin: DVec3::from_array(spec.origin),
            marks,
            last,
            epochs: count,
            kept: Mutex::new(Vec::new()),
        })
    }

    pub(crate) fn epochs(&self) -> usize {
        self.epochs
    }

    /// The first and last epochs' times, GPS seconds.
    pub(crate) fn span(&self) -> [f64; 2] {
        [self.marks[0].t, self.last.t]
    }

    /// The interpolated position (scene frame) and attitude at GPS time `t0 + dt`, held at the
    /// ends outside the span. Given as two parts because a GPS time near 1e9 s holds only
    /// 0.24 µs (1.4e-5 m at 60 m/s): the fraction between two epochs is taken from `t0 − t_a`
    /// and `dt` apart.
    pub(crate) fn pose(&self, t0: f64, dt: f64) -> (DVec3, DQuat) {
        let t = t0 + dt;
        // a block that would hold the last epoch alone (its mark is the last epoch) is never
        // read: the block before it ends on that epoch
        let blocks = self.marks.len()
            - usize::from(
                self.marks.len() > 1 && self.marks[self.marks.len() - 1].start == self.last.start,
            );
        let k = (self.marks.partition_point(|m| m.t <= t).max(1) - 1).min(blocks - 1);
        let block = self.block(k);
        let i = (block.partition_point(|e| e.t <= t).max(1) - 1).min(block.len() - 2);
        let (a, b) = (&block[i], &block[i + 1]);
        let s = (((t0 - a.t) + dt) / (b.t - a.t)).clamp(0.0, 1.0);
        let position = a.position + (b.position - a.position) * s;
        let q1 = if a.attitude.dot(b.attitude) < 0.0 {
            -b.attitude
        } else {
            b.attitude
        };
        let attitude = if a.attitude == q1 || s == 0.0 {
            a.attitude
        } else if s == 1.0 {
            q1
        } else {
            a.attitude.slerp(q1, s)
        };
        (position, attitude)
    }

    /// Epochs k·BLOCK to (k + 1)·BLOCK, both included (the last block ends at the last epoch).
    fn block(&self, k: usize) -> Arc<Vec<Epoch>> {
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(i) = kept.iter().position(|(j, _)| *j == k) {
            let entry = kept.remove(i);
            let block = entry.1.clone();
            kept.insert(0, entry);
            return block;
        }
        drop(kept);
        let block = Arc::new(self.read_block(k).unwrap_or_else(|e| {
            // the file was checked when opened: it changed while the run read it
            eprintln!("error: {e} (the trajectory file changed during the run; run again)");
            std::process::exit(1)
        }));
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        kept.insert(0, (k, block.clone()));
        kept.truncate(KEPT);
        block
    }

    fn read_block(&self, k: usize) -> Result<Vec<Epoch>> {
        let first = &self.marks[k];
        let end = self.marks.get(k + 1).map_or(self.last.end, |m| m.end);
        let mut bytes = vec![0u8; (end - first.start) as usize];
        self.file
            .read_exact_at(&mut bytes, first.start)
            .map_err(|e| Error::io(&self.path, "cannot read the trajectory file again", e))?;
        let text = String::from_utf8(bytes)
            .map_err(|_| Error::at(&self.path, Some((first.line, 1)), "", "is not UTF-8 text"))?;
        let origin = self.origin.to_array();
        let mut epochs = Vec::with_capacity(BLOCK + 1);
        for (n, row) in text.lines().enumerate() {
            if row.trim().is_empty() {
                continue;
            }
            let line = first.line + n;
            epochs.push(parse_row(
                &self.path,
                line,
                row,
                &self.columns,
                self.width,
                origin,
            )?);
        }
        if epochs.len() < 2 {
            return Err(Error::at(
                &self.path,
                Some((first.line, 1)),
                "",
                "the rows read again are not the rows checked",
            ));
        }
        Ok(epochs)
    }
}

fn read_header(path: &Path, row: &str) -> Result<([usize; 7], usize)> {
    // a spreadsheet's export may open with a byte-order mark
    let row = row.trim_start_matches('\u{feff}');
    let names: Vec<&str> = row.split(',').map(|f| f.trim().trim_matches('"')).collect();
    let mut columns = [0usize; 7];
    for (c, want) in COLUMNS.iter().enumerate() {
        let found: Vec<usize> = (0..names.len()).filter(|&i| names[i] == *want).collect();
        match found[..] {
            [i] => columns[c] = i,
            [] => {
                return Err(Error::at(
                    path,
                    Some((1, 1)),
                    want,
                    format!(
                        "the header row has no column {want}: a trajectory needs {} \
                         (found {})",
                        COLUMNS.join(", "),
                        shown(&names)
                    ),
                ))
            }
            _ => {
                return Err(Error::at(
                    path,
                    Some((1, 1)),
                    want,
                    format!("the header row names the column {want} twice"),
                ))
            }
        }
    }
    Ok((columns, names.len()))
}

/// A header's names for a message: the first dozen, so that a wrong file (one whose rows
/// are all on one line) cannot fill the terminal.
fn shown(names: &[&str]) -> String {
    const MOST: usize = 12;
    let mut s: Vec<&str> = names.iter().take(MOST).copied().collect();
    let more;
    if names.len() > MOST {
        more = format!("and {} more", names.len() - MOST);
        s.push(&more);
    }
    s.iter()
        .map(|n| match n.char_indices().nth(40) {
            Some((i, _)) => format!("{}…", &n[..i]),
            None => n.to_string(),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// One row: the named columns as numbers, the position moved into the scene's frame.
fn parse_row(
    path: &Path,
    line: usize,
    row: &str,
    columns: &[usize; 7],
    width: usize,
    origin: [f64; 3],
) -> Result<Epoch> {
    let fields: Vec<&str> = row.split(',').collect();
    if fields.len() != width {
        return Err(Error::at(
            path,
            Some((line, 1)),
            "",
            format!(
                "has {} fields where the header names {width} columns",
                fields.len()
            ),
        ));
    }
    let mut v = [0.0f64; 7];
    for (c, name) in COLUMNS.iter().enumerate() {
        let i = columns[c];
        let column = fields[..i].iter().map(|f| f.len() + 1).sum::<usize>() + 1;
        let field = fields[i].trim();
        v[c] = match field.parse::<f64>() {
            Ok(x) if x.is_finite() => x,
            _ => {
                return Err(Error::at(
                    path,
                    Some((line, column)),
                    name,
                    format!("must be a finite number, found {field:?}"),
                ))
            }
        };
        // GPS seconds to the year 2296; positions within 10,000 km of the frame's origin;
        // attitude angles within ±10^5 degrees (a heading unwrapped over many turns is one,
        // 10^308 is none)
        let (limit, what) = match c {
            0 => (1e10, "a GPS time in seconds within ±10^10"),
            1..=3 => (
                1e7,
                "a coordinate in metres within 10,000 km of the frame's origin",
            ),
            _ => (1e5, "an angle in degrees within ±10^5"),
        };
        let off = if (1..=3).contains(&c) {
            origin[c - 1]
        } else {
            0.0
        };
        if (v[c] - off).abs() > limit {
            return Err(Error::at(
                path,
                Some((line, column)),
                name,
                format!("must be {what}, found {field}"),
            ));
        }
    }
    Ok(Epoch {
        t: v[0],
        position: DVec3::new(v[1] - origin[0], v[2] - origin[1], v[3] - origin[2]),
        attitude: attitude(v[4], v[5], v[6]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 257 epochs: the last block's mark is the last epoch itself; a pose at or past it comes
    /// from the block before, held at the end, and every epoch's own pose is its row's.
    #[test]
    fn a_lone_last_epoch_is_read_with_the_block_before() {
        let dir = crate::testdata::TempDir::new("trajectory-257");
        let mut text = String::from("time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n");
        for k in 0..=BLOCK {
            text += &format!("{k},{},0,100,0,0,90\n", 2 * k);
        }
        let path = dir.join("t.csv");
        std::fs::write(&path, text).unwrap();
        let spec = Spec {
            file: path.display().to_string(),
            scan: None,
            resolved: None,
            origin: [0.0; 3],
        };
        let t = Trajectory::open(&spec).unwrap();
        assert_eq!(t.span(), [0.0, BLOCK as f64]);
        for k in [0usize, 1, 255, 256] {
            let (p, _) = t.pose(k as f64, 0.0);
            assert_eq!(p.x, 2.0 * k as f64, "epoch {k}");
        }
        let (p, _) = t.pose(BLOCK as f64, 5.0);
        assert_eq!(p.x, 2.0 * BLOCK as f64);
        let (p, _) = t.pose(255.0, 0.5);
        assert_eq!(p.x, 511.0);
    }
}
