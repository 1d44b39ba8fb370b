//! Values given per wavelength: one number for all, or a table `wavelength_nm: value` (scene
//! materials, the atmosphere's optical depths).

use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde::ser::{SerializeMap, Serializer};
use serde::{Deserialize, Serialize};
use std::fmt;

/// A value for all wavelengths, or a table wavelength_nm -> value.
#[derive(Debug, Clone, PartialEq)]
pub enum Spectral {
    Single(f64),
    Table(Vec<(f64, f64)>),
}

impl<'de> Deserialize<'de> for Spectral {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Spectral;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or a table of wavelength_nm: value")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<Spectral, E> {
                Ok(Spectral::Single(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Spectral, E> {
                Ok(Spectral::Single(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Spectral, E> {
                Ok(Spectral::Single(v as f64))
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut map: A,
            ) -> std::result::Result<Spectral, A::Error> {
                let mut table = Vec::new();
                while let Some(Wavelength(w)) = map.next_key::<Wavelength>()? {
                    let v: f64 = map.next_value()?;
                    if table.iter().any(|&(k, _)| k == w) {
                        return Err(de::Error::custom(format!(
                            "wavelength {w} nm is given twice"
                        )));
                    }
                    table.push((w, v));
                }
                if table.is_empty() {
                    return Err(de::Error::custom("the table is empty"));
                }
                Ok(Spectral::Table(table))
            }
        }
        d.deserialize_any(V)
    }
}

/// A table key: YAML integers (`532:`), floats (`532.5:`) and numeric strings are accepted.
struct Wavelength(f64);

impl<'de> Deserialize<'de> for Wavelength {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = Wavelength;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a wavelength in nm")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<Wavelength, E> {
                check_wavelength(v)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Wavelength, E> {
                check_wavelength(v as f64)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Wavelength, E> {
                check_wavelength(v as f64)
            }
            fn visit_str<E: de::Error>(self, v: &str) -> std::result::Result<Wavelength, E> {
                match v.trim().parse::<f64>() {
                    Ok(x) => check_wavelength(x),
                    Err(_) => Err(E::custom(format!(
                        "expected a wavelength in nm as key, found \"{v}\""
                    ))),
                }
            }
        }
        d.deserialize_any(V)
    }
}

fn check_wavelength<E: de::Error>(v: f64) -> std::result::Result<Wavelength, E> {
    if v.is_finite() && v > 0.0 {
        Ok(Wavelength(v))
    } else {
        Err(E::custom(format!(
            "wavelength {v} nm is not a positive number"
        )))
    }
}

impl Serialize for Spectral {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Spectral::Single(v) => s.serialize_f64(*v),
            Spectral::Table(t) => {
                let mut m = s.serialize_map(Some(t.len()))?;
                for (w, v) in t {
                    m.serialize_entry(w, v)?;
                }
                m.end()
            }
        }
    }
}

impl Spectral {
    /// The value at `wavelength_nm`, or why there is none.
    pub fn at(&self, wavelength_nm: f64) -> std::result::Result<f64, String> {
        match self {
            Spectral::Single(v) => Ok(*v),
            Spectral::Table(t) => t
                .iter()
                .find(|(w, _)| same_wavelength(*w, wavelength_nm))
                .map(|&(_, v)| v)
                .ok_or_else(|| {
                    let given: Vec<String> = t.iter().map(|(w, _)| format!("{w}")).collect();
                    format!(
                        "no value for {wavelength_nm} nm (the table gives {} nm); add {wavelength_nm}: <value> or give a single number",
                        given.join(", ")
                    )
                }),
        }
    }
}

fn same_wavelength(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

/// Most bands one campaign may trace at once: a path carries one throughput per band.
pub const MAX_BANDS: usize = 8;

/// The campaign's `wavelength_nm`: one number, or a list of bands traced in one pass (every
/// path traced once, one throughput per band). The first band is the campaign's wavelength
/// wherever one is needed alone.
#[derive(Debug, Clone, PartialEq)]
pub struct Wavelengths(Vec<f64>);

impl Wavelengths {
    pub fn one(wavelength_nm: f64) -> Wavelengths {
        Wavelengths(vec![wavelength_nm])
    }

    /// The first band.
    pub fn first(&self) -> f64 {
        self.0[0]
    }

    pub fn all(&self) -> &[f64] {
        &self.0
    }

    /// The index of a table row's band (`None`: a run of one band, index 0).
    pub fn index_of(&self, wavelength_nm: Option<f64>) -> usize {
        wavelength_nm
            .and_then(|w| self.0.iter().position(|&k| k == w))
            .unwrap_or(0)
    }

    /// True when the campaign traces several bands (its tables gain a `wavelength_nm` column).
    pub fn several(&self) -> bool {
        self.0.len() > 1
    }
}

impl<'de> Deserialize<'de> for Wavelengths {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Wavelengths;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a wavelength in nm or a list of them, e.g. [532, 1064]")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<Wavelengths, E> {
                Ok(Wavelengths(vec![v]))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Wavelengths, E> {
                Ok(Wavelengths(vec![v as f64]))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Wavelengths, E> {
                Ok(Wavelengths(vec![v as f64]))
            }
            fn visit_seq<A: de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> std::result::Result<Wavelengths, A::Error> {
                let mut v: Vec<f64> = Vec::new();
                while let Some(w) = seq.next_element::<f64>()? {
                    if v.iter().any(|&k| same_wavelength(k, w)) {
                        return Err(de::Error::custom(format!(
                            "wavelength {w} nm is listed twice"
                        )));
                    }
                    v.push(w);
                }
                if v.is_empty() {
                    return Err(de::Error::custom(
                        "the list of wavelengths is empty: give at least one, e.g. [1064]",
                    ));
                }
                if v.len() > MAX_BANDS {
                    return Err(de::Error::custom(format!(
                        "{} wavelengths listed; at most {MAX_BANDS} bands are traced in one pass",
                        v.len()
                    )));
                }
                Ok(Wavelengths(v))
            }
        }
        d.deserialize_any(V)
    }
}

impl Serialize for Wavelengths {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        if self.several() {
            self.0.serialize(s)
        } else {
            s.serialize_f64(self.0[0])
        }
    }
}

impl fmt::Display for Wavelengths {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let all: Vec<String> = self.0.iter().map(|w| w.to_string()).collect();
        f.write_str(&all.join(", "))
    }
}
