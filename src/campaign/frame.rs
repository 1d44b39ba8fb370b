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
            .filter(|c| !c.is_empty() && c.bytes().all(|b| b.is_ascii_digit()))
            .ok_or_else(|| {
                format!(
                    "must be EPSG:NNNN (e.g. EPSG:32631, UTM zone 31N), found {:?}",
                    self.crs
                )
            })?;
        let unknown = || format!("EPSG:{code} is not a CRS this build knows");
        let code = code.parse::<u16>().map_err(|_| unknown())?;
        let def = crs_definitions::from_code(code).ok_or_else(unknown)?;
        let wkt = def.wkt;
        if wkt.is_empty() {
            return Err(format!(
                "EPSG:{code} has no definition in this build's tables: choose another projected CRS for the place, such as a UTM zone (EPSG:326NN north, 327NN south)"
            ));
        }
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
        // a CRS whose axes point west and south (South African Lo grids) would mirror the
        // scene: x and y are east and north, the origin plus them the CRS's coordinates
        if let Some(axis) = def
            .proj4
            .split_whitespace()
            .find_map(|t| t.strip_prefix("+axis="))
            .filter(|a| !a.starts_with("en"))
        {
            return Err(format!(
                "EPSG:{code}'s axes point {} (+axis={axis}): a frame's x and y are the CRS's easting and northing, so its axes must point east and north; choose such a CRS for the same place (a UTM zone, EPSG:326NN north, 327NN south)",
                axis_names(axis)
            ));
        }
        Ok((code, wkt))
    }

    /// Why latitudes and longitudes cannot be had from this frame's CRS, if they cannot: a
    /// projection this build cannot invert (Krovak, oblique Mercator, ...) or a datum shift
    /// by grids it does not have (NAD27). The mission files give degrees; LAS and GeoTIFF do
    /// not need them.
    pub fn degrees_unavailable(&self) -> Option<String> {
        let why = match ToWgs84::new(self) {
            Err(e) => e,
            Ok(to) => match to.try_degrees(0.0, 0.0) {
                Ok(_) => return None,
                Err(e) => format!("{}: {e}", self.crs.trim()),
            },
        };
        Some(format!(
            "{why}: this build has no inverse projection from it to latitude and longitude, which the mission files (GEDI, ICESat-2) hold; choose another projected CRS for the place, such as a UTM zone (EPSG:326NN north, 327NN south)"
        ))
    }
}

/// CRSs whose definitions in the crs-definitions tables give no shift from their datum to
/// WGS 84 where EPSG holds one, with how far (m) their latitudes and longitudes, taken as on
/// WGS 84, lie from PROJ's at the centre of each area of use (`every_crs_against_proj`).
const WITHOUT_EPSG_SHIFT: [(u16, u32); 33] = [
    (2000, 571),
    (2081, 123),
    (2096, 383),
    (2097, 379),
    (2098, 373),
    (2312, 150),
    (2313, 116),
    (3354, 120),
    (3374, 306),
    (3396, 164),
    (3397, 170),
    (3398, 177),
    (3399, 189),
    (5167, 382),
    (5168, 410),
    (5169, 323),
    (5170, 320),
    (5173, 373),
    (5174, 379),
    (5175, 410),
    (5176, 383),
    (5177, 382),
    (5178, 386),
    (5666, 164),
    (5667, 170),
    (5668, 177),
    (5669, 189),
    (5682, 154),
    (5683, 160),
    (5684, 174),
    (5685, 192),
    (6991, 78),
    (8433, 335),
];

impl Frame {
    /// Why latitudes and longitudes from this frame's CRS lie far from WGS 84's, if they do:
    /// a definition without the datum shift EPSG holds ([`WITHOUT_EPSG_SHIFT`]).
    pub fn degrees_off(&self) -> Option<String> {
        let (code, _) = self.resolve().ok()?;
        let &(_, m) = WITHOUT_EPSG_SHIFT.iter().find(|(c, _)| *c == code)?;
        Some(format!(
            "frame.crs EPSG:{code}'s definition in this build gives no shift from its datum to WGS 84, which EPSG holds: the mission files' latitudes and longitudes are on its own datum, {m} m from WGS 84's at the centre of its area of use"
        ))
    }
}

/// `+axis=wsu` in words: "west and south".
fn axis_names(axis: &str) -> String {
    let word = |c: char| match c {
        'e' => "east",
        'w' => "west",
        'n' => "north",
        's' => "south",
        'u' => "up",
        'd' => "down",
        _ => "?",
    };
    let mut chars = axis.chars();
    match (chars.next(), chars.next()) {
        (Some(x), Some(y)) => format!("{} and {}", word(x), word(y)),
        _ => axis.to_string(),
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
        let from = proj4rs::proj::Proj::from_proj_string(&for_proj4rs(code, def.proj4))
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
        self.try_degrees(x, y).unwrap_or((f64::NAN, f64::NAN))
    }

    /// [`ToWgs84::degrees`], or why there are none.
    fn try_degrees(&self, x: f64, y: f64) -> std::result::Result<(f64, f64), String> {
        let mut p = (x + self.origin[0], y + self.origin[1], 0.0);
        match proj4rs::transform::transform(&self.from, &self.to, &mut p) {
            Ok(()) if p.0.is_finite() && p.1.is_finite() => {
                Ok((p.1.to_degrees(), p.0.to_degrees()))
            }
            Ok(()) => Err("the inverse projection gave no number".into()),
            Err(e) => Err(e.to_string()),
        }
    }
}

/// Prime meridians proj4 strings name, degrees east of Greenwich (PROJ's table).
const PRIME_MERIDIANS: [(&str, f64); 14] = [
    ("greenwich", 0.0),
    ("lisbon", -9.131906111111),
    ("paris", 2.337229166667),
    ("bogota", -74.080916666667),
    ("madrid", -3.687938888889),
    ("rome", 12.452333333333),
    ("bern", 7.439583333333),
    ("jakarta", 106.807719444444),
    ("ferro", -17.666666666667),
    ("brussels", 4.367975),
    ("stockholm", 18.058277777778),
    ("athens", 23.7163375),
    ("oslo", 10.722916666667),
    ("copenhagen", 12.57788),
];

/// Ellipsoids PROJ defines by their semi-minor axis: name, a, b (m).
const MINOR_AXIS_ELLIPSOIDS: [(&str, f64, f64); 6] = [
    ("mod_airy", 6_377_340.189, 6_356_034.446),
    ("clrk66", 6_378_206.4, 6_356_583.8),
    ("new_intl", 6_378_157.5, 6_356_772.2),
    ("plessis", 6_376_523.0, 6_355_863.0),
    ("SEasia", 6_378_155.0, 6_356_773.320_5),
    ("walbeck", 6_376_896.0, 6_355_834.846_7),
];

/// CRSs whose `+towgs84` in the crs-definitions tables (0.6.0) holds EPSG's rotations in the
/// coordinate-frame convention where proj4 reads the position-vector one: their signs are
/// turned. Stereo 70, and IGN63 Hiva Oa and Fatu Iva 72 in UTM zone 7S, were 38 m, 7 m and
/// 4.8 km off PROJ's transformations at their areas' centres, and are under 1 m once turned;
/// the tables' 873 other CRSs with rotations agree with PROJ.
const ROTATIONS_AS_COORDINATE_FRAME: [u16; 3] = [3302, 3303, 3844];

/// A proj4 definition rewritten so that proj4rs (0.1.10) reads it as PROJ does, around three of
/// its slips (each changes a position by tens of metres to hundreds of kilometres):
/// - it adds a prime meridian (`+pm`), which it holds in degrees, to longitudes in radians:
///   the meridian is given to it in radians;
/// - it takes the flattening of an ellipsoid given by its semi-minor axis b as (a - b) / b, not
///   (a - b) / a: `+b`, and the ellipsoids PROJ defines by b (among them Clarke 1866 and,
///   through the datum `ire65`, the modified Airy), are given to it as a and 1 / f;
/// - it reads a scale factor as `+k` or `+k0`, not PROJ's `+k_0`, and takes 1 without a word
///   (0.9998774 is 28 m over the 228 km from Lambert II's origin to Paris): given as `+k`.
///
/// And the tables' rotations of [`ROTATIONS_AS_COORDINATE_FRAME`] are turned.
fn for_proj4rs(code: u16, proj4: &str) -> String {
    let tokens: Vec<&str> = proj4.split_whitespace().collect();
    let a = tokens
        .iter()
        .find_map(|t| t.strip_prefix("+a="))
        .and_then(|v| v.parse::<f64>().ok());
    let by_minor_axis = |a: f64, b: f64| format!("+a={a} +rf={}", a / (a - b));
    let mut out: Vec<String> = Vec::with_capacity(tokens.len());
    for t in tokens {
        if let Some(pm) = t.strip_prefix("+pm=") {
            let degrees = PRIME_MERIDIANS
                .iter()
                .find(|(name, _)| name.eq_ignore_ascii_case(pm))
                .map(|&(_, d)| d)
                .or_else(|| pm.parse::<f64>().ok());
            out.push(match degrees {
                Some(d) => format!("+pm={}", d.to_radians()),
                None => t.to_string(),
            });
        } else if let Some(b) = t.strip_prefix("+b=") {
            out.push(match (a, b.parse::<f64>()) {
                (Some(a), Ok(b)) if b > 0.0 && b < a => format!("+rf={}", a / (a - b)),
                _ => t.to_string(),
            });
        } else if let Some(k) = t.strip_prefix("+k_0=") {
            out.push(format!("+k={k}"));
        } else if let Some(name) = t.strip_prefix("+ellps=") {
            out.push(
                match MINOR_AXIS_ELLIPSOIDS.iter().find(|(n, _, _)| *n == name) {
                    Some(&(_, a, b)) => by_minor_axis(a, b),
                    None => t.to_string(),
                },
            );
        } else if let Some(v) = t
            .strip_prefix("+towgs84=")
            .filter(|_| ROTATIONS_AS_COORDINATE_FRAME.contains(&code))
        {
            let mut p: Vec<String> = v.split(',').map(str::to_string).collect();
            for r in p.iter_mut().skip(3).take(3) {
                *r = match r.strip_prefix('-') {
                    Some(pos) => pos.to_string(),
                    None => format!("-{r}"),
                };
            }
            out.push(format!("+towgs84={}", p.join(",")));
        } else if t == "+datum=ire65" {
            // PROJ's datum: the modified Airy ellipsoid and this shift
            let (_, a, b) = MINOR_AXIS_ELLIPSOIDS[0];
            out.push(by_minor_axis(a, b));
            out.push("+towgs84=482.530,-130.596,564.557,-1.042,-0.214,-0.631,8.15".into());
        } else {
            out.push(t.to_string());
        }
    }
    out.join(" ")
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
        // a code of the right form that no table holds, or holds without a definition
        assert!(frame("EPSG:99999")
            .resolve()
            .unwrap_err()
            .contains("not a CRS this build knows"));
        assert!(frame("EPSG:8857")
            .resolve()
            .unwrap_err()
            .contains("no definition"));
    }

    #[test]
    fn proj4_definitions_are_given_to_proj4rs_as_proj_reads_them() {
        // Lambert II étendu: Paris meridian, a scale factor as k_0, an ellipsoid by its b
        let p = for_proj4rs(27572, crs_definitions::from_code(27572).unwrap().proj4);
        assert!(
            p.contains(&format!("+pm={}", 2.337229166667f64.to_radians())),
            "{p}"
        );
        assert!(p.contains("+k=0.99987742") && !p.contains("k_0"), "{p}");
        assert!(p.contains("+rf=293.466021") && !p.contains("+b="), "{p}");
        // Clarke 1866 by name, and the datum of Ireland 1965 through its modified Airy
        let p = for_proj4rs(2027, crs_definitions::from_code(2027).unwrap().proj4);
        assert!(p.contains("+a=6378206.4 +rf=294.978698"), "{p}");
        let p = for_proj4rs(29902, crs_definitions::from_code(29902).unwrap().proj4);
        assert!(
            p.contains("+a=6377340.189 +rf=299.324937") && p.contains("+towgs84=482.53"),
            "{p}"
        );
        // Stereo 70's rotations turned, another CRS's kept
        let p = for_proj4rs(3844, crs_definitions::from_code(3844).unwrap().proj4);
        assert!(
            p.contains("+towgs84=2.329,-147.042,-92.08,-0.309,0.325,0.497,5.69"),
            "{p}"
        );
        let osgb = crs_definitions::from_code(27700).unwrap().proj4;
        assert_eq!(
            for_proj4rs(27700, osgb),
            osgb.split_whitespace().collect::<Vec<_>>().join(" ")
        );
    }

    /// Latitudes and longitudes as PROJ gives them for the same CRS coordinates (pyproj 3.7.2, PROJ
    /// 9.5.1, `Transformer.from_crs(CRS(wkt), 4326)` with the tables' WKT): the frame's origin
    /// plus (18.2, 19.1) m.
    #[test]
    fn degrees_agree_with_proj_where_proj4rs_slipped() {
        let cases: [(&str, [f64; 2], [f64; 2]); 5] = [
            // Paris meridian, k_0, minor axis
            (
                "EPSG:27572",
                [600990.892, 2427961.512],
                [48.85017164, 2.35024790],
            ),
            // Madrid meridian
            (
                "EPSG:2062",
                [600000.0, 600000.0],
                [40.00017222, -3.68772551],
            ),
            // Oslo meridian
            ("EPSG:27391", [0.0, 0.0], [58.00099759, 6.05232308]),
            // Clarke 1866
            (
                "EPSG:2027",
                [500000.0, 4984944.378],
                [45.02007684, -92.99976901],
            ),
            // Stereo 70's rotations
            (
                "EPSG:3844",
                [500120.3, 444471.627],
                [45.50017189, 25.00023293],
            ),
        ];
        for (crs, origin, [lat, lon]) in cases {
            let f = Frame {
                crs: crs.into(),
                origin: [origin[0], origin[1], 0.0],
            };
            let (la, lo) = ToWgs84::new(&f).unwrap().degrees(18.2, 19.1);
            // 1e-6 degree: 0.1 m
            assert!(
                (la - lat).abs() < 1e-6 && (lo - lon).abs() < 1e-6,
                "{crs}: {la:.7} {lo:.7}, PROJ {lat} {lon}"
            );
        }
    }

    #[test]
    fn frames_lidarsim_cannot_place_are_refused_with_a_reason() {
        let south = frame("EPSG:2046").resolve().unwrap_err();
        assert!(south.contains("west and south"), "{south}");
        let krovak = Frame {
            crs: "EPSG:5514".into(),
            origin: [-700000.0, -1100000.0, 0.0],
        };
        assert!(krovak.resolve().is_ok());
        let why = krovak.degrees_unavailable().unwrap();
        assert!(why.contains("no inverse projection"), "{why}");
        let nad27 = Frame {
            crs: "EPSG:26717".into(),
            origin: [500000.0, 4500000.0, 0.0],
        };
        assert!(nad27.degrees_unavailable().is_some());
        assert!(frame("EPSG:32631").degrees_unavailable().is_none());
        // Korean 1985, taken as on WGS 84: said, with how far
        let korea = frame("EPSG:5178").degrees_off().unwrap();
        assert!(korea.contains("386 m"), "{korea}");
        assert!(frame("EPSG:32631").degrees_off().is_none());
    }
}
/// Every CRS of the tables against PROJ, from `tools/crs_reference.py`'s file (named by
/// `LIDARSIM_CRS_REFERENCE`): at each area of use's centre, lidarsim's latitude and longitude
/// against pyproj's. Manual: it needs that file, which needs pyproj.
#[cfg(test)]
mod sweep {
    /// Beyond 1 m of PROJ besides [`super::WITHOUT_EPSG_SHIFT`]: two CRSs whose WKT holds the
    /// rotations lidarsim turns (PROJ read from the WKT keeps them).
    const WKT_KEEPS_ROTATIONS: [u16; 2] = [3302, 3303];

    #[test]
    #[ignore]
    fn every_crs_against_proj() {
        let Some(path) = std::env::var_os("LIDARSIM_CRS_REFERENCE") else {
            eprintln!("SKIPPED: set LIDARSIM_CRS_REFERENCE to tools/crs_reference.py's file");
            return;
        };
        let text = std::fs::read_to_string(path).unwrap();
        let (mut compared, mut refused) = (0, 0);
        let mut off: Vec<(f64, String)> = Vec::new();
        for line in text.lines() {
            let f: Vec<&str> = line.split(',').collect();
            let v: Vec<f64> = f[1..].iter().map(|x| x.parse().unwrap()).collect();
            let frame = super::Frame {
                crs: format!("EPSG:{}", f[0]),
                origin: [v[0], v[1], 0.0],
            };
            if frame.resolve().is_err() || frame.degrees_unavailable().is_some() {
                refused += 1;
                continue;
            }
            compared += 1;
            let (la, lo) = super::ToWgs84::new(&frame).unwrap().degrees(0.0, 0.0);
            let dlo = ((lo - v[3] + 540.0) % 360.0) - 180.0;
            let m = ((la - v[2]) * 111_320.0).hypot(dlo * 111_320.0 * v[2].to_radians().cos());
            if m > 1.0 {
                off.push((m, f[0].to_string()));
            }
        }
        off.sort_by(|a, b| b.0.total_cmp(&a.0));
        eprintln!(
            "{compared} CRSs compared, {refused} refused, {} beyond 1 m: {off:?}",
            off.len()
        );
        let known = |c: &str| {
            let c: u16 = c.parse().unwrap();
            WKT_KEEPS_ROTATIONS.contains(&c) || super::WITHOUT_EPSG_SHIFT.iter().any(|w| w.0 == c)
        };
        let unknown: Vec<_> = off.iter().filter(|(_, c)| !known(c)).collect();
        assert!(unknown.is_empty(), "beyond 1 m of PROJ: {unknown:?}");
    }
}
