//! Procedural scenes, deterministic from a seed: written as OBJ templates, instance tables
//! and a scene YAML in the spec's format, so they load like any user scene.
//!
//! - [`generate`] / [`generate_with_summary`] write a [`SceneKind`]: a forest after the RAMI-IV
//!   Järvselja birch stand (1029 trees of 7 species on a sloping hectare, over 10^8 facets
//!   once instanced), an orchard after the RAMI-V Wellington Citrus Orchard, flat soil, or a
//!   town of box buildings and sparse trees.
//! - [`canopy`] is the older, simpler crown generator the benchmark uses.
//!
//! The same kind, seed and options give byte-identical files: every random number comes from
//! seeded xorshift streams, templates are built in parallel but each from its own stream, and
//! nothing depends on time, hashing order or scheduling.

use crate::error::{Error, Result};
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

mod stand;
#[cfg(test)]
mod tests;
mod tree;

pub use tree::LeafAngle;

use crate::rng::Rand;

/// Which procedural scene to write.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SceneKind {
    /// Mixed broadleaf stand after the RAMI-IV Järvselja birch stand: trees of up to 7
    /// species templates (birch, alder, ash, aspen, linden, spruce, maple) on gently sloping
    /// terrain (a heightfield), leaves and bark as separate materials.
    Forest,
    /// Citrus trees in rows on flat ground, after the RAMI-V Wellington Citrus Orchard.
    Orchard,
    /// One soil plane, for DSM and calibration tests.
    Flat,
    /// Flat ground with box buildings (five per hectare) and sparse broadleaf trees: the
    /// airborne survey of the throughput bench, where first returns come from roofs, crowns
    /// and open ground alike.
    Town,
}

impl SceneKind {
    pub const ALL: [SceneKind; 4] = [
        SceneKind::Forest,
        SceneKind::Orchard,
        SceneKind::Flat,
        SceneKind::Town,
    ];

    /// The lowercase name used on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Forest => "forest",
            SceneKind::Orchard => "orchard",
            SceneKind::Flat => "flat",
            SceneKind::Town => "town",
        }
    }
}

impl std::fmt::Display for SceneKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Options of [`generate`]. `None` takes the kind's default (see [`GenerateOptions::defaults`]);
/// an option that does not apply to the kind (e.g. `slope` for an orchard) is an error rather
/// than silently ignored.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GenerateOptions {
    /// Extent of the scene in x and y, m, from (0, 0). Forest 100 × 100, orchard 108 × 104
    /// (the WCO), flat 100 × 100.
    pub size_m: Option<[f64; 2]>,
    /// Number of trees. Forest 1029 (the Järvselja stand), orchard 1105 (the WCO).
    pub trees: Option<usize>,
    /// Distinct tree templates, each written once and instanced. Forest 7 (one per species;
    /// beyond 7, further templates are size variants of the species in turn), orchard 3.
    pub templates: Option<usize>,
    /// Leaves per template, each a flat hexagon of 6 triangles. Forest 17 000 (102 000 leaf
    /// triangles per template, so that 1029 trees exceed 10^8 facets), orchard 8 000.
    pub leaves: Option<usize>,
    /// Target leaf area index (one-sided leaf area over ground area); leaf size is set from
    /// it. Forest 4.0, orchard 2.0. Met to within the rounding of the written coordinates.
    pub lai: Option<f64>,
    /// Forest only: terrain slope, rise over run, in a random direction. Default 0.03.
    pub slope: Option<f64>,
    /// Forest only: least distance between two trunks, m. Default 1.5.
    pub min_spacing_m: Option<f64>,
}

impl GenerateOptions {
    /// Every option that applies to `kind` set to its default, the others `None`.
    pub fn defaults(kind: SceneKind) -> GenerateOptions {
        match kind {
            SceneKind::Forest => GenerateOptions {
                size_m: Some([100.0, 100.0]),
                trees: Some(1029),
                templates: Some(7),
                leaves: Some(17_000),
                lai: Some(4.0),
                slope: Some(0.03),
                min_spacing_m: Some(1.5),
            },
            SceneKind::Orchard => GenerateOptions {
                size_m: Some([108.0, 104.0]),
                trees: Some(1105),
                templates: Some(3),
                leaves: Some(8_000),
                lai: Some(2.0),
                slope: None,
                min_spacing_m: None,
            },
            SceneKind::Flat => GenerateOptions {
                size_m: Some([100.0, 100.0]),
                ..GenerateOptions::default()
            },
            SceneKind::Town => GenerateOptions {
                size_m: Some([100.0, 100.0]),
                trees: Some(60),
                templates: Some(3),
                leaves: Some(250),
                lai: Some(0.4),
                slope: None,
                min_spacing_m: Some(4.0),
            },
        }
    }

    /// Fills defaults and checks ranges, with messages naming the option.
    fn resolve(&self, kind: SceneKind) -> Result<stand::StandOptions> {
        let d = GenerateOptions::defaults(kind);
        // named by the command line's flag where it has one
        let bad = |what: &str, why: String| {
            let flag = match what {
                "size_m" => "--size",
                "trees" => "--trees",
                "templates" => "--templates",
                "leaves" => "--leaves",
                "lai" => "--lai",
                other => other,
            };
            Err(Error::msg(format!("generate {kind}: {flag}: {why}")))
        };
        let fields: [(&str, bool, bool); 6] = [
            ("trees", self.trees.is_some(), d.trees.is_some()),
            ("templates", self.templates.is_some(), d.templates.is_some()),
            ("leaves", self.leaves.is_some(), d.leaves.is_some()),
            ("lai", self.lai.is_some(), d.lai.is_some()),
            ("slope", self.slope.is_some(), d.slope.is_some()),
            (
                "min_spacing_m",
                self.min_spacing_m.is_some(),
                d.min_spacing_m.is_some(),
            ),
        ];
        for (name, given, applies) in fields {
            if given && !applies {
                return bad(name, format!("does not apply to {kind} scenes"));
            }
        }
        let size = self.size_m.or(d.size_m).unwrap_or([100.0, 100.0]);
        if !size
            .iter()
            .all(|v| v.is_finite() && *v > 0.0 && *v <= 100_000.0)
        {
            return bad(
                "size_m",
                format!(
                    "expected two positive sizes up to 100 km, found {} × {}",
                    size[0], size[1]
                ),
            );
        }
        // five buildings a hectare, each placed apart from all the others: past 10,000 the
        // search runs for minutes and gives up (a 100 km town asked for 5·10^6)
        let buildings = 5.0 * size[0] * size[1] / 1e4;
        if kind == SceneKind::Town && buildings > MAX_BUILDINGS as f64 {
            return bad(
                "size_m",
                format!(
                    "a town of {} × {} m holds {:.0} buildings (5 per hectare), more than the {MAX_BUILDINGS} one town can have: make it at most 2000 ha (e.g. 4400 m × 4400 m)",
                    size[0], size[1], buildings
                ),
            );
        }
        let r = stand::StandOptions {
            size,
            trees: self.trees.or(d.trees).unwrap_or(0),
            templates: self.templates.or(d.templates).unwrap_or(0),
            leaves: self.leaves.or(d.leaves).unwrap_or(0),
            lai: self.lai.or(d.lai).unwrap_or(0.0),
            slope: self.slope.or(d.slope).unwrap_or(0.0),
            min_spacing_m: self.min_spacing_m.or(d.min_spacing_m).unwrap_or(0.0),
        };
        if kind == SceneKind::Flat {
            return Ok(r);
        }
        if !(1..=10_000_000).contains(&r.trees) {
            return bad("trees", format!("expected 1 to 10^7, found {}", r.trees));
        }
        if !(1..=1000).contains(&r.templates) {
            return bad(
                "templates",
                format!("expected 1 to 1000, found {}", r.templates),
            );
        }
        if !(1..=10_000_000).contains(&r.leaves) {
            return bad("leaves", format!("expected 1 to 10^7, found {}", r.leaves));
        }
        if !(r.lai.is_finite() && r.lai > 0.0 && r.lai <= 20.0) {
            return bad(
                "lai",
                format!("expected a value in (0, 20], found {}", r.lai),
            );
        }
        if !(r.slope.is_finite() && (0.0..=1.0).contains(&r.slope)) {
            return bad(
                "slope",
                format!("expected 0 to 1 (rise over run), found {}", r.slope),
            );
        }
        if !(r.min_spacing_m.is_finite() && r.min_spacing_m >= 0.0) {
            return bad(
                "min_spacing_m",
                format!("expected a distance ≥ 0, found {}", r.min_spacing_m),
            );
        }
        Ok(r)
    }
}

/// Most buildings a generated town holds (five a hectare: 2000 ha).
const MAX_BUILDINGS: usize = 10_000;

/// One tree template of a generated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct TemplateSummary {
    /// File stem of the template's OBJ and instance table (`birch` for birch.obj, birch.csv).
    pub name: String,
    /// Species, with its Latin name.
    pub species: String,
    /// Instances of the template.
    pub trees: usize,
    /// Triangles of the template (bark and leaves).
    pub facets: u64,
    /// One-sided leaf area of all its instances together, m².
    pub leaf_area_m2: f64,
}

/// What [`generate_with_summary`] wrote. Facet counts include the ground and equal
/// `Scene::stats()` of the loaded scene (`instanced_triangles`, `distinct_triangles`); areas
/// are computed from the coordinates as written.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneratedSummary {
    pub kind: SceneKind,
    pub seed: u64,
    /// The scene file (also the last entry of `files`).
    pub scene: PathBuf,
    /// Every file written, the scene file last.
    pub files: Vec<PathBuf>,
    /// Total size of the files written, bytes.
    pub bytes: u64,
    pub trees: usize,
    /// Box buildings (a town), all in one mesh.
    pub buildings: usize,
    /// The templates (species) in the scene file's order; empty for a flat scene.
    pub templates: Vec<TemplateSummary>,
    /// Facets once instanced.
    pub facets: u64,
    /// Facets stored once (sum over templates, plus the ground).
    pub distinct_facets: u64,
    /// One-sided leaf area, instance scales included, m².
    pub leaf_area_m2: f64,
    /// Horizontal area of the ground, m².
    pub ground_area_m2: f64,
    /// `leaf_area_m2 / ground_area_m2`.
    pub lai: f64,
}

/// Writes a procedural scene into `out_dir` (created if needed; files of the same names are
/// replaced atomically) and returns the path of its scene file (`forest.yaml`, `orchard.yaml`
/// or `flat.yaml`). See [`generate_with_summary`] for the figures.
pub fn generate(
    kind: SceneKind,
    seed: u64,
    out_dir: &Path,
    opts: &GenerateOptions,
) -> Result<PathBuf> {
    generate_with_summary(kind, seed, out_dir, opts).map(|s| s.scene)
}

/// As [`generate`], returning what was written: files, trees, templates, facets and the
/// leaf area index.
pub fn generate_with_summary(
    kind: SceneKind,
    seed: u64,
    out_dir: &Path,
    opts: &GenerateOptions,
) -> Result<GeneratedSummary> {
    let o = opts.resolve(kind)?;
    std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, "cannot create folder", e))?;
    match kind {
        SceneKind::Forest => stand::forest(seed, out_dir, &o),
        SceneKind::Orchard => stand::orchard(seed, out_dir, &o),
        SceneKind::Flat => stand::flat(seed, out_dir, &o),
        SceneKind::Town => stand::town(seed, out_dir, &o),
    }
}

/// A canopy of tree crowns over flat ground.
#[derive(Clone, Debug)]
pub struct Canopy {
    /// Side of the square scene, m (from 0 to `size` in x and y).
    pub size: f64,
    /// Number of crowns.
    pub trees: usize,
    /// Distinct crown templates, instanced with random rotation and scale.
    pub templates: usize,
    /// Leaves per template.
    pub leaves: usize,
    /// Leaf side, m (equilateral triangles).
    pub leaf_m: f64,
    pub seed: u64,
}

impl Default for Canopy {
    fn default() -> Self {
        Canopy {
            size: 100.0,
            trees: 700,
            templates: 5,
            leaves: 20_000,
            leaf_m: 0.08,
            seed: 1,
        }
    }
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    crate::fsutil::write_text_atomic(path, text)
}

/// Writes the canopy into `dir` and returns the scene file's path.
///
/// The default (700 crowns of 20000 leaves of 2.8 cm² on a hectare) has a leaf area index of
/// about 4, a closed broadleaf stand like the paper's birch forest, where multiple scattering
/// carries about a quarter of the 1064 nm return.
/// Crowns are ellipsoids 2.5-3.5 m wide and 3-5 m tall whose base sits 4-7 m up; leaves are
/// placed uniformly in the crown with uniformly random orientation (a spherical leaf-angle
/// distribution). Optical properties at 532/1064 nm are typical broadleaf values (leaf
/// ρ 0.10/0.45, τ 0.05/0.45) over a soil of ρ 0.12/0.30.
///
/// One random stream in a fixed draw order makes the canopy, so its steps stay in one
/// function.
pub fn canopy(dir: &Path, c: &Canopy) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, "cannot create folder", e))?;
    let mut rng = Rand::new(c.seed);
    let mut objects = String::new();
    for k in 0..c.templates {
        let (rx, rz) = (1.25 + 0.5 * rng.uniform(), 1.5 + rng.uniform());
        let base = 4.0 + 3.0 * rng.uniform();
        let mut obj = format!("# crown template {k}: {} leaves\n", c.leaves);
        for i in 0..c.leaves {
            // uniform in the unit ball by rejection
            let p = loop {
                let p = [
                    2.0 * rng.uniform() - 1.0,
                    2.0 * rng.uniform() - 1.0,
                    2.0 * rng.uniform() - 1.0,
                ];
                if p[0] * p[0] + p[1] * p[1] + p[2] * p[2] <= 1.0 {
                    break p;
                }
            };
            let centre = [p[0] * rx, p[1] * rx, base + rz * (1.0 + p[2])];
            // a random orthonormal pair spans the leaf's plane
            let z = 2.0 * rng.uniform() - 1.0;
            let phi = 2.0 * PI * rng.uniform();
            let r = (1.0 - z * z).sqrt();
            let n = [r * phi.cos(), r * phi.sin(), z];
            let a = if n[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let mut u = [
                n[1] * a[2] - n[2] * a[1],
                n[2] * a[0] - n[0] * a[2],
                n[0] * a[1] - n[1] * a[0],
            ];
            let ul = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
            u.iter_mut().for_each(|x| *x /= ul);
            let v = [
                n[1] * u[2] - n[2] * u[1],
                n[2] * u[0] - n[0] * u[2],
                n[0] * u[1] - n[1] * u[0],
            ];
            let spin = 2.0 * PI * rng.uniform();
            let s = c.leaf_m / 3f64.sqrt();
            for j in 0..3 {
                let ang = spin + j as f64 * 2.0 * PI / 3.0;
                let (ca, sa) = (ang.cos() * s, ang.sin() * s);
                let q = [
                    centre[0] + ca * u[0] + sa * v[0],
                    centre[1] + ca * u[1] + sa * v[1],
                    centre[2] + ca * u[2] + sa * v[2],
                ];
                let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", q[0], q[1], q[2]);
            }
            let _ = writeln!(obj, "f {} {} {}", 3 * i + 1, 3 * i + 2, 3 * i + 3);
        }
        write_file(&dir.join(format!("crown{k}.obj")), &obj)?;
        let mut table = String::from("# x y z rotation_deg scale\n");
        for t in 0..c.trees {
            if t % c.templates != k {
                continue;
            }
            let _ = writeln!(
                table,
                "{:.3} {:.3} 0 {:.2} {:.3}",
                c.size * rng.uniform(),
                c.size * rng.uniform(),
                360.0 * rng.uniform(),
                0.8 + 0.4 * rng.uniform()
            );
        }
        write_file(&dir.join(format!("crown{k}.csv")), &table)?;
        let _ = writeln!(
            objects,
            "  - mesh: {{ file: crown{k}.obj, material: leaf, class: vegetation, instances: crown{k}.csv }}"
        );
    }
    let yaml = format!(
        "# Generated canopy (seed {seed}): {trees} crowns of {templates} templates, {leaves} leaves each.\nname: canopy\nmaterials:\n  soil: {{ reflectance: {{ 532: 0.12, 1064: 0.30 }} }}\n  leaf: {{ reflectance: {{ 532: 0.10, 1064: 0.45 }}, transmittance: {{ 532: 0.05, 1064: 0.45 }} }}\nobjects:\n  - plane: {{ z: 0, extent: [[0, 0], [{size}, {size}]], material: soil }}\n{objects}",
        seed = c.seed,
        trees = c.trees,
        templates = c.templates,
        leaves = c.leaves,
        size = c.size,
    );
    let path = dir.join("canopy.yaml");
    write_file(&path, &yaml)?;
    Ok(path)
}
