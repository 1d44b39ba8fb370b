//! Procedural scenes, deterministic from a seed: written as OBJ templates, an instance table
//! and a scene YAML in the spec's format, so they load like any user scene.

use crate::error::{Error, Result};
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// xorshift64*: a tiny deterministic generator, so that the files do not depend on any
/// random-number crate's version.
struct Rand(u64);

impl Rand {
    fn new(seed: u64) -> Rand {
        Rand(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
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
    crate::fsutil::write_text_atomic(path, text).map_err(|e| Error::file(path, e))
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
pub fn canopy(dir: &Path, c: &Canopy) -> Result<PathBuf> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::file(dir, format!("cannot create folder: {e}")))?;
    let mut rng = Rand::new(c.seed);
    let mut objects = String::new();
    for k in 0..c.templates {
        let (rx, rz) = (1.25 + 0.5 * rng.next(), 1.5 + rng.next());
        let base = 4.0 + 3.0 * rng.next();
        let mut obj = format!("# crown template {k}: {} leaves\n", c.leaves);
        for i in 0..c.leaves {
            // uniform in the unit ball by rejection
            let p = loop {
                let p = [
                    2.0 * rng.next() - 1.0,
                    2.0 * rng.next() - 1.0,
                    2.0 * rng.next() - 1.0,
                ];
                if p[0] * p[0] + p[1] * p[1] + p[2] * p[2] <= 1.0 {
                    break p;
                }
            };
            let centre = [p[0] * rx, p[1] * rx, base + rz * (1.0 + p[2])];
            // a random orthonormal pair spans the leaf's plane
            let z = 2.0 * rng.next() - 1.0;
            let phi = 2.0 * PI * rng.next();
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
            let spin = 2.0 * PI * rng.next();
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
                c.size * rng.next(),
                c.size * rng.next(),
                360.0 * rng.next(),
                0.8 + 0.4 * rng.next()
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
