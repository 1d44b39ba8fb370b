//! One tree template as OBJ text: a tapered trunk, branches and twigs as triangulated prisms
//! (group and usemtl `bark`), and flat leaves (group and usemtl `leaves`) clustered around the
//! branches inside a crown envelope, with an exactly sampled leaf-angle distribution.
//!
//! Coordinates are written with 4 decimals (0.1 mm) and every figure reported (triangles,
//! leaf area) is computed from the rounded values, i.e. from the geometry as a reader sees it.

use crate::rng::Rand;
use glam::DVec3;
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt::Write as _;

/// Leaf inclination distributions: the de Wit (1965) classes and the spherical one, as used by
/// radiative transfer models (e.g. DART, RAMI). The density g(θ) is over the inclination θ of
/// the leaf normal from the zenith, 0 ≤ θ ≤ π/2.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeafAngle {
    /// g = sin θ: as if leaf normals were uniform on the sphere (mean 57.3°).
    Spherical,
    /// g = 2/π (mean 45°).
    Uniform,
    /// g = 2/π (1 + cos 2θ): mostly horizontal leaves (mean 26.8°).
    Planophile,
    /// g = 2/π (1 − cos 2θ): mostly vertical leaves (mean 63.2°).
    Erectophile,
    /// g = 2/π (1 − cos 4θ): mostly at 45° (mean 45°).
    Plagiophile,
    /// g = 2/π (1 + cos 4θ): mostly horizontal or vertical (mean 45°).
    Extremophile,
}

impl LeafAngle {
    /// Draws an inclination (radians) from the distribution exactly: by inversion for the
    /// spherical and uniform cases, and by rejection under the bound 4/π for the de Wit
    /// classes g = 2/π (1 + a cos bθ), which needs no numerical inversion of the CDF.
    pub(super) fn sample(self, rng: &mut Rand) -> f64 {
        let (a, b) = match self {
            LeafAngle::Spherical => return rng.uniform().acos(),
            LeafAngle::Uniform => return FRAC_PI_2 * rng.uniform(),
            LeafAngle::Planophile => (1.0, 2.0),
            LeafAngle::Erectophile => (-1.0, 2.0),
            LeafAngle::Plagiophile => (-1.0, 4.0),
            LeafAngle::Extremophile => (1.0, 4.0),
        };
        loop {
            let theta = FRAC_PI_2 * rng.uniform();
            if 2.0 * rng.uniform() <= 1.0 + a * (b * theta).cos() {
                return theta;
            }
        }
    }

    pub(super) fn name(self) -> &'static str {
        match self {
            LeafAngle::Spherical => "spherical",
            LeafAngle::Uniform => "uniform",
            LeafAngle::Planophile => "planophile",
            LeafAngle::Erectophile => "erectophile",
            LeafAngle::Plagiophile => "plagiophile",
            LeafAngle::Extremophile => "extremophile",
        }
    }
}

/// Radial profile of the crown between its base and the tree top.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Profile {
    Ellipsoid,
    /// Widest at the base, as spruce.
    Cone,
}

/// The shape of one tree at scale 1, base of the trunk at the origin, z up.
#[derive(Clone, Debug)]
pub(super) struct TreeShape {
    pub height: f64,
    pub crown_base: f64,
    pub crown_radius: f64,
    pub profile: Profile,
    /// Trunk radius at the ground, m.
    pub trunk_radius: f64,
    pub branches: usize,
    /// Mean elevation of branches above the horizontal; negative droops.
    pub branch_elevation_deg: f64,
    /// Radius of the leaf cluster around a branch point, m.
    pub cluster_m: f64,
    pub leaf_angle: LeafAngle,
    /// Leaf length over width.
    pub leaf_aspect: f64,
}

impl TreeShape {
    fn crown_radius_at(&self, z: f64) -> f64 {
        let (lo, hi) = (self.crown_base, self.height);
        if !(lo..=hi).contains(&z) {
            return -1.0;
        }
        match self.profile {
            Profile::Ellipsoid => {
                let half = 0.5 * (hi - lo);
                let u = (z - 0.5 * (hi + lo)) / half;
                self.crown_radius * (1.0 - u * u).max(0.0).sqrt()
            }
            Profile::Cone => self.crown_radius * (hi - z) / (hi - lo),
        }
    }

    fn in_crown(&self, p: DVec3) -> bool {
        let r = self.crown_radius_at(p.z);
        r >= 0.0 && p.x * p.x + p.y * p.y <= r * r
    }

    fn trunk_radius_at(&self, z: f64) -> f64 {
        self.trunk_radius * (1.0 - 0.85 * (z.max(0.0) / self.height).min(1.0))
    }
}

/// What a template contributes to the scene's figures.
pub(super) struct Template {
    pub obj: String,
    pub triangles: u64,
    /// One-sided leaf area at scale 1, m², from the written (rounded) vertices.
    pub leaf_area: f64,
}

/// Appends ` v` rounded to 4 decimals and returns the value as written. Integer arithmetic
/// rather than `{:.4}`: several times faster, and the written text and the returned value
/// come from the same integer.
pub(super) fn put4(out: &mut String, v: f64) -> f64 {
    out.push(' ');
    fmt4(out, v)
}

/// Appends `v` rounded to 4 decimals and returns the value as written.
pub(super) fn fmt4(out: &mut String, v: f64) -> f64 {
    let n = (v * 1e4).round() as i64;
    if n < 0 {
        out.push('-');
    }
    let a = n.unsigned_abs();
    let _ = write!(out, "{}.{:04}", a / 10_000, a % 10_000);
    n as f64 / 1e4
}

/// An OBJ text being written, with its vertex count for absolute face indices.
struct Obj {
    text: String,
    verts: usize,
    triangles: u64,
    leaf_area: f64,
}

impl Obj {
    fn vertex(&mut self, p: DVec3) -> DVec3 {
        self.text.push('v');
        let x = put4(&mut self.text, p.x);
        let y = put4(&mut self.text, p.y);
        let z = put4(&mut self.text, p.z);
        self.text.push('\n');
        self.verts += 1;
        DVec3::new(x, y, z)
    }

    /// An open tube through `centres` with `sides` faces around, its rings perpendicular to
    /// the overall axis. Faces are wound so that normals point outwards.
    fn tube(&mut self, centres: &[DVec3], radii: &[f64], sides: usize) {
        let axis = (centres[centres.len() - 1] - centres[0]).normalize();
        let (e1, e2) = basis(axis);
        let first = self.verts + 1;
        for (c, &r) in centres.iter().zip(radii) {
            for k in 0..sides {
                let a = 2.0 * PI * k as f64 / sides as f64;
                self.vertex(*c + (e1 * a.cos() + e2 * a.sin()) * r);
            }
        }
        for i in 0..centres.len() - 1 {
            for k in 0..sides {
                let a = first + i * sides + k;
                let b = first + i * sides + (k + 1) % sides;
                let (c, d) = (b + sides, a + sides);
                let _ = writeln!(self.text, "f {a} {b} {c}\nf {a} {c} {d}");
                self.triangles += 2;
            }
        }
    }

    /// A flat leaf: a hexagon inscribed in an ellipse of half-axes `a` along `u` and `b`
    /// across, as a fan of 6 triangles around its centre, front side along `n`.
    fn leaf(&mut self, centre: DVec3, n: DVec3, u: DVec3, a: f64, b: f64) {
        let v = n.cross(u);
        let c = self.vertex(centre);
        let mut ring = [DVec3::ZERO; 6];
        for (k, p) in ring.iter_mut().enumerate() {
            let t = PI / 3.0 * k as f64;
            *p = self.vertex(centre + u * (a * t.cos()) + v * (b * t.sin()));
        }
        for k in 0..6 {
            self.leaf_area += 0.5 * (ring[k] - c).cross(ring[(k + 1) % 6] - c).length();
        }
        // relative indices: the centre is -7, ring vertex k is -6 + k
        self.text
            .push_str("f -7 -6 -5\nf -7 -5 -4\nf -7 -4 -3\nf -7 -3 -2\nf -7 -2 -1\nf -7 -1 -6\n");
        self.triangles += 6;
    }
}

/// Two unit vectors completing `n` to a right-handed orthonormal frame (e1 × e2 = n).
fn basis(n: DVec3) -> (DVec3, DVec3) {
    let a = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = n.cross(a).normalize();
    (e1, n.cross(e1))
}

fn unit_ball(rng: &mut Rand) -> DVec3 {
    loop {
        let p = DVec3::new(
            2.0 * rng.uniform() - 1.0,
            2.0 * rng.uniform() - 1.0,
            2.0 * rng.uniform() - 1.0,
        );
        if p.length_squared() <= 1.0 {
            return p;
        }
    }
}

/// A branch or twig axis that leaves grow around: start + d s − sag s² ẑ, 0 ≤ s ≤ len.
struct Host {
    start: DVec3,
    dir: DVec3,
    sag: f64,
    len: f64,
    /// Leaves grow from this fraction of the length on (not near the trunk).
    from: f64,
}

impl Host {
    fn at(&self, s: f64) -> DVec3 {
        self.start + self.dir * s - DVec3::Z * (self.sag * s * s)
    }
}

/// Builds one template. `leaf_area` is the target area of one leaf, m² (one side).
///
/// Long because the trunk, the branches and the leaves draw from one random stream in a
/// fixed order (the order makes the template); split, every step would carry the stream and
/// the half-built mesh.
pub(super) fn build(
    shape: &TreeShape,
    leaves: usize,
    leaf_area: f64,
    rng: &mut Rand,
    title: &str,
) -> Template {
    // about 25 bytes a vertex line: 7 of them and 66 bytes of faces a leaf
    let mut obj = Obj {
        text: String::with_capacity(250 * leaves + 4000 * shape.branches + 4096),
        verts: 0,
        triangles: 0,
        leaf_area: 0.0,
    };
    let _ = writeln!(
        obj.text,
        "# {title}\n# height {:.2} m, crown {:.2}-{:.2} m, radius {:.2} m; {leaves} leaves of {:.2} cm², {} leaf angles",
        shape.height,
        shape.crown_base,
        shape.height,
        shape.crown_radius,
        leaf_area * 1e4,
        shape.leaf_angle.name()
    );
    obj.text.push_str("g bark\nusemtl bark\n");

    // The trunk starts below the ground so that it meets a sloping terrain all round.
    let top = 0.97 * shape.height;
    let segments = 12;
    let centres: Vec<DVec3> = (0..=segments)
        .map(|i| DVec3::new(0.0, 0.0, -0.3 + (top + 0.3) * i as f64 / segments as f64))
        .collect();
    let radii: Vec<f64> = centres.iter().map(|c| shape.trunk_radius_at(c.z)).collect();
    obj.tube(&centres, &radii, 10);

    let sag = if shape.branch_elevation_deg < 0.0 {
        0.03
    } else {
        0.05
    };
    let golden = PI * (3.0 - 5f64.sqrt());
    let mut hosts: Vec<Host> = Vec::with_capacity(3 * shape.branches);
    let span = (shape.height - 0.3 - shape.crown_base).max(0.1);
    for b in 0..shape.branches {
        // stratified heights and a golden-angle spiral keep the crown evenly filled
        let h = shape.crown_base + span * (b as f64 + rng.uniform()) / shape.branches as f64;
        let az = golden * b as f64 + 0.5 * (rng.uniform() - 0.5);
        let el = (shape.branch_elevation_deg + 20.0 * (rng.uniform() - 0.5)).to_radians();
        let dir = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        let mut branch = Host {
            start: DVec3::new(0.0, 0.0, h),
            dir,
            sag,
            len: 0.0,
            from: 0.25,
        };
        let mut len = 0.05;
        while len < 4.0 * shape.crown_radius && shape.in_crown(branch.at(len + 0.05)) {
            len += 0.05;
        }
        branch.len = len.max(0.3);
        let r0 = (0.01 + 0.02 * branch.len).min(0.6 * shape.trunk_radius_at(h));
        let centres: Vec<DVec3> = (0..=3)
            .map(|i| branch.at(branch.len * i as f64 / 3.0))
            .collect();
        let radii: Vec<f64> = (0..=3).map(|i| r0 * (1.0 - 0.22 * i as f64)).collect();
        obj.tube(&centres, &radii, 6);
        for _ in 0..2 {
            let s = branch.len * (0.35 + 0.45 * rng.uniform());
            let p = branch.at(s);
            let d = (branch.dir + unit_ball(rng) * 0.9 + DVec3::Z * 0.3).normalize();
            let tl = (branch.len - s).max(0.2) * (0.4 + 0.3 * rng.uniform());
            let rb = 0.5 * r0 * (1.0 - 0.66 * s / branch.len);
            obj.tube(&[p, p + d * tl], &[rb.max(0.003), 0.002], 5);
            hosts.push(Host {
                start: p,
                dir: d,
                sag: 0.0,
                len: tl,
                from: 0.0,
            });
        }
        hosts.push(branch);
    }

    obj.text.push_str("g leaves\nusemtl leaves\n");
    // leaves are spread along hosts in proportion to their leafy length
    let mut cumulative = Vec::with_capacity(hosts.len());
    let mut total = 0.0;
    for h in &hosts {
        total += h.len * (1.0 - h.from);
        cumulative.push(total);
    }
    let b = (leaf_area / (1.5 * 3f64.sqrt() * shape.leaf_aspect)).sqrt();
    let a = shape.leaf_aspect * b;
    for _ in 0..leaves {
        let mut centre = None;
        for _ in 0..16 {
            let x = total * rng.uniform();
            let k = cumulative.partition_point(|&c| c < x).min(hosts.len() - 1);
            let h = &hosts[k];
            let p = h.at(h.len * (h.from + (1.0 - h.from) * rng.uniform()))
                + unit_ball(rng) * shape.cluster_m;
            if shape.in_crown(p) {
                centre = Some(p);
                break;
            }
        }
        // a leaf that found no room near a branch goes anywhere in the crown
        let centre = centre.unwrap_or_else(|| loop {
            let p = DVec3::new(
                shape.crown_radius * (2.0 * rng.uniform() - 1.0),
                shape.crown_radius * (2.0 * rng.uniform() - 1.0),
                shape.crown_base + (shape.height - shape.crown_base) * rng.uniform(),
            );
            if shape.in_crown(p) {
                break p;
            }
        });
        let theta = shape.leaf_angle.sample(rng);
        let phi = 2.0 * PI * rng.uniform();
        let n = DVec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        );
        let (e1, e2) = basis(n);
        let psi = 2.0 * PI * rng.uniform();
        let u = e1 * psi.cos() + e2 * psi.sin();
        obj.leaf(centre, n, u, a, b);
    }
    Template {
        obj: obj.text,
        triangles: obj.triangles,
        leaf_area: obj.leaf_area,
    }
}
