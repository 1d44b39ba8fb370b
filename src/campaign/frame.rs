//! `frame:`, the optional georeference of a campaign: the scene's local metres placed in a
//! projected coordinate reference system (campaign.md, "Keys of the next wave"). Without it
//! every product stays in local metres with no CRS.
//!
//! A product's coordinate in the CRS is local + `origin` (easting, northing, height): the
//! scene is not rotated or scaled, which holds for a projected CRS in metres over the few
//! kilometres a scene spans (the scale factor of a UTM zone differs from 1 by < 0.1 %, which a
//! user who needs it applies to the scene). A geographic CRS (degrees) has no such meaning
//! and is refused.

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Frame {
    /// `EPSG:NNNN`, a projected CRS in metres.
    pub crs: String,
    /// Where the scene's (0, 0, 0) lies in the CRS: easting, northing, height, m.
    pub origin: [f64; 3],
}

impl Frame {
    /// The EPSG code and its OGC WKT (CRS WKT 1, as LAS 1.4 stores it), or why the CRS cannot
    /// be used.
    pub fn resolve(&self) -> std::result::Result<(u16, &'static str), String> {
        let code = self
            .crs
            .trim()
            .strip_prefix("EPSG:")
            .or_else(|| self.crs.trim().strip_prefix("epsg:"))
            .and_then(|c| c.parse::<u16>().ok())
            .ok_or_else(|| {
                format!(
                    "must be EPSG:NNNN (e.g. EPSG:32631, UTM zone 31N), found {:?}",
                    self.crs
                )
            })?;
        let def = crs_definitions::from_code(code)
            .ok_or_else(|| format!("EPSG:{code} is not a CRS this build knows"))?;
        let wkt = def.wkt;
        if !wkt.starts_with("PROJCS[") {
            return Err(format!(
                "EPSG:{code} is not a projected CRS (its WKT starts {:?}): the scene's metres need a projected CRS in metres, such as a UTM zone (EPSG:326NN north, 327NN south)",
                &wkt[..wkt.find('[').unwrap_or(0)]
            ));
        }
        if !projected_in_metres(wkt) {
            return Err(format!(
                "EPSG:{code} is not in metres: the scene's coordinates are metres"
            ));
        }
        Ok((code, wkt))
    }
}

/// The inverse projection of a frame's CRS to WGS 84 longitude and latitude, degrees:
/// `proj4rs` (a pure Rust port of proj4js) fed the CRS's proj4 definition from the
/// `crs-definitions` tables. The mission files (GEDI, ICESat-2) hold degrees, as the real
/// products do.
pub struct ToWgs84 {
    from: proj4rs::proj::Proj,
    to: proj4rs::proj::Proj,
    origin: [f64; 3],
}

impl ToWgs84 {
    /// The converter of `frame`, or why its CRS has none.
    pub fn new(frame: &Frame) -> std::result::Result<ToWgs84, String> {
        let (code, _) = frame.resolve()?;
        let def = crs_definitions::from_code(code)
            .ok_or_else(|| format!("EPSG:{code} is not a CRS this build knows"))?;
        let from = proj4rs::proj::Proj::from_proj_string(def.proj4)
            .map_err(|e| format!("EPSG:{code} ({}): {e}", def.proj4))?;
        let to = proj4rs::proj::Proj::from_proj_string("+proj=longlat +datum=WGS84 +no_defs")
            .map_err(|e| format!("WGS 84: {e}"))?;
        Ok(ToWgs84 {
            from,
            to,
            origin: frame.origin,
        })
    }

    /// (latitude, longitude) in degrees of the local point (x, y) (metres from the frame's
    /// origin); NaN where the projection has no inverse there.
    pub fn degrees(&self, x: f64, y: f64) -> (f64, f64) {
        let mut p = (x + self.origin[0], y + self.origin[1], 0.0);
        match proj4rs::transform::transform(&self.from, &self.to, &mut p) {
            Ok(()) if p.0.is_finite() && p.1.is_finite() => (p.1.to_degrees(), p.0.to_degrees()),
            _ => (f64::NAN, f64::NAN),
        }
    }
}

/// Whether a PROJCS's own linear unit (its last top-level UNIT) is the metre.
fn projected_in_metres(wkt: &str) -> bool {
    // the GEOGCS inside a PROJCS has an angular UNIT; the PROJCS's own UNIT comes after it
    let after_geogcs = match wkt.find("GEOGCS[") {
        Some(at) => {
            let mut depth = 0i32;
            let mut end = wkt.len();
            for (i, ch) in wkt[at..].char_indices() {
                match ch {
                    '[' => depth += 1,
                    ']' => {
                        depth -= 1;
                        if depth == 0 {
                            end = at + i;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            &wkt[end..]
        }
        None => wkt,
    };
    after_geogcs.contains("UNIT[\"metre\"") || after_geogcs.contains("UNIT[\"meter\"")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(crs: &str) -> Frame {
        Frame {
            crs: crs.into(),
            origin: [500_000.0, 4_800_000.0, 120.0],
        }
    }

    #[test]
    fn utm_zones_resolve_and_others_are_refused_with_a_reason() {
        let (code, wkt) = frame("EPSG:32631").resolve().unwrap();
        assert_eq!(code, 32631);
        assert!(wkt.contains("UTM zone 31N"), "{wkt}");
        assert!(frame("EPSG:32755").resolve().is_ok());
        let geographic = frame("EPSG:4326").resolve().unwrap_err();
        assert!(geographic.contains("not a projected CRS"), "{geographic}");
        let feet = frame("EPSG:2227").resolve().unwrap_err(); // California zone 3, US feet
        assert!(feet.contains("not in metres"), "{feet}");
        for bad in ["32631", "EPSG:", "EPSG:abc", "UTM31"] {
            assert!(
                frame(bad).resolve().unwrap_err().contains("EPSG:NNNN"),
                "{bad}"
            );
        }
        assert!(frame("EPSG:1").resolve().unwrap_err().contains("not a CRS"));
    }
}
