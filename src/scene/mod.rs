//! Scene: geometry, materials and the two-level acceleration structure.
//!
//! World coordinates are f64 (`DVec3`). Geometry is stored and traced in f32 relative to the
//! scene's own origin (`Scene::origin`, the centre of its bounding box): a ray coming from
//! 419 km is first moved analytically, in f64, to the scene's bounding box, then traced in
//! scene-local f32, and the hit distance is added back in f64.
//!
//! Two levels: one BVH per distinct mesh (bottom level), one BVH over instances (top level),
//! so memory grows with the number of distinct meshes, not with the number of instances.

mod bvh;
mod config;
mod load;
mod mesh;
mod nearest;
pub mod rpv;
mod table;
#[cfg(test)]
mod tests;
pub mod top_surface;

pub use rpv::Rpv;
pub use table::{parse_instances, InstanceRow};

use crate::error::Result;
use bvh::{make_ray, traverse_any, traverse_closest, Blas, WatertightRay, BACKOFF};
use glam::{DVec2, DVec3, Vec3, Vec3A};
use obvhs::cwbvh::CwBvh;
use std::collections::BTreeMap;
use std::path::Path;

/// Class of a surface, used by products to label returns with the truth. Its order is the
/// order of the per-class columns of the waveform files (`ground_energy_j` … `other_energy_j`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SurfaceClass {
    Ground = 0,
    Vegetation = 1,
    Building = 2,
    Other = 3,
}

impl SurfaceClass {
    /// Every class, in column order.
    pub const ALL: [SurfaceClass; 4] = [
        SurfaceClass::Ground,
        SurfaceClass::Vegetation,
        SurfaceClass::Building,
        SurfaceClass::Other,
    ];

    /// Index of the class's per-class tally and waveform column.
    pub fn index(self) -> usize {
        self as usize
    }

    /// ASPRS LAS classification code.
    pub fn las_code(self) -> u8 {
        match self {
            SurfaceClass::Ground => 2,
            SurfaceClass::Vegetation => 5,
            SurfaceClass::Building => 6,
            SurfaceClass::Other => 1,
        }
    }

    /// The waveform files' column of the class's impulse energy per bin.
    pub const fn energy_column(self) -> &'static str {
        match self {
            SurfaceClass::Ground => "ground_energy_j",
            SurfaceClass::Vegetation => "vegetation_energy_j",
            SurfaceClass::Building => "building_energy_j",
            SurfaceClass::Other => "other_energy_j",
        }
    }

    /// Name of the LAS class, as `products.json` counts points by it.
    pub fn las_name(self) -> &'static str {
        match self {
            SurfaceClass::Ground => "ground",
            SurfaceClass::Vegetation => "vegetation",
            SurfaceClass::Building => "building",
            SurfaceClass::Other => "unclassified",
        }
    }
}

/// Optical properties of one material at the campaign's wavelength, with its class.
/// The BSDF is ρ/π on the side the geometric normal points to (`reflectance`), ρ_b/π on the
/// other side (`back_reflectance`), and τ/π through the facet from either side.
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    pub name: String,
    pub reflectance: f64,
    pub back_reflectance: f64,
    pub transmittance: f64,
    /// (ρ, ρ_b, τ) in each band of the campaign; the three values above are the largest of
    /// each over the bands, with which paths are sampled (the band's own with one band). With
    /// several bands ρ + τ may then exceed 1: it is a sampling weight, not a material.
    pub bands: Vec<[f64; 3]>,
    /// RPV glossy reflection instead of Lambert's (`reflectance`, `back_reflectance` are then
    /// its amplitudes ρ0; no transmittance): the shape paths are weighted with, that of the
    /// band of the largest ρ0.
    pub rpv: Option<Rpv>,
    /// RPV's shape in each band (empty for a Lambertian surface).
    pub band_rpv: Vec<Rpv>,
    /// A water surface (its front side, where its normal points, is air): a Fresnel interface,
    /// no ρ or τ.
    pub water: Option<WaterInterface>,
    pub class: SurfaceClass,
}

/// The air-water interface: refractive index `n` and the mean square slope `mss` of its
/// facets (Cox & Munk 1954, σ² = 0.003 + 0.00512 U for a wind of U m/s; 0: a smooth, specular
/// surface).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WaterInterface {
    pub n: f64,
    pub mss: f64,
}

/// A body of water: its surface at `z` over the rectangle `lo..hi` (x, y), and the water
/// column below it, of refractive index `n` and beam attenuation `attenuation[b]` per metre in
/// band b (docs/physics.md, "Water").
#[derive(Clone, Debug, PartialEq)]
pub struct WaterBody {
    /// Mean square slope of the surface's facets (0: smooth).
    pub mss: f64,
    pub z: f64,
    pub lo: [f64; 2],
    pub hi: [f64; 2],
    /// The phase index: refraction.
    pub n: f64,
    /// The phase index of each band (the first is `n`): a run of several bands refracts its
    /// paths with the first's, each band's own serves its default group index.
    pub n_bands: Vec<f64>,
    /// The group index per band: the time light takes in the column.
    pub n_group: Vec<f64>,
    /// Beam attenuation per band, per metre.
    pub attenuation: Vec<f64>,
    /// The least of them: the attenuation paths are weighted with, each band's weight then
    /// carrying e^(−(c_b − c_min) ℓ) ≤ 1, so that no band's weight can exceed the path's and
    /// the path's cannot underflow while a band still carries light.
    pub attenuation_min: f64,
}

impl WaterBody {
    /// Whether the straight segment from `a` to `b` runs in the water column. A segment cannot
    /// cross the surface (the surface stops it), so its midpoint tells.
    #[inline]
    pub fn holds(&self, a: glam::DVec3, b: glam::DVec3) -> bool {
        let m = (a + b) * 0.5;
        m.z < self.z
            && (self.lo[0]..=self.hi[0]).contains(&m.x)
            && (self.lo[1]..=self.hi[1]).contains(&m.y)
    }
}

/// The group index of water of phase index `n` at `wavelength_nm`: n_g = n − λ dn/dλ, with
/// the dispersion dn/dλ of Quan and Fry's empirical index of water (X. Quan, E. S. Fry,
/// "Empirical equation for the index of refraction of seawater", Applied Optics 34(18),
/// 3477-3480, 1995) for fresh water at 20 °C (salinity adds under 3 % to the dispersion):
///
///   n(λ) = n₀ + n₄T² + (n₅ + n₇T)/λ + n₈/λ² + n₉/λ³,   λ in nm,
///   dn/dλ = −(n₅ + n₇T)/λ² − 2n₈/λ³ − 3n₉/λ⁴,
///
/// with n₅ = 15.868, n₇ = −0.00423, n₈ = −4382, n₉ = 1.1455·10⁶. About 1.355 at 532 nm and
/// 1.34 at 1064 nm (the formula is fitted over 400-700 nm; beyond, its extrapolation).
pub fn water_group_index(n: f64, wavelength_nm: f64) -> f64 {
    const T: f64 = 20.0;
    let l = wavelength_nm;
    let dn = -(15.868 - 0.00423 * T) / (l * l)
        - 2.0 * -4382.0 / (l * l * l)
        - 3.0 * 1.1455e6 / (l * l * l * l);
    n - l * dn
}

/// Farthest a coordinate of a scene may lie from its frame's origin, m (1000 km): the tracer
/// works in f32 around the scene's centre (6 cm steps at this distance), and a value beyond is
/// a typo or a unit mistake, not a landscape.
pub const MAX_COORDINATE_M: f64 = 1e6;
/// Largest instance scale: a tree template scaled beyond this is a typo.
pub const MAX_SCALE: f64 = 1e4;

/// Identifies one facet of one instance; used to keep a ray from hitting the facet it leaves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FacetId {
    pub instance: u32,
    pub triangle: u32,
}

impl FacetId {
    pub const NONE: FacetId = FacetId {
        instance: u32::MAX,
        triangle: u32::MAX,
    };
}

/// A ray-surface intersection in world coordinates.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the (unit) ray direction from the ray origin, metres (f64).
    pub t: f64,
    pub position: DVec3,
    /// Unit geometric normal of the facet, in world coordinates (front side).
    pub normal: DVec3,
    /// Index into `Scene::surfaces`.
    pub surface: u32,
    pub facet: FacetId,
}

/// What the scene file declares (its distinct geometries, their triangles, every object's
/// instances), then how the tracer holds it: objects with equal instance tables are one
/// traced mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneStats {
    /// Distinct geometries (mesh files, planes, heightfields), each read once.
    pub distinct_meshes: usize,
    /// Their triangles (degenerate ones dropped).
    pub distinct_triangles: u64,
    /// Triangles once instanced (sum over instances of their mesh's triangles).
    pub instanced_triangles: u64,
    /// Every object's instances (one for an object without an instance table).
    pub instances: u64,
    /// The tracer's meshes and instances.
    pub traced_meshes: usize,
    pub traced_instances: u64,
    /// Bytes held by geometry and acceleration structures.
    pub memory_bytes: u64,
}

pub struct Scene {
    pub name: String,
    /// The body of water, when the scene has one.
    pub water: Option<WaterBody>,
    /// Every file the scene was read from: its YAML, meshes, instance tables, heightfields.
    pub files: Vec<std::path::PathBuf>,
    pub surfaces: Vec<Surface>,
    /// f64 world position of the scene-local origin.
    pub origin: DVec3,
    // the rest is private to the scene module
    meshes: Vec<Blas>,
    /// In top-level BVH leaf order, so the top-level callback id indexes them directly.
    instances: Vec<Instance>,
    tlas: CwBvh,
    /// Material slot -> index into `surfaces`, per object from `Instance::surfaces` on.
    slot_surfaces: Vec<u32>,
    world_lo: DVec3,
    world_hi: DVec3,
    /// `world_lo/hi` padded: rays are clipped to this box in f64 before the f32 trace.
    clip_lo: DVec3,
    clip_hi: DVec3,
    instanced_triangles: u64,
    /// What the scene file declares: see [`SceneStats`].
    pub(crate) declared: Declared,
    /// Every query while on (`start_ray_log`): the bench replays them against the bare BVH.
    ray_log: Option<std::sync::Mutex<Vec<LoggedRay>>>,
    /// `repeat: true`: the scene is one period of an infinite landscape.
    repeat: bool,
    /// The period's x-y rectangle (see [`Scene::period`]).
    period_lo: DVec2,
    period_hi: DVec2,
    /// Copies of overhanging geometry were added, moved by whole periods, so the geometry
    /// reaches beyond the period: a query of one period's column must stop at its far side
    /// (see [`Scene::intersect`]).
    wrapped: bool,
}

/// The scene file's own counts, kept for [`SceneStats`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Declared {
    pub meshes: usize,
    pub triangles: u64,
    pub instances: u64,
}

/// Most periods a query crosses in a repeated scene before its ray is taken to have left:
/// only a ray nearly parallel to the ground stays within the scene's heights that long.
pub const MAX_PERIODS: usize = 4096;

/// A query the scene answered, as the bench replays it.
#[derive(Clone, Copy, Debug)]
pub enum LoggedRay {
    /// [`Scene::intersect`]'s arguments.
    Closest {
        origin: DVec3,
        dir: DVec3,
        t_max: f64,
        skip: FacetId,
    },
    /// [`Scene::occluded`]'s arguments.
    Occluded {
        a: DVec3,
        b: DVec3,
        skip_a: FacetId,
        skip_b: FacetId,
    },
}

/// One placement of a mesh. Scene-local point x maps to mesh storage coordinates as
/// R(-θ) (x - translation) / scale; the direction maps the same way without the translation
/// and is not renormalised, so a ray parameter t means the same point in both frames.
#[derive(Clone, Copy, Debug)]
struct Instance {
    translation: Vec3A,
    cos: f32,
    sin: f32,
    inv_scale: f32,
    mesh: u32,
    /// Offset of this object's slots in `Scene::slot_surfaces`.
    surfaces: u32,
    /// Index in scene-file order (objects, then instance rows), reported in `FacetId`.
    id: u32,
}

impl Instance {
    #[inline(always)]
    fn dir_to_local(&self, d: Vec3A) -> Vec3A {
        let q = d * self.inv_scale;
        Vec3A::new(
            self.cos * q.x + self.sin * q.y,
            self.cos * q.y - self.sin * q.x,
            q.z,
        )
    }

    #[inline(always)]
    fn point_to_local(&self, p: Vec3A) -> Vec3A {
        self.dir_to_local(p - self.translation)
    }

    fn normal_to_world(&self, n: DVec3) -> DVec3 {
        let (c, s) = (self.cos as f64, self.sin as f64);
        DVec3::new(c * n.x - s * n.y, s * n.x + c * n.y, n.z)
    }
}

/// A ray moved into scene-local f32, started `BACKOFF` behind its clipped origin.
struct LocalRay {
    /// World distance of the local origin (before backing off).
    t0: f64,
    origin: Vec3A,
    dir: Vec3A,
    /// Local parameter limit, backoff included.
    tmax: f32,
    /// How near (m) a facet's plane may pass to the ray's start before a hit on it is taken
    /// for f32 round-off: a few ulps of the local coordinates.
    eps: f32,
}

/// True when the point `p` (instance-local) lies on the plane of `tri`, to within `eps`
/// world metres plus the round-off of f32 coordinates of their size. A ray that starts on a
/// facet cannot meet a coplanar neighbour except at distance 0, and a segment that ends on
/// one cannot be blocked by its coplanar neighbours; computed from the coordinates rather
/// than from the hit distance, the test stays exact for surfaces a micrometre apart seen
/// from far away.
#[inline]
fn on_plane(tri: &[Vec3; 3], p: Vec3A, inv_scale_len: f32, eps: f32) -> bool {
    let p = Vec3::from(p);
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    let dist = n.dot(p - tri[0]).abs() / n.length() * inv_scale_len;
    let size = p.abs().max(tri[0].abs()).max_element() * inv_scale_len;
    dist < eps + 4e-7 * size
}

impl Scene {
    /// Loads a scene file (see ../shared/spec/campaign.md, "Scene") with materials resolved at
    /// `wavelength_nm`.
    pub fn load(path: &Path, wavelength_nm: f64) -> Result<Scene> {
        load::load(path, &[wavelength_nm])
    }

    /// A wavelength every material of the scene file gives a value at (see
    /// [`load::common_wavelength`]): where a host loads a scene before it knows its bands.
    pub fn common_wavelength(path: &Path) -> Result<f64> {
        load::common_wavelength(path)
    }

    /// [`Scene::load`] with materials resolved in each of several bands.
    pub fn load_bands(path: &Path, wavelengths_nm: &[f64]) -> Result<Scene> {
        load::load(path, wavelengths_nm)
    }

    /// Whether the scene file's materials (and water) give every one of `wavelengths_nm`,
    /// without building the scene.
    pub fn check_bands(path: &Path, wavelengths_nm: &[f64]) -> Result<()> {
        load::check_bands(path, wavelengths_nm)
    }

    /// Clips `origin + t dir`, 0 < t < t_max, to the scene box in f64 and moves it to f32.
    #[inline]
    fn local_ray(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<LocalRay> {
        if self.instances.is_empty() || !origin.is_finite() || !dir.is_finite() {
            return None;
        }
        let mut t0 = 0.0f64;
        let mut t1 = t_max;
        for k in 0..3 {
            let (o, d) = (origin[k], dir[k]);
            if d == 0.0 {
                if o < self.clip_lo[k] || o > self.clip_hi[k] {
                    return None;
                }
            } else {
                let a = (self.clip_lo[k] - o) / d;
                let b = (self.clip_hi[k] - o) / d;
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        if t0.is_nan() || t1.is_nan() || t0 > t1 {
            return None;
        }
        let d = Vec3A::from(dir.as_vec3());
        if d == Vec3A::ZERO {
            return None;
        }
        let p = Vec3A::from((origin + dir * t0 - self.origin).as_vec3());
        // A little beyond the box exit: the exit is rounded to f32 like everything else.
        let span = ((t1 - t0) * (1.0 + 1e-6)) as f32 + BACKOFF + 1e-5;
        Some(LocalRay {
            t0,
            origin: p - d * BACKOFF,
            dir: d,
            tmax: span,
            eps: 4e-7 * p.abs().max_element() + 1e-8,
        })
    }

    /// Closest hit along the ray `origin + t dir`, `dir` a unit vector, with 0 < t < t_max,
    /// ignoring the facet `skip` (the one the ray leaves). In a repeated scene the ray meets
    /// the copies of the scene in turn, and the hit is where it lies in the world.
    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_max: f64, skip: FacetId) -> Option<Hit> {
        if let Some(log) = &self.ray_log {
            if let Ok(mut v) = log.lock() {
                v.push(LoggedRay::Closest {
                    origin,
                    dir,
                    t_max,
                    skip,
                });
            }
        }
        if !self.repeat {
            return self.intersect_copy(origin, dir, t_max, skip);
        }
        let mut found = None;
        self.copies_along(origin, dir, t_max, |shift, first, _, (enter, exit)| {
            let skip = if first { skip } else { FacetId::NONE };
            if !self.wrapped {
                found = self
                    .intersect_copy(origin - shift, dir, t_max, skip)
                    .map(|h| Hit {
                        position: h.position + shift,
                        ..h
                    });
                return found.is_some();
            }
            // Wrapped geometry reaches past the column on both sides: a hit beyond it may
            // not be the nearest, which the next column holds, and one before it lies in a
            // column already searched (the facet the ray leaves among them), so only the
            // ray's stretch within the column is asked.
            let from = if first { 0.0 } else { enter.max(0.0) };
            let start = origin + dir * from;
            found = self
                .intersect_copy(start - shift, dir, t_max.min(exit) - from, skip)
                .map(|h| Hit {
                    t: h.t + from,
                    position: h.position + shift,
                    ..h
                });
            found.is_some()
        });
        found
    }

    /// The periods of a repeated scene whose columns the ray `origin + t dir`, 0 < t < t_max,
    /// crosses within the scene's heights, in the order it meets them, as the shift (whole
    /// periods in x and y) that moves each onto the scene's own period; `visit(shift, first,
    /// last, (enter, exit))` returns true to stop, `enter` and `exit` the ray's parameters
    /// where it enters and leaves the column. The scene's geometry holds every piece of every copy that lies in its own
    /// period (overhanging parts wrapped in, see `load`), so a query of the shifted ray
    /// against the scene finds what lies in that column.
    fn copies_along(
        &self,
        origin: DVec3,
        dir: DVec3,
        t_max: f64,
        mut visit: impl FnMut(DVec3, bool, bool, (f64, f64)) -> bool,
    ) {
        let (lo, hi) = (self.period_lo, self.period_hi);
        let (zlo, zhi) = (self.clip_lo.z, self.clip_hi.z);
        let (t0, t1) = if dir.z == 0.0 {
            if origin.z < zlo || origin.z > zhi {
                return;
            }
            (0.0, t_max)
        } else {
            let (a, b) = ((zlo - origin.z) / dir.z, (zhi - origin.z) / dir.z);
            (a.min(b).max(0.0), a.max(b).min(t_max))
        };
        if t0.is_nan() || t1.is_nan() || t0 > t1 {
            return;
        }
        let period = hi - lo;
        let p = origin + dir * t0;
        // a box flat in x or y repeats only in the other direction
        let cell = |x: f64, lo: f64, w: f64| if w > 0.0 { ((x - lo) / w).floor() } else { 0.0 };
        let (mut kx, mut ky) = (cell(p.x, lo.x, period.x), cell(p.y, lo.y, period.y));
        let exit = |k: f64, o: f64, d: f64, lo: f64, w: f64| {
            if w <= 0.0 || d == 0.0 {
                f64::INFINITY
            } else if d > 0.0 {
                (lo + (k + 1.0) * w - o) / d
            } else {
                (lo + k * w - o) / d
            }
        };
        let mut enter = t0;
        for n in 0..MAX_PERIODS {
            let tx = exit(kx, origin.x, dir.x, lo.x, period.x);
            let ty = exit(ky, origin.y, dir.y, lo.y, period.y);
            let next = tx.min(ty);
            let last = next.is_nan() || next >= t1;
            let shift = DVec3::new(kx * period.x.max(0.0), ky * period.y.max(0.0), 0.0);
            if visit(shift, n == 0, last, (enter, next)) || last {
                return;
            }
            enter = next;
            if tx <= ty {
                kx += dir.x.signum();
            } else {
                ky += dir.y.signum();
            }
        }
    }

    /// [`Scene::intersect`] on the scene's own copy: the top-level traversal with each
    /// instance's traversal nested in its closure, the hot path, kept in one place so that
    /// the two levels' skip and coplanar rules read together.
    fn intersect_copy(&self, origin: DVec3, dir: DVec3, t_max: f64, skip: FacetId) -> Option<Hit> {
        let lr = self.local_ray(origin, dir, t_max)?;
        // only a ray that starts on a facet (not one clipped to the box) can meet its
        // facet's coplanar neighbours at distance 0
        let on_surface = skip != FacetId::NONE && lr.t0 == 0.0;
        let mut best_t = f32::INFINITY;
        let mut best_inst = 0usize;
        let mut best_tri = 0usize;
        traverse_closest(
            &self.tlas,
            make_ray(lr.origin, lr.dir, lr.tmax),
            |ray, id| {
                let inst = &self.instances[id];
                let blas = &self.meshes[inst.mesh as usize];
                // A ray leaving a facet of a flat mesh (instances turn about z only) meets
                // the mesh's other facets at its start or not at all (it runs in their plane
                // only with probability 0), and the coplanar rule below refuses those: the
                // same answer without the traversal, which for the ground is most of a
                // bounce's or a return's query.
                if on_surface && blas.flat && inst.id == skip.instance {
                    return f32::INFINITY;
                }
                let o = inst.point_to_local(ray.origin);
                let d = inst.dir_to_local(ray.direction);
                let wr = WatertightRay::new(Vec3::from(o), Vec3::from(d));
                // the ray's true start (before backing off) and local units per world metre
                let start = o + d * BACKOFF;
                let inv_len = 1.0 / d.length();
                let skip_tri = if inst.id == skip.instance {
                    skip.triangle
                } else {
                    u32::MAX
                };
                let mut found = usize::MAX;
                let mut found_t = f32::INFINITY;
                traverse_closest(&blas.bvh, make_ray(o, d, ray.tmax), |r, k| {
                    if skip_tri != u32::MAX && blas.bvh.primitive_indices[k] == skip_tri {
                        return f32::INFINITY;
                    }
                    let t = wr.intersect(&blas.tris[k], BACKOFF, r.tmax);
                    if t < r.tmax && on_surface && on_plane(&blas.tris[k], start, inv_len, lr.eps) {
                        return f32::INFINITY;
                    }
                    if t < r.tmax {
                        found = k;
                        found_t = t;
                    }
                    t
                });
                if found != usize::MAX {
                    best_t = found_t;
                    best_inst = id;
                    best_tri = found;
                    found_t
                } else {
                    f32::INFINITY
                }
            },
        );
        if !best_t.is_finite() {
            return None;
        }
        let t = lr.t0 + (best_t - BACKOFF) as f64;
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        let inst = &self.instances[best_inst];
        let blas = &self.meshes[inst.mesh as usize];
        let v = &blas.tris[best_tri];
        let (a, b, c) = (v[0].as_dvec3(), v[1].as_dvec3(), v[2].as_dvec3());
        let normal = inst.normal_to_world((b - a).cross(c - a)).normalize();
        Some(Hit {
            t,
            position: origin + dir * t,
            normal,
            surface: self.slot_surfaces[(inst.surfaces + blas.slots[best_tri]) as usize],
            facet: FacetId {
                instance: inst.id,
                triangle: blas.bvh.primitive_indices[best_tri],
            },
        })
    }

    /// True when the ray from `a` along the unit vector `dir` meets any facet other than
    /// `skip_a` before it leaves the scene: an any-hit query (the traversal stops at the first
    /// blocker), for visibility towards a light at infinity such as the sun.
    pub fn occluded_towards(&self, a: DVec3, dir: DVec3, skip_a: FacetId) -> bool {
        // a point beyond the clip box (beyond its heights, when repeated): no facet lies
        // between it and the box
        let mut beyond = (self.clip_hi - self.clip_lo).length() + (a - self.clip_lo).length() + 1.0;
        if self.repeat {
            let dz = (self.clip_hi.z - self.clip_lo.z) + (a.z - self.clip_lo.z).abs() + 1.0;
            let periods = (self.period_hi - self.period_lo).length() * MAX_PERIODS as f64;
            beyond = (dz / dir.z.abs()).min(periods).max(beyond);
        }
        self.occluded(a, a + dir * beyond, skip_a, FacetId::NONE)
    }

    /// True when the open segment from `a` to `b` crosses any facet other than `skip_a`
    /// (the facet `a` lies on) and `skip_b` (the facet `b` lies on); in a repeated scene, of
    /// any copy it crosses (the skipped facets are those of the copies `a` and `b` lie in).
    pub fn occluded(&self, a: DVec3, b: DVec3, skip_a: FacetId, skip_b: FacetId) -> bool {
        if let Some(log) = &self.ray_log {
            if let Ok(mut v) = log.lock() {
                v.push(LoggedRay::Occluded {
                    a,
                    b,
                    skip_a,
                    skip_b,
                });
            }
        }
        if !self.repeat {
            return self.occluded_copy(a, b, skip_a, skip_b);
        }
        let len = (b - a).length();
        if len.is_nan() || len <= 0.0 || !len.is_finite() {
            return false;
        }
        let mut blocked = false;
        let dir = (b - a) / len;
        self.copies_along(a, dir, len, |shift, first, last, (enter, exit)| {
            let sa = if first { skip_a } else { FacetId::NONE };
            let sb = if last { skip_b } else { FacetId::NONE };
            if !self.wrapped {
                blocked = self.occluded_copy(a - shift, b - shift, sa, sb);
                return blocked;
            }
            // the segment's stretch within the column (see `intersect`): wrapped geometry
            // past it is another column's, the facets at a and b among it
            let from = if first { a } else { a + dir * enter.max(0.0) };
            let to = if last { b } else { a + dir * exit.min(len) };
            blocked = self.occluded_copy(from - shift, to - shift, sa, sb);
            blocked
        });
        blocked
    }

    /// [`Scene::occluded`] on the scene's own copy.
    fn occluded_copy(&self, a: DVec3, b: DVec3, skip_a: FacetId, skip_b: FacetId) -> bool {
        let delta = b - a;
        let len = delta.length();
        if len.is_nan() || len <= 0.0 || !len.is_finite() {
            return false;
        }
        let dir = delta / len;
        // How close to b (m) f32 coordinates can tell a blocker from b's own surface; the
        // segment stops that far short of b, and facets coplanar with b are not blockers.
        let end_eps = 4e-7 * Vec3A::from((b - self.origin).as_vec3()).abs().max_element() + 1e-8;
        let reach = len - end_eps as f64;
        let Some(lr) = self.local_ray(a, dir, reach) else {
            return false;
        };
        let tmax = ((reach - lr.t0) as f32 + BACKOFF).min(lr.tmax);
        // see `on_plane`
        let start_on_surface = skip_a != FacetId::NONE && lr.t0 == 0.0;
        let end_on_surface = skip_b != FacetId::NONE;
        let b_local = Vec3A::from((b - self.origin).as_vec3());
        if tmax.is_nan() || tmax <= BACKOFF {
            return false;
        }
        traverse_any(&self.tlas, make_ray(lr.origin, lr.dir, tmax), |ray, id| {
            let inst = &self.instances[id];
            let blas = &self.meshes[inst.mesh as usize];
            // a segment from or to a facet of a flat mesh meets its other facets only at
            // that end, where the coplanar rule refuses them (see `intersect_copy`)
            if blas.flat
                && ((start_on_surface && inst.id == skip_a.instance)
                    || (end_on_surface && inst.id == skip_b.instance))
            {
                return f32::INFINITY;
            }
            let o = inst.point_to_local(ray.origin);
            let d = inst.dir_to_local(ray.direction);
            let wr = WatertightRay::new(Vec3::from(o), Vec3::from(d));
            let start = o + d * BACKOFF;
            let end = inst.point_to_local(b_local);
            let inv_len = 1.0 / d.length();
            let sa = if inst.id == skip_a.instance {
                skip_a.triangle
            } else {
                u32::MAX
            };
            let sb = if inst.id == skip_b.instance {
                skip_b.triangle
            } else {
                u32::MAX
            };
            let skipping = sa != u32::MAX || sb != u32::MAX;
            let clear = !traverse_any(&blas.bvh, make_ray(o, d, ray.tmax), |r, k| {
                if skipping {
                    let orig = blas.bvh.primitive_indices[k];
                    if orig == sa || orig == sb {
                        return f32::INFINITY;
                    }
                }
                let t = wr.intersect(&blas.tris[k], BACKOFF, r.tmax);
                if t < r.tmax
                    && ((start_on_surface && on_plane(&blas.tris[k], start, inv_len, lr.eps))
                        || (end_on_surface && on_plane(&blas.tris[k], end, inv_len, end_eps)))
                {
                    return f32::INFINITY;
                }
                t
            });
            if clear {
                f32::INFINITY
            } else {
                // Any value below tmax stops the top-level traversal.
                f32::NEG_INFINITY
            }
        })
    }

    /// Clears every mesh's `flat` mark, so that queries traverse flat meshes as any other;
    /// returns how many were marked (the tests compare the two ways).
    #[cfg(test)]
    pub(crate) fn forget_flat(&mut self) -> usize {
        self.meshes
            .iter_mut()
            .map(|m| std::mem::replace(&mut m.flat, false) as usize)
            .sum()
    }

    /// Starts keeping every query the scene answers (for the bench; costs a lock per query).
    pub fn start_ray_log(&mut self) {
        self.ray_log = Some(std::sync::Mutex::new(Vec::new()));
    }

    /// The queries kept since [`Scene::start_ray_log`], which stops.
    pub fn take_ray_log(&mut self) -> Vec<LoggedRay> {
        self.ray_log
            .take()
            .and_then(|m| m.into_inner().ok())
            .unwrap_or_default()
    }

    /// World-space bounding box (min, max) of all geometry (of a repeated scene, its period's
    /// geometry with the overhanging parts of the neighbouring periods wrapped in).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        (self.world_lo, self.world_hi)
    }

    /// What a run over the scene should say of it: RPV materials whose BRDF is held to an
    /// albedo of 1 near grazing incidence.
    pub fn warnings(&self) -> Vec<String> {
        let mut out: Vec<String> = self
            .surfaces
            .iter()
            .filter(|s| s.rpv.iter().chain(&s.band_rpv).any(|r| r.limit.is_some()))
            .map(|s| {
                format!(
                    "material {}: its RPV albedo exceeds 1 between {}° and {}° of incidence (a property of RPV with k < 1); its BRDF is divided there by the albedo, which keeps it reciprocal and conserves energy",
                    s.name,
                    rpv::MAX_REFUSED_DEG,
                    rpv::MAX_CHECKED_DEG
                )
            })
            .collect();
        out.dedup();
        if let Some(w) = self
            .water
            .as_ref()
            .filter(|w| w.n_bands.iter().any(|&n| n != w.n))
        {
            out.push(format!(
                "the water's refractive index differs between the bands ({}): every path refracts with the first band's, one geometry for all (each band's own index sets its default group index, so its times)",
                w.n_bands
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        out
    }

    /// `repeat: true`: the scene is one period ([`Scene::period`]) of an infinite landscape.
    pub fn is_repeated(&self) -> bool {
        self.repeat
    }

    /// The x-y rectangle of a repeated scene's period: the scene file's `period`, else the
    /// ground's extent (planes, heightfields), else all geometry's; None when not repeated.
    pub fn period(&self) -> Option<(DVec2, DVec2)> {
        self.repeat.then_some((self.period_lo, self.period_hi))
    }

    /// The copy of the scene's box that a beam from `origin` along `dir` crosses at the
    /// scene's mid-height (or that holds `origin`, for a beam along the ground): the box a
    /// pulse's range gate and sun are sized by, the geometry's box moved by the periods that
    /// bring the scene's own period under that point. [`Scene::bounds`] when not repeated.
    pub fn bounds_near(&self, origin: DVec3, dir: DVec3) -> (DVec3, DVec3) {
        let (lo, hi) = (self.world_lo, self.world_hi);
        if !self.repeat {
            return (lo, hi);
        }
        let (plo, phi) = (self.period_lo, self.period_hi);
        let mid = 0.5 * (lo.z + hi.z);
        let at = if dir.z != 0.0
            && ((mid - origin.z) / dir.z).is_finite()
            && (mid - origin.z) / dir.z > 0.0
        {
            origin + dir * ((mid - origin.z) / dir.z)
        } else {
            origin
        };
        let period = phi - plo;
        let k = |x: f64, lo: f64, w: f64| {
            if w > 0.0 {
                ((x - lo) / w).floor() * w
            } else {
                0.0
            }
        };
        let shift = DVec3::new(k(at.x, plo.x, period.x), k(at.y, plo.y, period.y), 0.0);
        (lo + shift, hi + shift)
    }

    pub fn stats(&self) -> SceneStats {
        use std::mem::size_of;
        let memory = self.meshes.iter().map(Blas::memory_bytes).sum::<usize>()
            + self.meshes.capacity() * size_of::<Blas>()
            + self.instances.capacity() * size_of::<Instance>()
            + bvh::bvh_bytes(&self.tlas)
            + self.slot_surfaces.capacity() * size_of::<u32>()
            + self.surfaces.capacity() * size_of::<Surface>()
            + self
                .surfaces
                .iter()
                .map(|s| s.name.capacity())
                .sum::<usize>();
        SceneStats {
            distinct_meshes: self.declared.meshes,
            distinct_triangles: self.declared.triangles,
            instanced_triangles: self.instanced_triangles,
            instances: self.declared.instances,
            traced_meshes: self.meshes.len(),
            traced_instances: self.instances.len() as u64,
            memory_bytes: memory as u64,
        }
    }
}

/// Leaf area index of a loaded scene, from its geometry: the one-sided area of leaf facets
/// (vegetation facets whose material transmits at the wavelength the scene was loaded at),
/// each instance's scale² included, over the horizontal (projected) area of the ground
/// facets. `None` when the scene has no ground. Overlapping ground objects would be counted
/// twice.
pub fn leaf_area_index(scene: &Scene) -> Option<f64> {
    // (mesh, first material slot) -> (leaf area, projected ground area) at scale 1
    let mut per_object: BTreeMap<(u32, u32), (f64, f64)> = BTreeMap::new();
    let (mut leaf, mut ground) = (0.0f64, 0.0f64);
    for inst in &scene.instances {
        let (l, g) = *per_object
            .entry((inst.mesh, inst.surfaces))
            .or_insert_with(|| {
                let blas = &scene.meshes[inst.mesh as usize];
                let (mut l, mut g) = (0.0f64, 0.0f64);
                for (t, slot) in blas.distinct() {
                    let s = &scene.surfaces
                        [scene.slot_surfaces[(inst.surfaces + slot) as usize] as usize];
                    let is_leaf = s.class == SurfaceClass::Vegetation && s.transmittance > 0.0;
                    let is_ground = s.class == SurfaceClass::Ground;
                    if !(is_leaf || is_ground) {
                        continue;
                    }
                    let (a, b, c) = (t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3());
                    let n = (b - a).cross(c - a);
                    if is_leaf {
                        l += 0.5 * n.length();
                    } else {
                        g += 0.5 * n.z.abs();
                    }
                }
                (l, g)
            });
        let s2 = 1.0 / (inst.inv_scale as f64 * inst.inv_scale as f64);
        leaf += l * s2;
        ground += g * s2;
    }
    (ground > 0.0).then(|| leaf / ground)
}
