//! Points kept on disk between the products stage's two passes: the first pass makes them a
//! part of waveforms at a time, the second needs their extent (the LAS offsets, the DSM
//! grid) before it can use them. A fixed-size little-endian record per point, in a file under
//! a temporary name that is removed when the spill is dropped.

use crate::error::{Error, Result};
use crate::fsutil::{Pending, WRITE_ADVICE};
use crate::products::points::Point;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

/// Bytes of one record: x, y, z, gps_time f64; intensity u16; return number, number of
/// returns u8; scan angle f32; point source u16; class u8; apparent reflectance f32; pulse u64;
/// band f32 (NaN: none).
const RECORD: usize = 4 * 8 + 2 + 1 + 1 + 4 + 2 + 1 + 4 + 8 + 4 + 1;

/// Points read back at a time.
pub const CHUNK: usize = 1 << 16;

pub struct Spill {
    /// Never committed: the file only lives while the stage runs.
    pending: Pending,
    writer: BufWriter<File>,
    len: usize,
}

impl Spill {
    /// A spill file beside `path` (under its temporary name).
    pub fn create(path: &Path) -> Result<Spill> {
        let (pending, file) = Pending::create(path)?;
        Ok(Spill {
            pending,
            writer: BufWriter::with_capacity(1 << 20, file),
            len: 0,
        })
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn push(&mut self, points: &[Point]) -> Result<()> {
        let mut buf = Vec::with_capacity(points.len() * RECORD);
        for p in points {
            encode(p, &mut buf);
        }
        self.writer.write_all(&buf).map_err(|e| self.error(e))?;
        self.len += points.len();
        Ok(())
    }

    /// Calls `each` with the points in the order they were pushed, [`CHUNK`] at a time.
    pub fn read(&mut self, mut each: impl FnMut(&[Point]) -> Result<()>) -> Result<()> {
        self.writer.flush().map_err(|e| self.error(e))?;
        let file = File::open(self.pending.tmp()).map_err(|e| self.error(e))?;
        let mut reader = BufReader::with_capacity(1 << 20, file);
        let mut left = self.len;
        let mut bytes = vec![0u8; CHUNK * RECORD];
        let mut points = Vec::with_capacity(CHUNK);
        while left > 0 {
            let n = left.min(CHUNK);
            reader
                .read_exact(&mut bytes[..n * RECORD])
                .map_err(|e| self.error(e))?;
            points.clear();
            points.extend(bytes[..n * RECORD].chunks_exact(RECORD).map(decode));
            each(&points)?;
            left -= n;
        }
        Ok(())
    }

    fn error(&self, e: std::io::Error) -> Error {
        Error::io(self.pending.tmp(), "cannot write or read back points", e).advise(WRITE_ADVICE)
    }
}

fn encode(p: &Point, out: &mut Vec<u8>) {
    for v in [p.x, p.y, p.z, p.gps_time] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&p.intensity.to_le_bytes());
    out.extend_from_slice(&[p.return_number, p.number_of_returns]);
    out.extend_from_slice(&p.scan_angle_deg.to_le_bytes());
    out.extend_from_slice(&p.point_source_id.to_le_bytes());
    out.push(p.classification);
    out.extend_from_slice(&p.apparent_reflectance.to_le_bytes());
    out.extend_from_slice(&p.pulse_id.to_le_bytes());
    out.extend_from_slice(&p.wavelength_nm.unwrap_or(f32::NAN).to_le_bytes());
    out.push(u8::from(p.left_to_right) | u8::from(p.edge_of_line) << 1);
}

fn decode(b: &[u8]) -> Point {
    let mut at = 0;
    let mut take = |n: usize| {
        let s = &b[at..at + n];
        at += n;
        s
    };
    let f64_at = |s: &[u8]| f64::from_le_bytes(s.try_into().unwrap_or_default());
    let (x, y, z, gps_time) = (
        f64_at(take(8)),
        f64_at(take(8)),
        f64_at(take(8)),
        f64_at(take(8)),
    );
    let intensity = u16::from_le_bytes(take(2).try_into().unwrap_or_default());
    let r = take(2);
    let scan_angle_deg = f32::from_le_bytes(take(4).try_into().unwrap_or_default());
    let point_source_id = u16::from_le_bytes(take(2).try_into().unwrap_or_default());
    let classification = take(1)[0];
    let apparent_reflectance = f32::from_le_bytes(take(4).try_into().unwrap_or_default());
    let pulse_id = u64::from_le_bytes(take(8).try_into().unwrap_or_default());
    let nm = f32::from_le_bytes(take(4).try_into().unwrap_or_default());
    let flags = take(1)[0];
    Point {
        x,
        y,
        z,
        gps_time,
        intensity,
        return_number: r[0],
        number_of_returns: r[1],
        scan_angle_deg,
        point_source_id,
        classification,
        apparent_reflectance,
        pulse_id,
        wavelength_nm: (!nm.is_nan()).then_some(nm),
        left_to_right: flags & 1 != 0,
        edge_of_line: flags & 2 != 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every field comes back bit for bit, in order, across chunk boundaries.
    #[test]
    fn points_come_back_as_they_went() {
        let dir = crate::testdata::TempDir::new("spill");
        let points: Vec<Point> = (0..CHUNK as u64 + 7)
            .map(|i| Point {
                x: i as f64 * 0.1 - 3e5,
                y: -(i as f64).sqrt(),
                z: f64::from_bits(0x4000_0000_0000_0001 + i),
                gps_time: 1e9 + i as f64 * 1e-5,
                intensity: (i % 65536) as u16,
                return_number: (i % 4) as u8 + 1,
                number_of_returns: 4,
                scan_angle_deg: -11.0 + i as f32 * 1e-4,
                point_source_id: (i % 3) as u16,
                classification: (i % 7) as u8,
                apparent_reflectance: 0.3 + i as f32 * 1e-6,
                pulse_id: u64::MAX - i,
                wavelength_nm: (i % 2 == 0).then_some(532.0 + i as f32),
                left_to_right: i % 3 == 0,
                edge_of_line: i % 5 == 0,
            })
            .collect();
        let path = dir.join("points.las");
        let mut spill = Spill::create(&path).unwrap();
        spill.push(&points[..5]).unwrap();
        spill.push(&points[5..]).unwrap();
        let mut back = Vec::new();
        spill
            .read(|chunk| {
                back.extend_from_slice(chunk);
                Ok(())
            })
            .unwrap();
        assert_eq!(back, points);
        let tmp = spill.pending.tmp().to_path_buf();
        assert!(tmp.is_file());
        drop(spill);
        assert!(!tmp.exists(), "the spill file outlived its stage");
        assert!(!path.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
