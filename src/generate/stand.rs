//! Stand layouts (forest, orchard, flat ground, town), their materials and scene files.

use super::tree::{self, fmt4, LeafAngle, Profile, TreeShape};
use super::{write_file, GeneratedSummary, SceneKind, TemplateSummary};
use crate::error::{Error, Result};
use crate::rng::{stream, Rand};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Options with every default filled in for one kind.
#[derive(Clone, Debug)]
pub(super) struct StandOptions {
    pub size: [f64; 2],
    pub trees: usize,
    pub templates: usize,
    pub leaves: usize,
    pub lai: f64,
    pub slope: f64,
    pub min_spacing_m: f64,
}

/// Optical properties at 532 and 1064 nm; a zero transmittance is left out of the file.
struct Optics {
    name: &'static str,
    reflectance: [f64; 2],
    transmittance: [f64; 2],
    source: &'static str,
}

/// Every value below is a rounded typical value, not a copy of one table: the source family is
/// named so that a user can replace it with measured spectra.
///
/// Soil under the forest and the flat scene: a moist, mid-brown mineral soil, of the order of
/// the soil/understory spectra of the RAMI-IV Järvselja scenes (HET07/HET09) and of soil
/// spectral libraries (ASTER/ECOSTRESS); ρ rises from green to the near infrared.
static SOIL: Optics = Optics {
    name: "soil",
    reflectance: [0.12, 0.30],
    transmittance: [0.0, 0.0],
    source: "typical moist mineral soil, rounded (RAMI-IV HET07/HET09 soil spectra, ASTER/ECOSTRESS library)",
};

/// Bark of most species: grey-brown bark, of the order of the RAMI-IV Järvselja bark spectra.
static BARK: Optics = Optics {
    name: "bark",
    reflectance: [0.20, 0.35],
    transmittance: [0.0, 0.0],
    source: "typical grey-brown bark, rounded (RAMI-IV HET07/HET09 Järvselja bark spectra)",
};

/// Birch bark is white: brighter than other bark in the visible, flatter into the NIR.
static BARK_BIRCH: Optics = Optics {
    name: "bark_birch",
    reflectance: [0.35, 0.45],
    transmittance: [0.0, 0.0],
    source: "white birch bark, rounded (RAMI-IV Järvselja birch bark spectra)",
};

/// One species of the forest: its shape at scale 1, share of the stems and optics.
struct Species {
    name: &'static str,
    latin: &'static str,
    share: f64,
    shape: TreeShape,
    leaf: Optics,
    bark: &'static Optics,
}

/// What the species below share unless they say otherwise.
const BROADLEAF: TreeShape = TreeShape {
    height: 20.0,
    crown_base: 8.0,
    crown_radius: 2.5,
    profile: Profile::Ellipsoid,
    trunk_radius: 0.15,
    branches: 90,
    branch_elevation_deg: 45.0,
    cluster_m: 0.5,
    leaf_angle: LeafAngle::Planophile,
    leaf_aspect: 1.2,
};

/// The seven species of the RAMI-IV Järvselja birch stand (HET07/HET09), birch dominant.
/// Heights, crown sizes and stem shares are rounded, plausible values for a mature mixed
/// hemiboreal stand (birch, aspen and ash in the upper layer; linden, maple and spruce below),
/// not the stand's inventory. Leaf-angle classes are assigned per species in the spirit of
/// published measurements of broadleaf inclination (e.g. Pisek et al. 2013, Agric. For.
/// Meteorol. 169: most temperate broadleaves planophile to plagiophile; aspen leaves, on
/// flattened petioles, steeper); birch keeps the spherical default of radiative transfer
/// models and spruce shoots are taken as uniform.
///
/// Leaf ρ/τ at 532/1064 nm are typical broadleaf values as given by PROSPECT simulations
/// (Jacquemoud & Baret 1990; Feret et al. 2008) for a mature green leaf (N≈1.5, Cab≈40 µg/cm²)
/// and by LOPEX93 measurements (Hosgood et al. 1995), rounded and varied a little per
/// species; spruce is a shoot-level value (needles clumped: lower transmittance).
static SPECIES: [Species; 7] = [
    Species {
        name: "birch",
        latin: "Betula pendula",
        share: 0.42,
        shape: TreeShape {
            height: 22.0,
            crown_base: 10.0,
            crown_radius: 2.6,
            profile: Profile::Ellipsoid,
            trunk_radius: 0.16,
            branch_elevation_deg: 45.0,
            leaf_angle: LeafAngle::Spherical,
            leaf_aspect: 1.4,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "leaf_birch",
            reflectance: [0.08, 0.47],
            transmittance: [0.05, 0.45],
            source: "birch leaf (PROSPECT / LOPEX93 typical values)",
        },
        bark: &BARK_BIRCH,
    },
    Species {
        name: "alder",
        latin: "Alnus glutinosa",
        share: 0.12,
        shape: TreeShape {
            height: 19.0,
            crown_base: 8.0,
            crown_radius: 2.3,
            profile: Profile::Ellipsoid,
            trunk_radius: 0.15,
            branch_elevation_deg: 50.0,
            leaf_angle: LeafAngle::Planophile,
            leaf_aspect: 1.2,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "leaf_alder",
            reflectance: [0.07, 0.44],
            transmittance: [0.04, 0.43],
            source: "dark green alder leaf (PROSPECT / LOPEX93 typical values)",
        },
        bark: &BARK,
    },
    Species {
        name: "ash",
        latin: "Fraxinus excelsior",
        share: 0.06,
        shape: TreeShape {
            height: 24.0,
            crown_base: 12.0,
            crown_radius: 2.8,
            profile: Profile::Ellipsoid,
            trunk_radius: 0.18,
            branch_elevation_deg: 55.0,
            leaf_angle: LeafAngle::Plagiophile,
            leaf_aspect: 2.5,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "leaf_ash",
            reflectance: [0.09, 0.46],
            transmittance: [0.05, 0.45],
            source: "ash leaflet (PROSPECT / LOPEX93 typical values)",
        },
        bark: &BARK,
    },
    Species {
        name: "aspen",
        latin: "Populus tremula",
        share: 0.08,
        shape: TreeShape {
            height: 25.0,
            crown_base: 14.0,
            crown_radius: 2.4,
            profile: Profile::Ellipsoid,
            trunk_radius: 0.17,
            branch_elevation_deg: 60.0,
            leaf_angle: LeafAngle::Erectophile,
            leaf_aspect: 1.0,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "leaf_aspen",
            reflectance: [0.09, 0.45],
            transmittance: [0.06, 0.44],
            source: "aspen leaf (PROSPECT / LOPEX93 typical values)",
        },
        bark: &BARK,
    },
    Species {
        name: "linden",
        latin: "Tilia cordata",
        share: 0.14,
        shape: TreeShape {
            height: 15.0,
            crown_base: 4.0,
            crown_radius: 2.2,
            profile: Profile::Ellipsoid,
            trunk_radius: 0.12,
            branch_elevation_deg: 40.0,
            leaf_angle: LeafAngle::Planophile,
            leaf_aspect: 1.1,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "leaf_linden",
            reflectance: [0.08, 0.48],
            transmittance: [0.05, 0.46],
            source: "linden leaf (PROSPECT / LOPEX93 typical values)",
        },
        bark: &BARK,
    },
    Species {
        name: "spruce",
        latin: "Picea abies",
        share: 0.12,
        shape: TreeShape {
            height: 20.0,
            crown_base: 2.0,
            crown_radius: 2.0,
            profile: Profile::Cone,
            trunk_radius: 0.14,
            branch_elevation_deg: -15.0,
            leaf_angle: LeafAngle::Uniform,
            leaf_aspect: 3.0,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "shoot_spruce",
            reflectance: [0.06, 0.38],
            transmittance: [0.02, 0.30],
            source:
                "spruce shoot, needles clumped (PROSPECT needle runs / RAMI-IV spruce, rounded)",
        },
        bark: &BARK,
    },
    Species {
        name: "maple",
        latin: "Acer platanoides",
        share: 0.06,
        shape: TreeShape {
            height: 13.0,
            crown_base: 4.0,
            crown_radius: 2.3,
            profile: Profile::Ellipsoid,
            trunk_radius: 0.11,
            branch_elevation_deg: 45.0,
            leaf_angle: LeafAngle::Planophile,
            leaf_aspect: 1.0,
            ..BROADLEAF
        },
        leaf: Optics {
            name: "leaf_maple",
            reflectance: [0.08, 0.46],
            transmittance: [0.05, 0.45],
            source: "maple leaf (PROSPECT / LOPEX93 typical values)",
        },
        bark: &BARK,
    },
];

/// Citrus trees of the RAMI-V Wellington Citrus Orchard: leaf, wood and ground values are
/// the means over CTR1..CTR10 of the RAMI-V WCO surface table (shared/data/rami-wco/
/// spectral.txt), interpolated linearly between band centres (532 nm between O04 and O06,
/// 1064 nm between O17 and MD5).
static CITRUS_LEAF: Optics = Optics {
    name: "leaf_citrus",
    reflectance: [0.122, 0.613],
    transmittance: [0.031, 0.314],
    source: "RAMI-V WCO CTR1-10 foliage, interpolated to 532/1064 nm",
};
static CITRUS_WOOD: Optics = Optics {
    name: "bark_citrus",
    reflectance: [0.157, 0.440],
    transmittance: [0.0, 0.0],
    source: "RAMI-V WCO wood, interpolated to 532/1064 nm",
};
static ORCHARD_SOIL: Optics = Optics {
    name: "soil",
    reflectance: [0.128, 0.374],
    transmittance: [0.0, 0.0],
    source: "RAMI-V WCO ground, interpolated to 532/1064 nm",
};

/// A citrus tree: a dense ellipsoidal crown from 0.6 m to 3.6 m on a short trunk.
const CITRUS: TreeShape = TreeShape {
    height: 3.6,
    crown_base: 0.6,
    crown_radius: 1.5,
    profile: Profile::Ellipsoid,
    trunk_radius: 0.08,
    branches: 40,
    branch_elevation_deg: 40.0,
    cluster_m: 0.35,
    leaf_angle: LeafAngle::Spherical,
    leaf_aspect: 2.0,
};

fn material_line(yaml: &mut String, o: &Optics) {
    let [r1, r2] = o.reflectance;
    let _ = write!(
        yaml,
        "  {}: {{ reflectance: {{ 532: {r1}, 1064: {r2} }}",
        o.name
    );
    if o.transmittance != [0.0, 0.0] {
        let [t1, t2] = o.transmittance;
        let _ = write!(yaml, ", transmittance: {{ 532: {t1}, 1064: {t2} }}");
    }
    let _ = writeln!(yaml, " }}   # {}", o.source);
}

/// The bark and leaf materials of the templates, each once, in the templates' order.
fn template_materials(yaml: &mut String, plans: &[TemplatePlan]) {
    let mut names: Vec<&str> = Vec::new();
    for m in plans.iter().flat_map(|p| [p.bark, p.leaf]) {
        if !names.contains(&m.name) {
            names.push(m.name);
            material_line(yaml, m);
        }
    }
}

fn round4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

/// Files written so far, for the summary.
#[derive(Default)]
struct Written {
    files: Vec<PathBuf>,
    bytes: u64,
}

impl Written {
    fn write(&mut self, path: PathBuf, text: &str) -> Result<()> {
        write_file(&path, text)?;
        self.bytes += text.len() as u64;
        self.files.push(path);
        Ok(())
    }
}

/// One placed tree.
struct PlacedTree {
    x: f64,
    y: f64,
    z: f64,
    rotation_deg: f64,
    scale: f64,
    template: usize,
}

/// A template to build: its file stem, species label, shape, optics, and tree count.
struct TemplatePlan<'a> {
    stem: String,
    species: String,
    shape: TreeShape,
    leaf: &'a Optics,
    bark: &'a Optics,
}

/// Builds and writes every template (in parallel: each has its own generator, so the files
/// do not depend on the schedule), then the instance tables. Leaf size per template is set so
/// that the stand's one-sided leaf area is `lai` × `ground_area`, leaf area per tree being
/// taken proportional to the crown's projected area.
#[allow(clippy::too_many_arguments)]
fn trees(
    seed: u64,
    dir: &Path,
    plans: &[TemplatePlan],
    placed: &[PlacedTree],
    leaves: usize,
    lai: f64,
    ground_area: f64,
    out: &mut Written,
) -> Result<(Vec<TemplateSummary>, String)> {
    let weight = |p: &TemplatePlan| PI * p.shape.crown_radius * p.shape.crown_radius;
    let denom: f64 = placed
        .iter()
        .map(|t| weight(&plans[t.template]) * t.scale * t.scale)
        .sum();
    let k = lai * ground_area / denom;
    let built: Vec<Result<(tree::Template, PathBuf)>> = plans
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let mut rng = stream(seed, 1000 + i as u64);
            let title = format!(
                "{} template {i} (lidarsim scene generate, seed {seed})",
                p.species
            );
            let t = tree::build(
                &p.shape,
                leaves,
                k * weight(p) / leaves as f64,
                &mut rng,
                &title,
            );
            let path = dir.join(format!("{}.obj", p.stem));
            write_file(&path, &t.obj)?;
            Ok((t, path))
        })
        .collect();
    let mut summaries = Vec::with_capacity(plans.len());
    let mut objects = String::new();
    for (i, (b, p)) in built.into_iter().zip(plans).enumerate() {
        let (t, path) = b?;
        out.bytes += t.obj.len() as u64;
        out.files.push(path);
        let mut table = String::from("# x y z rotation_deg scale\n");
        let mut count = 0;
        let mut leaf_area = 0.0;
        for r in placed.iter().filter(|r| r.template == i) {
            fmt4(&mut table, r.x);
            table.push(' ');
            fmt4(&mut table, r.y);
            table.push(' ');
            fmt4(&mut table, r.z);
            let _ = writeln!(table, " {:.2} {:.4}", r.rotation_deg, r.scale);
            count += 1;
            leaf_area += t.leaf_area * r.scale * r.scale;
        }
        out.write(dir.join(format!("{}.csv", p.stem)), &table)?;
        let _ = writeln!(
            objects,
            "  - mesh: {{ file: {s}.obj, materials: {{ leaves: {l}, bark: {b} }}, class: vegetation, instances: {s}.csv }}",
            s = p.stem,
            l = p.leaf.name,
            b = p.bark.name,
        );
        summaries.push(TemplateSummary {
            name: p.stem.clone(),
            species: p.species.clone(),
            trees: count,
            facets: t.triangles,
            leaf_area_m2: leaf_area,
        });
    }
    Ok((summaries, objects))
}

/// Heights of the terrain on a grid; `z` reproduces the heightfield's own triangles.
struct Terrain {
    cell: f64,
    rows: usize,
    cols: usize,
    z: Vec<f64>,
}

impl Terrain {
    /// Height of the surface the loader builds: cell (i, j) is split along its diagonal into
    /// (v00, v10, v11) and (v00, v11, v01), as in `mesh::heightfield`.
    fn z(&self, x: f64, y: f64) -> f64 {
        let gx = x / self.cell;
        let gy = y / self.cell;
        let j = (gx.floor() as usize).min(self.cols - 2);
        let i = (gy.floor() as usize).min(self.rows - 2);
        let (fx, fy) = (gx - j as f64, gy - i as f64);
        let at = |i: usize, j: usize| self.z[i * self.cols + j];
        let (z00, z10, z01, z11) = (at(i, j), at(i, j + 1), at(i + 1, j), at(i + 1, j + 1));
        if fx >= fy {
            z00 + fx * (z10 - z00) + fy * (z11 - z10)
        } else {
            z00 + fy * (z01 - z00) + fx * (z11 - z01)
        }
    }
}

/// A plane of the given slope in a random direction, plus three long, low undulations
/// (5 cm amplitude, 30-70 m wavelength) so that the ground is not a perfect plane.
fn terrain(rng: &mut Rand, size: [f64; 2], slope: f64) -> Terrain {
    // at most about 400 cells a side: finer adds triangles, not realism
    let cell = (size[0].max(size[1]) / 400.0).max(1.0);
    let cols = (size[0] / cell - 1e-9).ceil() as usize + 1;
    let rows = (size[1] / cell - 1e-9).ceil() as usize + 1;
    let az = 2.0 * PI * rng.uniform();
    let (c, s) = (az.cos(), az.sin());
    let waves: Vec<(f64, f64, f64)> = (0..3)
        .map(|_| {
            let k = 2.0 * PI / (30.0 + 40.0 * rng.uniform());
            let dir = 2.0 * PI * rng.uniform();
            (k * dir.cos(), k * dir.sin(), 2.0 * PI * rng.uniform())
        })
        .collect();
    let (cx, cy) = (0.5 * size[0], 0.5 * size[1]);
    let mut z = Vec::with_capacity(rows * cols);
    for i in 0..rows {
        for j in 0..cols {
            let (x, y) = (j as f64 * cell, i as f64 * cell);
            let mut h = slope * ((x - cx) * c + (y - cy) * s);
            for &(kx, ky, ph) in &waves {
                h += 0.05 * (kx * x + ky * y + ph).cos();
            }
            z.push(round4(h));
        }
    }
    Terrain {
        cell,
        rows,
        cols,
        z,
    }
}

/// Dart throwing: uniform positions, none closer than `min` to another (a hard-core process,
/// like stems in a natural stand). Positions are rounded as written.
fn positions(rng: &mut Rand, size: [f64; 2], n: usize, min: f64) -> Result<Vec<[f64; 2]>> {
    // Disjoint disks of diameter `min` centred on the stand lie within it grown by min/2 on
    // every side, so no more than that area over a disk's fit: a count beyond it is refused at
    // once (the search would fail only after its attempts ran out, minutes for a large count).
    let most = (size[0] + min) * (size[1] + min) / (std::f64::consts::PI / 4.0 * min * min);
    if n as f64 > most {
        return Err(Error::msg(format!(
            "generate: cannot place {n} trees at least {min} m apart on {} × {} m (no more than {} fit); lower the tree count or the spacing",
            size[0],
            size[1],
            most.floor()
        )));
    }
    // The grid only speeds up the search for neighbours: any cell at least `min` finds them
    // (the same positions whatever its size), and one of about a tree's share of the stand
    // keeps it small on a large stand of few trees.
    let cell = min
        .max(0.5)
        .max((size[0] * size[1] / n.max(1) as f64).sqrt());
    let gx = (size[0] / cell).ceil() as usize + 1;
    let gy = (size[1] / cell).ceil() as usize + 1;
    let mut grid: Vec<Vec<u32>> = vec![Vec::new(); gx * gy];
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(n);
    let mut attempts = 0usize;
    let limit = 1000 * n + 10_000;
    while out.len() < n {
        attempts += 1;
        if attempts > limit {
            return Err(Error::msg(format!(
                "generate: cannot place {n} trees at least {min} m apart on {} × {} m (placed {}); lower the tree count or the spacing",
                size[0],
                size[1],
                out.len()
            )));
        }
        let p = [
            round4(size[0] * rng.uniform()),
            round4(size[1] * rng.uniform()),
        ];
        let (ci, cj) = ((p[0] / cell) as usize, (p[1] / cell) as usize);
        let mut free = true;
        'near: for i in ci.saturating_sub(1)..=(ci + 1).min(gx - 1) {
            for j in cj.saturating_sub(1)..=(cj + 1).min(gy - 1) {
                for &q in &grid[j * gx + i] {
                    let q = out[q as usize];
                    if (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) < min * min {
                        free = false;
                        break 'near;
                    }
                }
            }
        }
        if free {
            grid[cj * gx + ci].push(out.len() as u32);
            out.push(p);
        }
    }
    Ok(out)
}

/// Index drawn with probability proportional to `weights`.
fn pick(rng: &mut Rand, weights: &[f64]) -> usize {
    let total: f64 = weights.iter().sum();
    let mut x = total * rng.uniform();
    for (i, &w) in weights.iter().enumerate() {
        if x < w {
            return i;
        }
        x -= w;
    }
    weights.len() - 1
}

fn header(kind: SceneKind, seed: u64, lines: &[String]) -> String {
    let mut s = format!(
        "# Procedural {} scene written by lidarsim scene generate (seed {seed}).\n",
        kind.name()
    );
    for l in lines {
        let _ = writeln!(s, "# {l}");
    }
    s
}

/// The scene file's parts that every stand has besides its trees.
struct StandFile<'a> {
    kind: SceneKind,
    plans: &'a [TemplatePlan<'a>],
    placed: &'a [PlacedTree],
    ground_area: f64,
    ground_facets: u64,
    /// The materials listed before the templates' own, and whether those follow.
    materials: &'a [&'a Optics],
    template_materials: bool,
    /// The YAML lines of the objects before the trees (the ground first).
    objects: String,
    /// Buildings beside the trees, and their facets.
    buildings: usize,
    building_facets: u64,
}

/// What every stand does once its trees are placed: the templates' meshes and instance
/// tables, then the scene file (its header from `header`, given the summary), written last.
fn write_stand(
    seed: u64,
    dir: &Path,
    o: &StandOptions,
    s: StandFile,
    mut out: Written,
    header_lines: impl FnOnce(&GeneratedSummary) -> Vec<String>,
) -> Result<GeneratedSummary> {
    let (summaries, objects) = trees(
        seed,
        dir,
        s.plans,
        s.placed,
        o.leaves,
        o.lai,
        s.ground_area,
        &mut out,
    )?;
    let mut summary = summarize(
        s.kind,
        seed,
        dir,
        out,
        summaries,
        s.ground_facets,
        s.ground_area,
    );
    summary.facets += s.building_facets;
    summary.buildings = s.buildings;
    summary.distinct_facets += s.building_facets;
    let mut yaml = header(s.kind, seed, &header_lines(&summary));
    let _ = writeln!(yaml, "name: {}\nmaterials:", s.kind.name());
    for m in s.materials {
        material_line(&mut yaml, m);
    }
    if s.template_materials {
        template_materials(&mut yaml, s.plans);
    }
    yaml.push_str("objects:\n");
    yaml.push_str(&s.objects);
    yaml.push_str(&objects);
    finish(summary, dir.join(format!("{}.yaml", s.kind.name())), &yaml)
}

/// A forest stand: terrain, species templates, tree positions, instance tables, scene file,
/// in the order of one random stream (the draw order makes the stand); the steps are
/// helpers (`terrain`, `positions`, `trees`), this function is their sequence and the YAML.
pub(super) fn forest(seed: u64, dir: &Path, o: &StandOptions) -> Result<GeneratedSummary> {
    let mut out = Written::default();
    let mut rng = stream(seed, 0);
    let ground = terrain(&mut rng, o.size, o.slope);
    let ground_area = (ground.cols - 1) as f64 * (ground.rows - 1) as f64 * ground.cell.powi(2);
    let mut csv = String::with_capacity(ground.rows * ground.cols * 9);
    for i in 0..ground.rows {
        for j in 0..ground.cols {
            if j > 0 {
                csv.push(',');
            }
            fmt4(&mut csv, ground.z[i * ground.cols + j]);
        }
        csv.push('\n');
    }
    out.write(dir.join("terrain.csv"), &csv)?;

    let templates = o.templates.min(o.trees);
    let plans: Vec<TemplatePlan> = (0..templates)
        .map(|k| {
            let sp = &SPECIES[k % SPECIES.len()];
            let round = k / SPECIES.len();
            let mut shape = sp.shape.clone();
            if round > 0 {
                // further templates of a species are its variants
                let mut r = stream(seed, 500 + k as u64);
                shape.height *= 0.9 + 0.2 * r.uniform();
                shape.crown_base *= 0.9 + 0.2 * r.uniform();
                shape.crown_radius *= 0.9 + 0.2 * r.uniform();
            }
            TemplatePlan {
                stem: if round == 0 {
                    sp.name.to_string()
                } else {
                    format!("{}_{}", sp.name, round + 1)
                },
                species: format!("{} ({})", sp.name, sp.latin),
                shape,
                leaf: &sp.leaf,
                bark: sp.bark,
            }
        })
        .collect();
    let weights: Vec<f64> = (0..templates)
        .map(|k| {
            let n = (templates - k % SPECIES.len()).div_ceil(SPECIES.len());
            SPECIES[k % SPECIES.len()].share / n as f64
        })
        .collect();
    let xy = positions(&mut rng, o.size, o.trees, o.min_spacing_m)?;
    let placed: Vec<PlacedTree> = xy
        .iter()
        .enumerate()
        .map(|(i, p)| {
            // every template gets a tree, so that no instance table is empty
            let template = if i < templates {
                i
            } else {
                pick(&mut rng, &weights)
            };
            PlacedTree {
                x: p[0],
                y: p[1],
                z: round4(ground.z(p[0], p[1])),
                rotation_deg: (36_000.0 * rng.uniform()).round() / 100.0,
                scale: round4(0.8 + 0.4 * rng.uniform()),
                template,
            }
        })
        .collect();
    let file = StandFile {
        kind: SceneKind::Forest,
        plans: &plans,
        placed: &placed,
        ground_area,
        ground_facets: 2 * (ground.rows - 1) as u64 * (ground.cols - 1) as u64,
        materials: &[&SOIL],
        template_materials: true,
        objects: format!(
            "  - heightfield: {{ file: terrain.csv, cell_m: {}, material: soil, class: ground }}\n",
            ground.cell
        ),
        buildings: 0,
        building_facets: 0,
    };
    write_stand(seed, dir, o, file, out, |summary| {
        vec![
            format!(
                "{} trees of {} species templates on {} × {} m, after the RAMI-IV Järvselja birch stand;",
                summary.trees,
                summary.templates.len(),
                o.size[0],
                o.size[1]
            ),
            format!(
                "terrain slope {}, leaf area index {:.3}, {} facets once instanced ({} distinct).",
                o.slope, summary.lai, summary.facets, summary.distinct_facets
            ),
        ]
    })
}

/// An orchard (the WCO layout: rows of one species); long for the same reason as [`forest`].
pub(super) fn orchard(seed: u64, dir: &Path, o: &StandOptions) -> Result<GeneratedSummary> {
    // WCO: rows about 4.5 m apart along y, trees 2 m apart in a row, some missing
    const ROW_M: f64 = 4.5;
    const TREE_M: f64 = 2.0;
    let out = Written::default();
    let mut rng = stream(seed, 0);
    let rows = (o.size[0] / ROW_M).floor().max(1.0) as usize;
    let slots = (o.size[1] / TREE_M).floor().max(1.0) as usize;
    if o.trees > rows * slots {
        return Err(Error::msg(format!(
            "generate: an orchard of {} × {} m has room for {} trees ({rows} rows of {slots}, {ROW_M} m × {TREE_M} m apart), not {}",
            o.size[0],
            o.size[1],
            rows * slots,
            o.trees
        )));
    }
    let x0 = 0.5 * (o.size[0] - (rows - 1) as f64 * ROW_M);
    let y0 = 0.5 * (o.size[1] - (slots - 1) as f64 * TREE_M);
    // the first `trees` of a random permutation of the slots are planted
    let mut all: Vec<usize> = (0..rows * slots).collect();
    let n = all.len();
    for i in 0..o.trees {
        let j = i + ((n - i) as f64 * rng.uniform()) as usize;
        all.swap(i, j.min(n - 1));
    }
    let mut kept = all[..o.trees].to_vec();
    kept.sort_unstable();
    let templates = o.templates.min(o.trees);
    let placed: Vec<PlacedTree> = kept
        .iter()
        .enumerate()
        .map(|(i, &slot)| {
            let (r, s) = (slot / slots, slot % slots);
            PlacedTree {
                x: round4(x0 + r as f64 * ROW_M + 0.1 * (rng.uniform() - 0.5)),
                y: round4(y0 + s as f64 * TREE_M + 0.2 * (rng.uniform() - 0.5)),
                z: 0.0,
                rotation_deg: (36_000.0 * rng.uniform()).round() / 100.0,
                scale: round4(0.9 + 0.2 * rng.uniform()),
                template: if i < templates {
                    i
                } else {
                    (templates as f64 * rng.uniform()) as usize % templates
                },
            }
        })
        .collect();
    let plans: Vec<TemplatePlan> = (0..templates)
        .map(|k| {
            let mut shape = CITRUS.clone();
            let mut r = stream(seed, 500 + k as u64);
            shape.height *= 0.9 + 0.2 * r.uniform();
            shape.crown_radius *= 0.9 + 0.2 * r.uniform();
            TemplatePlan {
                stem: format!("citrus{}", k + 1),
                species: "citrus (Citrus sinensis)".to_string(),
                shape,
                leaf: &CITRUS_LEAF,
                bark: &CITRUS_WOOD,
            }
        })
        .collect();
    let file = StandFile {
        kind: SceneKind::Orchard,
        plans: &plans,
        placed: &placed,
        ground_area: o.size[0] * o.size[1],
        ground_facets: 2,
        materials: &[&ORCHARD_SOIL, &CITRUS_WOOD, &CITRUS_LEAF],
        template_materials: false,
        objects: ground_plane(o),
        buildings: 0,
        building_facets: 0,
    };
    write_stand(seed, dir, o, file, out, |summary| {
        vec![
            format!(
                "{} citrus trees of {} templates in rows {ROW_M} m apart, {TREE_M} m apart in a row, on {} × {} m,",
                summary.trees,
                summary.templates.len(),
                o.size[0],
                o.size[1]
            ),
            format!(
                "after the RAMI-V Wellington Citrus Orchard; leaf area index {:.3}, {} facets once instanced.",
                summary.lai, summary.facets
            ),
        ]
    })
}

/// The flat ground plane of a stand, as a scene file's object line.
fn ground_plane(o: &StandOptions) -> String {
    format!(
        "  - plane: {{ z: 0, extent: [[0, 0], [{}, {}]], material: soil, class: ground }}\n",
        o.size[0], o.size[1]
    )
}

pub(super) fn flat(seed: u64, dir: &Path, o: &StandOptions) -> Result<GeneratedSummary> {
    let area = o.size[0] * o.size[1];
    let summary = summarize(
        SceneKind::Flat,
        seed,
        dir,
        Written::default(),
        Vec::new(),
        2,
        area,
    );
    let mut yaml = header(
        SceneKind::Flat,
        seed,
        &[format!(
            "Bare soil, {} × {} m, for DSM and calibration tests.",
            o.size[0], o.size[1]
        )],
    );
    yaml.push_str("name: flat\nmaterials:\n");
    material_line(&mut yaml, &SOIL);
    let _ = writeln!(
        yaml,
        "objects:\n  - plane: {{ z: 0, extent: [[0, 0], [{}, {}]], material: soil, class: ground }}",
        o.size[0], o.size[1]
    );
    finish(summary, dir.join("flat.yaml"), &yaml)
}

/// Roofs: concrete and bitumen roofing, rounded (ASTER/ECOSTRESS man-made materials).
static ROOF: Optics = Optics {
    name: "roof",
    reflectance: [0.15, 0.25],
    transmittance: [0.0, 0.0],
    source: "typical concrete/bitumen roofing, rounded (ASTER/ECOSTRESS man-made materials)",
};

/// Walls: light render and brick, rounded (ASTER/ECOSTRESS man-made materials).
static WALL: Optics = Optics {
    name: "wall",
    reflectance: [0.30, 0.40],
    transmittance: [0.0, 0.0],
    source: "typical light render and brick, rounded (ASTER/ECOSTRESS man-made materials)",
};

/// One box building: centre, half sizes along its own axes, rotation about z and height.
struct Building {
    x: f64,
    y: f64,
    half: [f64; 2],
    rotation: f64,
    height: f64,
}

impl Building {
    /// Radius of the circle around its footprint.
    fn reach(&self) -> f64 {
        self.half[0].hypot(self.half[1])
    }

    /// Corners of the footprint, counter-clockwise seen from above.
    fn corners(&self) -> [[f64; 2]; 4] {
        let (s, c) = self.rotation.sin_cos();
        [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|[u, v]| {
            let (a, b) = (u * self.half[0], v * self.half[1]);
            [
                round4(self.x + a * c - b * s),
                round4(self.y + a * s + b * c),
            ]
        })
    }
}

/// The town's buildings: five per hectare, each inside the scene and at least 3 m from the
/// others, drawn from `rng` until that many fit.
fn place_buildings(rng: &mut crate::rng::Rand, o: &StandOptions) -> Result<Vec<Building>> {
    let ground_area = o.size[0] * o.size[1];
    let n_buildings = ((5.0 * ground_area / 1e4).round() as usize).max(1);
    let mut buildings: Vec<Building> = Vec::with_capacity(n_buildings);
    let mut attempts = 0usize;
    while buildings.len() < n_buildings {
        attempts += 1;
        if attempts > 100_000 {
            return Err(Error::msg(format!(
                "generate: cannot place {n_buildings} buildings on {} × {} m; make the town larger",
                o.size[0], o.size[1]
            )));
        }
        let half = [5.0 + 5.0 * rng.uniform(), 4.0 + 4.0 * rng.uniform()];
        let b = Building {
            x: o.size[0] * rng.uniform(),
            y: o.size[1] * rng.uniform(),
            half,
            rotation: PI * rng.uniform(),
            height: round4(6.0 + 9.0 * rng.uniform()),
        };
        let r = b.reach();
        let inside =
            b.x - r >= 0.0 && b.y - r >= 0.0 && b.x + r <= o.size[0] && b.y + r <= o.size[1];
        let apart = buildings
            .iter()
            .all(|q| (q.x - b.x).hypot(q.y - b.y) >= q.reach() + r + 3.0);
        if inside && apart {
            buildings.push(b);
        }
    }
    Ok(buildings)
}

/// The buildings as one OBJ mesh: their walls and flat roofs, groups `wall` and `roof`.
fn buildings_obj(seed: u64, buildings: &[Building]) -> String {
    let n_buildings = buildings.len();
    let mut obj = format!(
        "# {n_buildings} box buildings (lidarsim scene generate, seed {seed})
"
    );
    for b in buildings {
        for [x, y] in b.corners() {
            for z in [0.0, b.height] {
                obj.push_str("v ");
                fmt4(&mut obj, x);
                obj.push(' ');
                fmt4(&mut obj, y);
                obj.push(' ');
                fmt4(&mut obj, z);
                obj.push('\n');
            }
        }
    }
    // vertex 8k + 2c + 1 is corner c of building k at ground, + 1 the same at the roof
    obj.push_str("g roof\nusemtl roof\n");
    for k in 0..buildings.len() {
        let top = |c: usize| 8 * k + 2 * c + 2;
        let _ = writeln!(obj, "f {} {} {}", top(0), top(1), top(2));
        let _ = writeln!(obj, "f {} {} {}", top(0), top(2), top(3));
    }
    obj.push_str("g wall\nusemtl wall\n");
    for k in 0..buildings.len() {
        for c in 0..4 {
            let d = (c + 1) % 4;
            let (g0, t0) = (8 * k + 2 * c + 1, 8 * k + 2 * c + 2);
            let (g1, t1) = (8 * k + 2 * d + 1, 8 * k + 2 * d + 2);
            // outward: corners run counter-clockwise, so (g0, g1, t1) faces away from the centre
            let _ = writeln!(obj, "f {g0} {g1} {t1}");
            let _ = writeln!(obj, "f {g0} {t1} {t0}");
        }
    }
    obj
}

/// Trees at least `min_spacing_m` apart, clear of the buildings by `crown`, their crowns
/// inside the scene; every template gets a tree first.
fn place_garden_trees(
    rng: &mut crate::rng::Rand,
    o: &StandOptions,
    templates: usize,
    crown: f64,
    buildings: &[Building],
) -> Result<Vec<PlacedTree>> {
    let n_buildings = buildings.len();
    let mut placed: Vec<PlacedTree> = Vec::with_capacity(o.trees);
    let mut attempts = 0usize;
    while placed.len() < o.trees {
        attempts += 1;
        if attempts > 1000 * o.trees + 10_000 {
            return Err(Error::msg(format!(
                "generate: cannot place {} trees at least {} m apart and clear of {n_buildings} buildings on {} × {} m (placed {}); lower the tree count or the spacing",
                o.trees, o.min_spacing_m, o.size[0], o.size[1], placed.len()
            )));
        }
        // crowns stay inside the scene
        let (x, y) = (
            round4(crown + (o.size[0] - 2.0 * crown).max(0.0) * rng.uniform()),
            round4(crown + (o.size[1] - 2.0 * crown).max(0.0) * rng.uniform()),
        );
        let clear = buildings
            .iter()
            .all(|b| (b.x - x).hypot(b.y - y) >= b.reach() + crown)
            && placed
                .iter()
                .all(|t| (t.x - x).hypot(t.y - y) >= o.min_spacing_m);
        let (rotation, scale) = (rng.uniform(), rng.uniform());
        let template = if placed.len() < templates {
            placed.len()
        } else {
            (templates as f64 * rng.uniform()) as usize % templates
        };
        if clear {
            placed.push(PlacedTree {
                x,
                y,
                z: 0.0,
                rotation_deg: (36_000.0 * rotation).round() / 100.0,
                scale: round4(0.8 + 0.4 * scale),
                template,
            });
        }
    }
    Ok(placed)
}

/// A town: flat ground, box buildings (five per hectare, flat roofs, 6-15 m tall, at least
/// 3 m apart) and sparse trees (the forest's first species, at least `min_spacing_m` apart and
/// clear of the buildings by their crown radius); long for the same reason as [`forest`].
pub(super) fn town(seed: u64, dir: &Path, o: &StandOptions) -> Result<GeneratedSummary> {
    let mut out = Written::default();
    let mut rng = stream(seed, 0);
    let ground_area = o.size[0] * o.size[1];
    let buildings = place_buildings(&mut rng, o)?;
    let n_buildings = buildings.len();
    out.write(dir.join("buildings.obj"), &buildings_obj(seed, &buildings))?;
    let templates = o.templates.min(o.trees);
    let plans: Vec<TemplatePlan> = (0..templates)
        .map(|k| {
            let sp = &SPECIES[k % SPECIES.len()];
            let mut shape = sp.shape.clone();
            let mut r = stream(seed, 500 + k as u64);
            shape.height *= 0.5 + 0.2 * r.uniform();
            shape.crown_base *= 0.4 + 0.2 * r.uniform();
            // a garden tree: fewer, shorter branches than one grown in a stand
            shape.branches /= 3;
            TemplatePlan {
                stem: format!("{}{}", sp.name, k + 1),
                species: format!("{} ({})", sp.name, sp.latin),
                shape,
                leaf: &sp.leaf,
                bark: sp.bark,
            }
        })
        .collect();
    let crown = plans
        .iter()
        .map(|p| p.shape.crown_radius * 1.2)
        .fold(0.0, f64::max);
    let placed = place_garden_trees(&mut rng, o, templates, crown, &buildings)?;
    let file = StandFile {
        kind: SceneKind::Town,
        plans: &plans,
        placed: &placed,
        ground_area,
        ground_facets: 2,
        materials: &[&SOIL, &ROOF, &WALL],
        template_materials: true,
        objects: ground_plane(o)
            + "  - mesh: { file: buildings.obj, materials: { roof: roof, wall: wall }, class: building }\n",
        buildings: buildings.len(),
        building_facets: 10 * buildings.len() as u64,
    };
    write_stand(seed, dir, o, file, out, |summary| {
        vec![
            format!(
                "{n_buildings} box buildings and {} trees of {} templates on flat ground, {} × {} m;",
                summary.trees,
                summary.templates.len(),
                o.size[0],
                o.size[1]
            ),
            format!(
                "leaf area index {:.3} over the whole ground, {} facets once instanced.",
                summary.lai, summary.facets
            ),
        ]
    })
}

fn summarize(
    kind: SceneKind,
    seed: u64,
    dir: &Path,
    out: Written,
    templates: Vec<TemplateSummary>,
    ground_facets: u64,
    ground_area: f64,
) -> GeneratedSummary {
    let leaf_area: f64 = templates.iter().map(|t| t.leaf_area_m2).sum();
    GeneratedSummary {
        kind,
        seed,
        scene: dir.to_path_buf(),
        files: out.files,
        bytes: out.bytes,
        trees: templates.iter().map(|t| t.trees).sum(),
        buildings: 0,
        facets: ground_facets
            + templates
                .iter()
                .map(|t| t.facets * t.trees as u64)
                .sum::<u64>(),
        distinct_facets: ground_facets + templates.iter().map(|t| t.facets).sum::<u64>(),
        leaf_area_m2: leaf_area,
        ground_area_m2: ground_area,
        lai: leaf_area / ground_area,
        templates,
    }
}

/// Writes the scene file last, so that a scene file on disk always has its parts.
fn finish(mut s: GeneratedSummary, path: PathBuf, yaml: &str) -> Result<GeneratedSummary> {
    write_file(&path, yaml)?;
    s.bytes += yaml.len() as u64;
    s.files.push(path.clone());
    s.scene = path;
    Ok(s)
}
