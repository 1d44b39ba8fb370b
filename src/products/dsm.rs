//! DSM error (paper section 3.2): the first-return DSM (highest first-return point per cell)
//! minus the reference DSM of the scene's own surfaces (`Scene::top_surface_grid`) on the same
//! grid, summarised as bias, RMSE, coverage and against scan angle.
//!
//! Scan-angle attribution: a cell's error is attributed to the |scan angle| of the point that
//! set the cell's DSM value (its highest first return), since that pulse's viewing geometry is
//! what decided the height; among points of equal height, the smallest |angle| wins.

use crate::error::{Error, Result};
use crate::fsutil::{write_atomic, write_text_atomic};
use crate::pipeline::plot::{line_plot, Series};
pub use crate::scene::dsm::Grid;
use serde::Serialize;
use std::io::Write;
use std::path::Path;

/// One point as the DSM needs it: world position, scan angle (degrees), and whether it is its
/// pulse's first return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DsmPoint {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub scan_angle_deg: f64,
    pub first: bool,
}

/// Width of the scan-angle bins of `DsmReport::by_scan_angle`.
pub const ANGLE_BIN_DEG: f64 = 2.0;

/// The highest z of the first-return points in each cell (NaN where there is none).
pub fn first_return_dsm(points: &[DsmPoint], grid: &Grid) -> Vec<f64> {
    first_return_dsm_with_angle(points, grid).0
}

/// The first-return DSM and, per cell, the |scan angle| (degrees) of the point that set it
/// (NaN where there is none).
pub fn first_return_dsm_with_angle(points: &[DsmPoint], grid: &Grid) -> (Vec<f64>, Vec<f64>) {
    let n = grid.len();
    let mut z = vec![f64::NAN; n];
    let mut angle = vec![f64::NAN; n];
    for p in points {
        if !p.first || !p.z.is_finite() {
            continue;
        }
        let Some(k) = grid.index(p.x, p.y) else {
            continue;
        };
        let a = p.scan_angle_deg.abs();
        let better = z[k].is_nan() || p.z > z[k] || (p.z == z[k] && a < angle[k]);
        if better {
            z[k] = p.z;
            angle[k] = a;
        }
    }
    (z, angle)
}

/// Error figures of the cells whose |scan angle| falls in [bin_deg_lo, bin_deg_hi).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AngleBin {
    pub bin_deg_lo: f64,
    pub bin_deg_hi: f64,
    pub cells: usize,
    /// NaN (null in JSON) for an empty bin.
    pub bias_m: f64,
    pub rmse_m: f64,
}

/// DSM error figures. Error = measured − reference over the cells where both exist; the
/// figures are NaN (null in JSON) when there is no such cell.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DsmReport {
    pub bias_m: f64,
    pub rmse_m: f64,
    pub mae_m: f64,
    /// `cells_with_points / cells`.
    pub coverage: f64,
    /// Cells with a reference surface.
    pub cells: usize,
    /// Cells with a reference surface and a first-return value: the cells compared.
    pub cells_with_points: usize,
    /// 2° bins of |scan angle| from 0 up to the largest angle seen, empty bins included.
    pub by_scan_angle: Vec<AngleBin>,
    pub resolution_m: f64,
}

#[derive(Default)]
struct Sums {
    n: usize,
    sum: f64,
    sum_sq: f64,
    sum_abs: f64,
}

impl Sums {
    fn add(&mut self, e: f64) {
        self.n += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.sum_abs += e.abs();
    }

    fn mean(&self, s: f64) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            s / self.n as f64
        }
    }
}

/// Compares a measured DSM with the reference on `grid`; `angle_per_cell` is the |scan angle|
/// attributed to each cell (see the module notes), NaN where unknown.
pub fn compare(
    reference: &[f64],
    measured: &[f64],
    angle_per_cell: &[f64],
    grid: &Grid,
) -> DsmReport {
    let mut all = Sums::default();
    let mut bins: Vec<Sums> = Vec::new();
    let mut cells = 0;
    for (k, &r) in reference.iter().enumerate() {
        if !r.is_finite() {
            continue;
        }
        cells += 1;
        let m = measured.get(k).copied().unwrap_or(f64::NAN);
        if !m.is_finite() {
            continue;
        }
        let e = m - r;
        all.add(e);
        let a = angle_per_cell.get(k).copied().unwrap_or(f64::NAN).abs();
        if a.is_finite() {
            let b = (a / ANGLE_BIN_DEG).floor() as usize;
            if bins.len() <= b {
                bins.resize_with(b + 1, Sums::default);
            }
            bins[b].add(e);
        }
    }
    DsmReport {
        bias_m: all.mean(all.sum),
        rmse_m: all.mean(all.sum_sq).sqrt(),
        mae_m: all.mean(all.sum_abs),
        coverage: if cells == 0 {
            f64::NAN
        } else {
            all.n as f64 / cells as f64
        },
        cells,
        cells_with_points: all.n,
        by_scan_angle: bins
            .iter()
            .enumerate()
            .map(|(b, s)| AngleBin {
                bin_deg_lo: b as f64 * ANGLE_BIN_DEG,
                bin_deg_hi: (b + 1) as f64 * ANGLE_BIN_DEG,
                cells: s.n,
                bias_m: s.mean(s.sum),
                rmse_m: s.mean(s.sum_sq).sqrt(),
            })
            .collect(),
        resolution_m: grid.cell,
    }
}

/// Writes `dir/report.json`, `dir/error_vs_scan_angle.svg` (bias and RMSE per angle bin) and
/// `dir/error_map.png` (see `error_map_rgb`).
pub fn write_report(
    dir: &Path,
    report: &DsmReport,
    reference: &[f64],
    measured: &[f64],
    grid: &Grid,
) -> Result<()> {
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::msg(format!("cannot encode the DSM report: {e}")))?;
    write_text_atomic(&dir.join("report.json"), &(json + "\n"))?;

    let centre = |b: &AngleBin| 0.5 * (b.bin_deg_lo + b.bin_deg_hi);
    let series = [
        Series {
            name: "bias (m)".into(),
            points: report
                .by_scan_angle
                .iter()
                .map(|b| (centre(b), b.bias_m))
                .collect(),
        },
        Series {
            name: "RMSE (m)".into(),
            points: report
                .by_scan_angle
                .iter()
                .map(|b| (centre(b), b.rmse_m))
                .collect(),
        },
    ];
    let svg = line_plot(
        &format!(
            "DSM error vs scan angle ({} m cells)",
            fmt_res(report.resolution_m)
        ),
        "|scan angle| (deg), centre of 2° bin",
        "first-return DSM − reference (m)",
        &series,
    );
    write_text_atomic(&dir.join("error_vs_scan_angle.svg"), &svg)?;

    let (w, h, rgb) = error_map_rgb(reference, measured, grid);
    let png = encode_png_rgb(w, h, &rgb);
    let path = dir.join("error_map.png");
    write_atomic(&path, |mut f| {
        f.write_all(&png)
            .map_err(|e| Error::file(&path, format!("cannot write: {e}")))
    })
}

fn fmt_res(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Errors beyond this (m) get the full colour.
const MAP_SATURATION_M: f64 = 1.0;
/// The map is drawn at least this wide: small grids get k×k pixel blocks per cell.
const MAP_MIN_WIDTH_PX: usize = 400;
/// No first return where the reference has a surface: a blind spot.
const GREY_MISSED: [u8; 3] = [128, 128, 128];
/// No reference surface.
const GREY_EMPTY: [u8; 3] = [64, 64, 64];

/// The per-cell error as an 8-bit RGB image, north (high y) up: blue below the reference,
/// white on it, red above, saturating at ±1 m; mid grey where the reference has a surface but
/// no first return fell, dark grey where there is no reference. Returns (width, height, rgb).
pub fn error_map_rgb(reference: &[f64], measured: &[f64], grid: &Grid) -> (usize, usize, Vec<u8>) {
    let k = MAP_MIN_WIDTH_PX.div_ceil(grid.nx.max(1)).max(1);
    let (w, h) = (grid.nx * k, grid.ny * k);
    let mut rgb = vec![0u8; w * h * 3];
    for j in 0..grid.ny {
        for i in 0..grid.nx {
            let c = grid.nx * j + i;
            let r = reference.get(c).copied().unwrap_or(f64::NAN);
            let m = measured.get(c).copied().unwrap_or(f64::NAN);
            let colour = if !r.is_finite() {
                GREY_EMPTY
            } else if !m.is_finite() {
                GREY_MISSED
            } else {
                diverging((m - r) / MAP_SATURATION_M)
            };
            let row0 = (grid.ny - 1 - j) * k;
            for y in row0..row0 + k {
                for x in i * k..(i + 1) * k {
                    rgb[(y * w + x) * 3..][..3].copy_from_slice(&colour);
                }
            }
        }
    }
    (w, h, rgb)
}

/// Blue (−1) through white (0) to red (+1).
fn diverging(t: f64) -> [u8; 3] {
    let t = t.clamp(-1.0, 1.0);
    let fade = |a: f64| (255.0 * (1.0 - a)).round() as u8;
    if t < 0.0 {
        [fade(-t), fade(-t), 255]
    } else {
        [255, fade(t), fade(t)]
    }
}

/// A PNG of 8-bit RGB pixels (`rgb`, row-major, top row first), uncompressed: zlib with
/// stored deflate blocks, so no compression library is needed.
pub fn encode_png_rgb(width: usize, height: usize, rgb: &[u8]) -> Vec<u8> {
    assert_eq!(rgb.len(), width * height * 3, "pixel buffer size");
    let mut raw = Vec::with_capacity(height * (width * 3 + 1));
    for row in rgb.chunks_exact(width * 3) {
        raw.push(0); // filter: none
        raw.extend_from_slice(row);
    }
    let mut z = Vec::with_capacity(raw.len() + raw.len() / 65535 * 5 + 16);
    z.extend_from_slice(&[0x78, 0x01]);
    let blocks: Vec<&[u8]> = if raw.is_empty() {
        vec![&raw[..]]
    } else {
        raw.chunks(65535).collect()
    };
    for (b, block) in blocks.iter().enumerate() {
        z.push(u8::from(b + 1 == blocks.len()));
        let len = block.len() as u16;
        z.extend_from_slice(&len.to_le_bytes());
        z.extend_from_slice(&(!len).to_le_bytes());
        z.extend_from_slice(block);
    }
    z.extend_from_slice(&adler32(&raw).to_be_bytes());

    let mut png = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    let mut ihdr = Vec::with_capacity(13);
    ihdr.extend_from_slice(&(width as u32).to_be_bytes());
    ihdr.extend_from_slice(&(height as u32).to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]); // 8 bits, RGB, deflate, adaptive, no interlace
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &z);
    chunk(&mut png, b"IEND", &[]);
    png
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

const CRC_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut n = 0;
    while n < 256 {
        let mut c = n as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        t[n] = c;
        n += 1;
    }
    t
};

/// CRC-32 (ISO-HDLC, as PNG uses).
fn crc32(data: &[u8]) -> u32 {
    !data.iter().fold(!0u32, |c, &b| {
        CRC_TABLE[((c ^ b as u32) & 0xff) as usize] ^ (c >> 8)
    })
}

fn adler32(data: &[u8]) -> u32 {
    const MOD: u32 = 65521;
    let (mut a, mut b) = (1u32, 0u32);
    // 5552 bytes is the most that can be summed before b could overflow u32
    for block in data.chunks(5552) {
        for &x in block {
            a += x as u32;
            b += a;
        }
        a %= MOD;
        b %= MOD;
    }
    (b << 16) | a
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use std::path::PathBuf;

    fn tmp(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("lidarsim-dsmprod-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn flat_plane_dense_points_have_no_bias() {
        let d = tmp("plane");
        let p = d.join("scene.yaml");
        std::fs::write(
            &p,
            "name: plane\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [20, 20]], material: soil }\n",
        )
        .unwrap();
        let scene = Scene::load(&p, 1064.0).unwrap();
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 2.0,
            nx: 10,
            ny: 10,
        };
        let reference = scene.top_surface_grid(&grid);
        assert!(reference.iter().all(|z| z.abs() < 1e-9));
        // 5 cm spacing, a scan line every row, angles across the swath
        let mut points = Vec::new();
        for a in 0..400 {
            for b in 0..400 {
                let (x, y) = (0.025 + 0.05 * a as f64, 0.025 + 0.05 * b as f64);
                points.push(DsmPoint {
                    x,
                    y,
                    z: 0.0,
                    scan_angle_deg: (x - 10.0) * 1.1,
                    first: true,
                });
                // a later return below must not lower or raise anything
                points.push(DsmPoint {
                    x,
                    y,
                    z: 5.0,
                    scan_angle_deg: 0.0,
                    first: false,
                });
            }
        }
        let (measured, angle) = first_return_dsm_with_angle(&points, &grid);
        assert_eq!(measured, first_return_dsm(&points, &grid));
        let r = compare(&reference, &measured, &angle, &grid);
        assert!(r.bias_m.abs() < 0.01 && r.rmse_m < 0.01, "{r:?}");
        assert_eq!((r.cells, r.cells_with_points, r.coverage), (100, 100, 1.0));
        assert_eq!(r.resolution_m, 2.0);
        // every point of a cell is equally high, so the cell takes its smallest |angle|: up to
        // 8.8° in the outermost cells, so 5 bins, every cell binned
        assert!(
            (angle[0] - (10.0 - 1.975) * 1.1).abs() < 1e-9,
            "{}",
            angle[0]
        );
        assert_eq!(r.by_scan_angle.len(), 5);
        assert_eq!(r.by_scan_angle.iter().map(|b| b.cells).sum::<usize>(), 100);
        assert_eq!(r.by_scan_angle[4].bin_deg_lo, 8.0);

        let out = d.join("dsm");
        write_report(&out, &r, &reference, &measured, &grid).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(json["cells"], 100);
        assert!(json["by_scan_angle"][0]["rmse_m"].is_number());
        let svg = std::fs::read_to_string(out.join("error_vs_scan_angle.svg")).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("RMSE"));
        let png = std::fs::read(out.join("error_map.png")).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&png[16..24], &[0, 0, 1, 144, 0, 0, 1, 144]); // 400 × 400
    }

    #[test]
    fn missed_cells_lower_coverage() {
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 1.0,
            nx: 4,
            ny: 3,
        };
        // the reference has no surface in the last column
        let mut reference = vec![1.0; 12];
        for j in 0..3 {
            reference[j * 4 + 3] = f64::NAN;
        }
        // points in 6 of the 9 surfaced cells, one in the unsurfaced column, one outside
        let at = |x: f64, y: f64, z: f64, a: f64| DsmPoint {
            x,
            y,
            z,
            scan_angle_deg: a,
            first: true,
        };
        let points = [
            at(0.5, 0.5, 1.2, 1.0),
            at(0.6, 0.6, 0.9, -7.0), // lower: does not set the cell
            at(1.5, 0.5, 1.2, -3.0),
            at(2.5, 0.5, 0.8, 3.5),
            at(0.5, 1.5, 0.8, 0.5),
            at(1.5, 1.5, 1.0, 2.5),
            at(2.0, 2.0, 1.0, 5.0), // on a shared corner: cell (2, 2)
            at(3.5, 1.5, 9.0, 0.0), // no reference there
            at(-0.5, 1.5, 9.0, 0.0),
            DsmPoint {
                first: false,
                ..at(0.5, 2.5, 2.0, 0.0)
            },
        ];
        let (measured, angle) = first_return_dsm_with_angle(&points, &grid);
        assert_eq!(measured[0], 1.2);
        assert_eq!(angle[0], 1.0);
        assert_eq!(measured[2 * 4 + 2], 1.0);
        assert!(measured[2 * 4].is_nan());
        let r = compare(&reference, &measured, &angle, &grid);
        assert_eq!((r.cells, r.cells_with_points), (9, 6));
        assert!((r.coverage - 6.0 / 9.0).abs() < 1e-12);
        let errors = [0.2, 0.2, -0.2, -0.2, 0.0, 0.0];
        let bias = errors.iter().sum::<f64>() / 6.0;
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / 6.0).sqrt();
        assert!((r.bias_m - bias).abs() < 1e-12 && (r.rmse_m - rmse).abs() < 1e-12);
        assert!((r.mae_m - 0.8 / 6.0).abs() < 1e-12);
        // bins: [0,2): 1.0→+0.2, 0.5→−0.2; [2,4): 3.0→+0.2, 3.5→−0.2, 2.5→0; [4,6): 5.0→0
        let b: Vec<(usize, f64)> = r
            .by_scan_angle
            .iter()
            .map(|b| (b.cells, b.bias_m))
            .collect();
        assert_eq!(b.len(), 3);
        assert_eq!((b[0].0, b[1].0, b[2].0), (2, 3, 1));
        assert!(b[0].1.abs() < 1e-12 && b[1].1.abs() < 1e-12 && b[2].1 == 0.0);
        assert!((r.by_scan_angle[0].rmse_m - 0.2).abs() < 1e-12);

        // no points at all: nothing covered, figures undefined, written as null
        let r = compare(&reference, &[f64::NAN; 12], &[f64::NAN; 12], &grid);
        assert_eq!((r.cells_with_points, r.coverage), (0, 0.0));
        assert!(r.bias_m.is_nan() && r.by_scan_angle.is_empty());
        let json = serde_json::to_string(&r).unwrap();
        assert!(json.contains("\"bias_m\":null"), "{json}");
    }

    #[test]
    fn crc_and_adler_known_values() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(adler32(b"Wikipedia"), 0x11E6_0398);
        assert_eq!(adler32(&[]), 1);
        // long enough to need the modulo several times
        let big: Vec<u8> = (0..200_000u32).map(|i| (i * 7 + 3) as u8).collect();
        let (mut a, mut b) = (1u64, 0u64);
        for &x in &big {
            a = (a + x as u64) % 65521;
            b = (b + a) % 65521;
        }
        assert_eq!(adler32(&big), ((b << 16) | a) as u32);
    }

    #[test]
    fn png_layout_and_decode() {
        // wide enough for several stored blocks
        let (w, h) = (300, 100);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
        let png = encode_png_rgb(w, h, &rgb);
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        // walk the chunks and check every CRC
        let mut at = 8;
        let mut kinds = Vec::new();
        let mut idat = Vec::new();
        while at < png.len() {
            let len = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
            let body = &png[at + 4..at + 8 + len];
            let crc = u32::from_be_bytes(png[at + 8 + len..at + 12 + len].try_into().unwrap());
            assert_eq!(crc32(body), crc);
            kinds.push(String::from_utf8(body[..4].to_vec()).unwrap());
            if &body[..4] == b"IDAT" {
                idat.extend_from_slice(&body[4..]);
            }
            at += 12 + len;
        }
        assert_eq!(kinds, ["IHDR", "IDAT", "IEND"]);
        // inflate the stored blocks by hand
        assert_eq!(idat[0], 0x78);
        assert_eq!(((idat[0] as u16) << 8 | idat[1] as u16) % 31, 0);
        let mut raw = Vec::new();
        let mut p = 2;
        loop {
            let last = idat[p] & 1 == 1;
            assert_eq!(idat[p] & 6, 0, "stored block");
            let len = u16::from_le_bytes([idat[p + 1], idat[p + 2]]);
            let nlen = u16::from_le_bytes([idat[p + 3], idat[p + 4]]);
            assert_eq!(len, !nlen);
            raw.extend_from_slice(&idat[p + 5..p + 5 + len as usize]);
            p += 5 + len as usize;
            if last {
                break;
            }
        }
        assert_eq!(
            u32::from_be_bytes(idat[p..p + 4].try_into().unwrap()),
            adler32(&raw)
        );
        assert_eq!(p + 4, idat.len());
        assert_eq!(raw.len(), h * (w * 3 + 1));
        for (y, row) in raw.chunks(w * 3 + 1).enumerate() {
            assert_eq!(row[0], 0);
            assert_eq!(&row[1..], &rgb[y * w * 3..(y + 1) * w * 3]);
        }

        // and an independent decoder, where one is at hand
        let d = tmp("png");
        let f = d.join("t.png");
        std::fs::write(&f, &png).unwrap();
        let script = r#"
import sys, zlib, struct
b = open(sys.argv[1], 'rb').read()
assert b[:8] == b'\x89PNG\r\n\x1a\n'
i, idat, ihdr = 8, b'', None
while i < len(b):
    n, = struct.unpack('>I', b[i:i+4]); t = b[i+4:i+8]; d = b[i+8:i+8+n]
    assert struct.unpack('>I', b[i+8+n:i+12+n])[0] == zlib.crc32(t + d) & 0xffffffff
    if t == b'IHDR': ihdr = struct.unpack('>IIBBBBB', d)
    if t == b'IDAT': idat += d
    i += 12 + n
w, h = ihdr[0], ihdr[1]
raw = zlib.decompress(idat)
assert len(raw) == h * (3 * w + 1)
print(w, h, raw[1], raw[-1])
"#;
        match std::process::Command::new("python3")
            .arg("-c")
            .arg(script)
            .arg(&f)
            .output()
        {
            Ok(out) if out.status.success() => {
                let s = String::from_utf8_lossy(&out.stdout);
                let last = rgb[rgb.len() - 1];
                assert_eq!(s.trim(), format!("{w} {h} {} {last}", rgb[0]));
            }
            Ok(out) => panic!(
                "python3 rejects the PNG: {}",
                String::from_utf8_lossy(&out.stderr)
            ),
            Err(_) => eprintln!("python3 not available: decode check skipped"),
        }
    }

    #[test]
    fn error_map_colours() {
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 1.0,
            nx: 4,
            ny: 2,
        };
        let reference = [0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0];
        let measured = [-2.0, 0.0, 0.5, 1.0, f64::NAN, 3.0, 0.0, 0.0];
        let (w, h, rgb) = error_map_rgb(&reference, &measured, &grid);
        assert_eq!((w, h), (400, 200));
        // row j = 0 is drawn at the bottom
        let px = |i: usize, j: usize| {
            let (x, y) = (i * 100 + 50, (1 - j) * 100 + 50);
            [
                rgb[(y * w + x) * 3],
                rgb[(y * w + x) * 3 + 1],
                rgb[(y * w + x) * 3 + 2],
            ]
        };
        assert_eq!(px(0, 0), [0, 0, 255]);
        assert_eq!(px(1, 0), [255, 255, 255]);
        assert_eq!(px(2, 0), [255, 128, 128]);
        assert_eq!(px(3, 0), GREY_EMPTY);
        assert_eq!(px(0, 1), GREY_MISSED);
        assert_eq!(px(1, 1), [255, 0, 0]);
    }
}
