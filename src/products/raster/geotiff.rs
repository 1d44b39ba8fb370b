//! The DSM rasters as GeoTIFF (campaign.md, "Keys of the next wave"): float32, one band,
//! nodata -9999, north up. With a `frame` the raster lies in its CRS (GeoKey ProjectedCSType
//! = the EPSG code) and heights are in it too (local + the origin's height); without one it
//! lies in the scene's local metres with no CRS. The GeoTIFF tags are plain TIFF tags:
//! ModelPixelScale (33550), ModelTiepoint (33922), GeoKeyDirectory (34735) and GDAL's
//! nodata (42113), which GDAL, rasterio and QGIS read.

use super::Grid;
use crate::campaign::Frame;
use crate::error::{Error, Result};
use crate::fsutil::{write_atomic, WRITE_ADVICE};
use std::io::BufWriter;
use std::path::Path;
use tiff::encoder::{colortype::Gray32Float, TiffEncoder};
use tiff::tags::Tag;

/// The value of a cell without data.
pub const NODATA: f32 = -9999.0;

/// Writes `values` (row-major from the grid's south-west cell, as [`Grid::index`] counts
/// them; NaN for no data) as a GeoTIFF. `heights` adds the frame's origin height to every
/// value (a DSM; not a difference of two).
pub fn write(
    path: &Path,
    grid: &Grid,
    values: &[f64],
    frame: Option<&Frame>,
    heights: bool,
) -> Result<()> {
    let err = |e: tiff::TiffError| {
        Error::io(path, "cannot write GeoTIFF", std::io::Error::other(e)).advise(WRITE_ADVICE)
    };
    let shift = frame.map_or([0.0; 3], |f| f.origin);
    let dz = if heights { shift[2] } else { 0.0 };
    // TIFF rows run north to south; the grid's rows run south to north
    let mut data = Vec::with_capacity(grid.len());
    for row in (0..grid.ny).rev() {
        for col in 0..grid.nx {
            let v = values[row * grid.nx + col];
            data.push(if v.is_finite() {
                (v + dz) as f32
            } else {
                NODATA
            });
        }
    }
    let west = grid.x0 + shift[0];
    let north = grid.y0 + grid.ny as f64 * grid.cell + shift[1];
    let keys = geokeys(frame);
    write_atomic(path, |file| {
        let mut enc = TiffEncoder::new(BufWriter::new(file)).map_err(err)?;
        let mut image = enc
            .new_image::<Gray32Float>(grid.nx as u32, grid.ny as u32)
            .map_err(err)?;
        let e = image.encoder();
        e.write_tag(Tag::ModelPixelScaleTag, &[grid.cell, grid.cell, 0.0][..])
            .map_err(err)?;
        e.write_tag(
            Tag::ModelTiepointTag,
            &[0.0, 0.0, 0.0, west, north, 0.0][..],
        )
        .map_err(err)?;
        e.write_tag(Tag::GeoKeyDirectoryTag, &keys[..])
            .map_err(err)?;
        e.write_tag(Tag::GdalNodata, &*format!("{NODATA}"))
            .map_err(err)?;
        image.write_data(&data).map_err(err)
    })
}

/// The GeoKey directory (GeoTIFF 1.0): a header (version 1, revision 1.0, key count), then
/// per key its id, where its value is (0: in the entry) and the value.
fn geokeys(frame: Option<&Frame>) -> Vec<u16> {
    const USER_DEFINED: u16 = 32767;
    let code = frame.and_then(|f| f.resolve().ok()).map(|(code, _)| code);
    let keys: Vec<[u16; 4]> = vec![
        // GTModelTypeGeoKey: 1 projected; user-defined without a frame (local metres)
        [1024, 0, 1, if code.is_some() { 1 } else { USER_DEFINED }],
        // GTRasterTypeGeoKey: 1 = RasterPixelIsArea, the tiepoint is a cell's corner
        [1025, 0, 1, 1],
        // ProjectedCSTypeGeoKey: the EPSG code, or user-defined
        [3072, 0, 1, code.unwrap_or(USER_DEFINED)],
        // ProjLinearUnitsGeoKey: 9001 = metre
        [3076, 0, 1, 9001],
    ];
    let mut out = vec![1, 1, 0, keys.len() as u16];
    out.extend(keys.iter().flatten());
    out
}

/// A raster read back from a GeoTIFF [`write`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Raster {
    pub width: usize,
    pub height: usize,
    /// Row-major from the north-west cell, NaN where there is no data.
    pub values: Vec<f32>,
    /// GDAL's geotransform: west, cell width, 0, north, 0, -cell height.
    pub transform: [f64; 6],
    /// The CRS's EPSG code; None for local metres.
    pub epsg: Option<u16>,
}

/// Reads a raster [`write`] wrote (float32, one band, the tags it writes).
pub fn read(path: &Path) -> Result<Raster> {
    use tiff::decoder::{Decoder, DecodingResult};
    let bad = |e: &dyn std::fmt::Display| {
        Error::data(path, format!("not a GeoTIFF lidarsim wrote: {e}"))
            .advise("run the products stage again")
    };
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, "cannot open", e))?;
    let mut d = Decoder::new(std::io::BufReader::new(file)).map_err(|e| bad(&e))?;
    let (w, h) = d.dimensions().map_err(|e| bad(&e))?;
    let tie = d
        .get_tag_f64_vec(Tag::ModelTiepointTag)
        .map_err(|e| bad(&e))?;
    let scale = d
        .get_tag_f64_vec(Tag::ModelPixelScaleTag)
        .map_err(|e| bad(&e))?;
    let keys = d
        .get_tag_u16_vec(Tag::GeoKeyDirectoryTag)
        .map_err(|e| bad(&e))?;
    if tie.len() < 6 || scale.len() < 2 {
        return Err(bad(&"its tiepoint or pixel scale is short"));
    }
    let epsg = keys
        .chunks_exact(4)
        .skip(1)
        .find(|k| k[0] == 3072 && k[1] == 0)
        .map(|k| k[3])
        .filter(|&c| c != 32767);
    let DecodingResult::F32(values) = d.read_image().map_err(|e| bad(&e))? else {
        return Err(bad(&"its cells are not float32"));
    };
    if values.len() != w as usize * h as usize {
        return Err(bad(&"its size does not match its cells"));
    }
    let values = values
        .into_iter()
        .map(|v| if v == NODATA { f32::NAN } else { v })
        .collect();
    Ok(Raster {
        width: w as usize,
        height: h as usize,
        values,
        transform: [tie[3], scale[0], 0.0, tie[4], 0.0, -scale[1]],
        epsg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tiff::decoder::{Decoder, DecodingResult};

    /// A 3 x 2 raster with one empty cell, read back: size, north-up rows, nodata, heights
    /// shifted by the origin, and the GeoTIFF tags that place it.
    #[test]
    fn a_raster_reads_back_north_up_with_its_tags() {
        let dir = crate::testdata::TempDir::new("geotiff");
        let path = dir.join("dsm.tif");
        let grid = Grid {
            x0: 10.0,
            y0: 20.0,
            cell: 2.0,
            nx: 3,
            ny: 2,
        };
        // south row first, as the grid counts: (0,0) (1,0) (2,0), then (0,1) ...
        let values = [1.0, 2.0, f64::NAN, 4.0, 5.0, 6.0];
        let frame = Frame {
            crs: "EPSG:32631".into(),
            origin: [500_000.0, 4_800_000.0, 100.0],
        };
        write(&path, &grid, &values, Some(&frame), true).unwrap();
        let mut d = Decoder::new(std::fs::File::open(&path).unwrap()).unwrap();
        assert_eq!(d.dimensions().unwrap(), (3, 2));
        let DecodingResult::F32(v) = d.read_image().unwrap() else {
            panic!("not float32");
        };
        assert_eq!(v, vec![104.0, 105.0, 106.0, 101.0, 102.0, NODATA]);
        let tie = d.get_tag_f64_vec(Tag::ModelTiepointTag).unwrap();
        assert_eq!(tie, vec![0.0, 0.0, 0.0, 500_010.0, 4_800_024.0, 0.0]);
        let scale = d.get_tag_f64_vec(Tag::ModelPixelScaleTag).unwrap();
        assert_eq!(scale, vec![2.0, 2.0, 0.0]);
        let keys = d.get_tag_u16_vec(Tag::GeoKeyDirectoryTag).unwrap();
        assert_eq!(&keys[..4], &[1, 1, 0, 4]);
        assert!(keys.chunks(4).any(|k| k == [3072, 0, 1, 32631]), "{keys:?}");
        assert_eq!(d.get_tag_ascii_string(Tag::GdalNodata).unwrap(), "-9999");
        // without a frame: local metres, no height shift, a user-defined CRS
        write(&path, &grid, &values, None, true).unwrap();
        let mut d = Decoder::new(std::fs::File::open(&path).unwrap()).unwrap();
        let tie = d.get_tag_f64_vec(Tag::ModelTiepointTag).unwrap();
        assert_eq!(tie, vec![0.0, 0.0, 0.0, 10.0, 24.0, 0.0]);
        let DecodingResult::F32(v) = d.read_image().unwrap() else {
            panic!("not float32");
        };
        assert_eq!(v[0], 4.0);
        let r = read(&path).unwrap();
        assert_eq!((r.width, r.height, r.epsg), (3, 2, None));
        assert_eq!(r.transform, [10.0, 2.0, 0.0, 24.0, 0.0, -2.0]);
        assert_eq!(&r.values[..5], &[4.0, 5.0, 6.0, 1.0, 2.0]);
        assert!(r.values[5].is_nan());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
