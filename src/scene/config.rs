//! The scene file as written by the user, and material resolution at one wavelength.

use crate::campaign::spectral::Spectral;
use crate::campaign::yaml::Doc;
use crate::error::{Error, Result};
use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;

use super::rpv::{Rpv, MAX_CHECKED_DEG, MAX_REFUSED_DEG};
use super::SurfaceClass;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SceneFile {
    pub name: String,
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
    #[serde(default)]
    pub objects: Vec<ObjectSpec>,
    /// The scene is one period of an infinite landscape (DART's repeated scene).
    #[serde(default)]
    pub repeat: bool,
    /// The period's x-y rectangle [[x0, y0], [x1, y1]]; absent: the extent of the ground
    /// objects (planes, heightfields), else of all geometry. Geometry that overhangs it wraps
    /// into it.
    #[serde(default)]
    pub period: Option<[[f64; 2]; 2]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MaterialSpec {
    /// Lambertian reflectance, or RPV's amplitude ρ0 with `rpv`.
    pub reflectance: Spectral,
    #[serde(default)]
    pub back_reflectance: Option<Spectral>,
    #[serde(default)]
    pub transmittance: Option<Spectral>,
    /// The RPV glossy reflectance (docs/physics.md, "Glossy surfaces: RPV") instead of Lambert's.
    #[serde(default)]
    pub rpv: Option<RpvSpec>,
}

/// RPV's shape parameters, each one number or a table by wavelength.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RpvSpec {
    pub k: Spectral,
    pub theta: Spectral,
    #[serde(default)]
    pub rho_c: Option<Spectral>,
}

/// One list item `kind: { ... }`. Deserialized by hand: serde_yaml 0.9 reads externally tagged
/// enums only from `!tag` syntax, and the contract uses single-key maps.
#[derive(Debug)]
pub(crate) enum ObjectSpec {
    Plane(PlaneSpec),
    Mesh(MeshSpec),
    Heightfield(HeightfieldSpec),
    Water(WaterSpec),
}

const KINDS: &[&str] = &["plane", "mesh", "heightfield", "water"];

/// A body of water (docs/physics.md, "Water"): its smooth surface, a horizontal rectangle at `z`, over
/// a water column that fills everything below it within the rectangle, down to whatever the
/// scene puts there (the seabed).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct WaterSpec {
    pub z: f64,
    pub extent: [[f64; 2]; 2],
    /// Beam attenuation coefficient of the water column, per metre, by wavelength.
    pub attenuation_per_m: Spectral,
    /// The phase index, which steers refraction, per band or one number; default 1.33. A run
    /// of several bands refracts every path with its first band's.
    #[serde(default)]
    pub refractive_index: Option<Spectral>,
    /// The group index, per band or one number: light in the column travels at c / n_g.
    /// Default: the phase index plus the dispersion of Quan and Fry's water index at the band
    /// ([`crate::scene::water_group_index`]).
    #[serde(default)]
    pub group_index: Option<Spectral>,
    /// Wind speed at 12.5 m, m/s: a surface roughened by Cox-Munk slopes; absent: smooth.
    #[serde(default)]
    pub wind_speed_m_s: Option<f64>,
}

impl<'de> Deserialize<'de> for ObjectSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = ObjectSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("one of `plane: {...}`, `mesh: {...}`, `heightfield: {...}`")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut map: A,
            ) -> std::result::Result<ObjectSpec, A::Error> {
                let Some(kind) = map.next_key::<String>()? else {
                    return Err(de::Error::invalid_length(0, &self));
                };
                let obj = match kind.as_str() {
                    "plane" => ObjectSpec::Plane(map.next_value()?),
                    "mesh" => ObjectSpec::Mesh(map.next_value()?),
                    "heightfield" => ObjectSpec::Heightfield(map.next_value()?),
                    "water" => ObjectSpec::Water(map.next_value()?),
                    _ => return Err(de::Error::unknown_variant(&kind, KINDS)),
                };
                if let Some(extra) = map.next_key::<String>()? {
                    return Err(de::Error::custom(format!(
                        "one object per list item: found `{extra}` after `{kind}`; start a new item with `- {extra}: ...`"
                    )));
                }
                Ok(obj)
            }
        }
        d.deserialize_map(V)
    }
}

impl ObjectSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            ObjectSpec::Plane(_) => "plane",
            ObjectSpec::Mesh(_) => "mesh",
            ObjectSpec::Heightfield(_) => "heightfield",
            ObjectSpec::Water(_) => "water",
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PlaneSpec {
    pub z: f64,
    pub extent: [[f64; 2]; 2],
    pub material: String,
    #[serde(default)]
    pub class: Option<ClassSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MeshSpec {
    pub file: String,
    #[serde(default)]
    pub material: Option<String>,
    #[serde(default)]
    pub materials: Option<BTreeMap<String, String>>,
    #[serde(default)]
    pub instances: Option<String>,
    #[serde(default)]
    pub class: Option<ClassSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct HeightfieldSpec {
    pub file: String,
    pub cell_m: f64,
    pub material: String,
    #[serde(default)]
    pub origin: Option<[f64; 2]>,
    #[serde(default)]
    pub class: Option<ClassSpec>,
}

#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum ClassSpec {
    Ground,
    Vegetation,
    Building,
    Other,
}

impl From<ClassSpec> for SurfaceClass {
    fn from(c: ClassSpec) -> Self {
        match c {
            ClassSpec::Ground => SurfaceClass::Ground,
            ClassSpec::Vegetation => SurfaceClass::Vegetation,
            ClassSpec::Building => SurfaceClass::Building,
            ClassSpec::Other => SurfaceClass::Other,
        }
    }
}

/// A material's optical properties at the campaign's wavelengths: the largest over its bands
/// (what paths are sampled with) and each band's (ρ, ρ_back, τ).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ResolvedMaterial {
    pub reflectance: f64,
    pub back_reflectance: f64,
    pub transmittance: f64,
    pub bands: Vec<[f64; 3]>,
    /// RPV's shape paths are sampled and weighted with (that of the band of the largest ρ0),
    /// and each band's; `None` and empty for a Lambertian material.
    pub rpv: Option<Rpv>,
    pub band_rpv: Vec<Rpv>,
    /// A water surface.
    pub water: Option<super::WaterInterface>,
}

/// Resolves every material at each of `wavelengths_nm`, with located errors; a material's
/// scalar values are the largest over the bands (the band's own with one band).
pub(crate) fn resolve_materials(
    doc: &Doc,
    file: &SceneFile,
    wavelengths_nm: &[f64],
) -> Result<BTreeMap<String, ResolvedMaterial>> {
    let mut out: BTreeMap<String, ResolvedMaterial> = BTreeMap::new();
    for &w in wavelengths_nm {
        for (name, m) in resolve_at(doc, file, w)? {
            let band = [m.reflectance, m.back_reflectance, m.transmittance];
            let rpv = m.rpv;
            let entry = out.entry(name).or_insert(m);
            entry.bands.push(band);
            entry.band_rpv.extend(rpv);
        }
    }
    for m in out.values_mut() {
        let max = |i: usize| m.bands.iter().map(|b| b[i]).fold(0.0, f64::max);
        (m.reflectance, m.back_reflectance, m.transmittance) = (max(0), max(1), max(2));
        // RPV's shape of the band of the largest amplitude (the first among equals)
        let brightest = (0..m.bands.len()).fold(0, |best, b| {
            if m.bands[b][0] > m.bands[best][0] {
                b
            } else {
                best
            }
        });
        m.rpv = m.band_rpv.get(brightest).copied();
    }
    Ok(out)
}

fn value_at(doc: &Doc, key: &str, s: &Spectral, wavelength_nm: f64) -> Result<f64> {
    let v = s.at(wavelength_nm).map_err(|why| doc.error(key, why))?;
    if !v.is_finite() || !(0.0..=1.0).contains(&v) {
        return Err(doc.error(
            key,
            format!("{v} at {wavelength_nm} nm is not within [0, 1]"),
        ));
    }
    Ok(v)
}

/// A material's RPV shape at `wavelength_nm`, checked: parameters in their ranges, no
/// transmittance (an RPV surface is opaque), and a directional albedo of at most 1 from every
/// incidence on both sides (else the surface would create energy).
fn resolve_rpv(
    doc: &Doc,
    base: &str,
    spec: &RpvSpec,
    m: &MaterialSpec,
    rho0: [f64; 2],
    wavelength_nm: f64,
) -> Result<Rpv> {
    let key = format!("{base}.rpv");
    if m.transmittance.is_some() {
        return Err(doc.error(
            &format!("{base}.transmittance"),
            "an RPV surface is opaque: give it no transmittance (RPV is for soils, roofs, roads)",
        ));
    }
    let value = |name: &str, s: &Spectral, lo: f64, hi: f64| -> Result<f64> {
        let k = format!("{key}.{name}");
        let v = s.at(wavelength_nm).map_err(|why| doc.error(&k, why))?;
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            return Err(doc.error(
                &k,
                format!("{v} at {wavelength_nm} nm is not within [{lo}, {hi}]"),
            ));
        }
        Ok(v)
    };
    let rpv = Rpv {
        k: value("k", &spec.k, 0.1, 3.0)?,
        theta: value("theta", &spec.theta, -0.99, 0.99)?,
        rho_c: match &spec.rho_c {
            Some(s) => Some(value("rho_c", s, 0.0, 1.0)?),
            None => None,
        },
        limit: None,
    };
    for (side, r) in ["front", "back"].into_iter().zip(rho0) {
        let (albedo, deg) = rpv.max_albedo(r, 0.0, f64::from(MAX_REFUSED_DEG));
        // the quadrature is good to about 1e-3 (docs/physics.md, "Glossy surfaces: RPV")
        if albedo > 1.0 + 2e-3 {
            return Err(doc.error(
                &key,
                format!(
                    "with ρ0 = {r} ({side} side) at {wavelength_nm} nm these RPV parameters reflect {albedo:.3} of the light from {deg}° incidence: more than it receives; lower ρ0, or bring k nearer 1 and theta nearer 0"
                ),
            ));
        }
    }
    // beyond it, up to grazing incidence, RPV's growth is the model's: held to 1, not refused
    let grazing = rho0.map(|r| {
        rpv.max_albedo(r, f64::from(MAX_REFUSED_DEG), MAX_CHECKED_DEG)
            .0
    });
    if grazing.iter().any(|&a| a > 1.0 + 2e-3) {
        return Ok(rpv.limited());
    }
    Ok(rpv)
}

/// Resolves every material at `wavelength_nm`, with located errors.
fn resolve_at(
    doc: &Doc,
    file: &SceneFile,
    wavelength_nm: f64,
) -> Result<BTreeMap<String, ResolvedMaterial>> {
    if !(wavelength_nm.is_finite() && wavelength_nm > 0.0) {
        return Err(Error::msg(format!(
            "wavelength {wavelength_nm} nm is not a positive number"
        )));
    }
    let mut out = BTreeMap::new();
    for (name, m) in &file.materials {
        let base = format!("materials.{name}");
        let r = value_at(
            doc,
            &format!("{base}.reflectance"),
            &m.reflectance,
            wavelength_nm,
        )?;
        let rb = match &m.back_reflectance {
            Some(s) => value_at(doc, &format!("{base}.back_reflectance"), s, wavelength_nm)?,
            None => r,
        };
        let t = match &m.transmittance {
            Some(s) => value_at(doc, &format!("{base}.transmittance"), s, wavelength_nm)?,
            None => 0.0,
        };
        // A little slack so that tables written as 0.45 + 0.55 pass despite rounding.
        for (side, key, refl) in [
            ("front", "reflectance", r),
            ("back", "back_reflectance", rb),
        ] {
            if refl + t > 1.0 + 1e-9 {
                let at = if key == "back_reflectance" && m.back_reflectance.is_none() {
                    format!("{base}.reflectance")
                } else {
                    format!("{base}.{key}")
                };
                return Err(doc.error(
                    &at,
                    format!(
                        "{key} + transmittance = {refl} + {t} = {} > 1 at {wavelength_nm} nm ({side} side): a surface cannot scatter more than it receives",
                        refl + t
                    ),
                ));
            }
        }
        let rpv = match &m.rpv {
            Some(spec) => Some(resolve_rpv(doc, &base, spec, m, [r, rb], wavelength_nm)?),
            None => None,
        };
        out.insert(
            name.clone(),
            ResolvedMaterial {
                reflectance: r,
                back_reflectance: rb,
                transmittance: t,
                bands: Vec::new(),
                rpv,
                band_rpv: Vec::new(),
                water: None,
            },
        );
    }
    Ok(out)
}
