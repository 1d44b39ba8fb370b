//! Bottom-level acceleration (one wide BVH per distinct mesh) and the watertight ray-triangle
//! test used at that level.

use glam::{DVec3, Vec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use std::time::Duration;

use super::mesh::{MeshData, SlotName};

/// obvhs culls BVH nodes whose exit distance is below 1e-4 (its node test clamps tmin there).
/// Rays are started this far behind their true origin and hits are accepted only beyond it,
/// so that geometry closer than 1e-4 to the origin is not lost.
pub(crate) const BACKOFF: f32 = 1e-3;

/// obvhs's slow preset: large triangles' boxes split before the build (a long blade or a
/// ground triangle no longer gives one box that most rays enter), a wider PLOC search and
/// more reinsertion. Chosen over the medium preset by measurement: the campaigns traced with
/// less CPU for the same bytes, at the cost of a slightly longer scene load and a little more
/// scene memory; the very slow preset traced no faster and built twice as long (the figures
/// are in the commit that made the choice).
const BUILD: BvhBuildParams = BvhBuildParams::slow_build();

/// One distinct mesh with its BVH. Triangles are stored in BVH leaf order, so the id obvhs
/// hands to the callback indexes them directly; `bvh.primitive_indices[k]` gives the
/// triangle's index in the mesh as loaded, which is what `FacetId::triangle` reports. The
/// build splits the boxes of large triangles (see [`BUILD`]), so a triangle can stand in
/// several leaves: code that must see each triangle once goes through [`Blas::distinct`].
pub(crate) struct Blas {
    pub tris: Vec<[Vec3; 3]>,
    pub slots: Vec<u32>,
    /// Each triangle's first place in `tris`, in leaf order (so a run of them is compact in
    /// space, as the top surface's chunks want).
    pub distinct: Vec<u32>,
    pub bvh: CwBvh,
    pub slot_names: Vec<SlotName>,
    /// Mesh-local position of the stored coordinates' origin.
    pub offset: DVec3,
    /// Bounds of the stored coordinates.
    pub lo: Vec3,
    pub hi: Vec3,
    /// Every vertex at one height (a `plane` object, flat ground): a ray that leaves one of
    /// its facets, or a segment that ends on one, meets no other facet of the mesh away from
    /// that point, so its traversal can be left out (see `Scene::intersect`).
    pub flat: bool,
}

impl Blas {
    pub fn build(mesh: &MeshData) -> Blas {
        let prims: Vec<Triangle> = mesh
            .tris
            .iter()
            .map(|t| Triangle {
                v0: Vec3A::from(t[0]),
                v1: Vec3A::from(t[1]),
                v2: Vec3A::from(t[2]),
            })
            .collect();
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in &mesh.tris {
            for v in t {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        let mut bvh = build_cwbvh_from_tris(&prims, BUILD, &mut Duration::default());
        drop(prims);
        shrink(&mut bvh);
        let mut tris = Vec::with_capacity(bvh.primitive_indices.len());
        let mut slots = Vec::with_capacity(bvh.primitive_indices.len());
        let mut seen = vec![false; mesh.tris.len()];
        let mut distinct = Vec::with_capacity(mesh.tris.len());
        for (k, &i) in bvh.primitive_indices.iter().enumerate() {
            tris.push(mesh.tris[i as usize]);
            slots.push(mesh.slots[i as usize]);
            if !std::mem::replace(&mut seen[i as usize], true) {
                distinct.push(k as u32);
            }
        }
        Blas {
            tris,
            slots,
            distinct,
            bvh,
            slot_names: mesh.slot_names.clone(),
            offset: mesh.offset,
            lo,
            hi,
            flat: lo.z == hi.z,
        }
    }

    /// Each of the mesh's triangles once, with its material slot.
    pub fn distinct(&self) -> impl Iterator<Item = (&[Vec3; 3], u32)> + '_ {
        self.distinct
            .iter()
            .map(|&k| (&self.tris[k as usize], self.slots[k as usize]))
    }

    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.tris.capacity() * size_of::<[Vec3; 3]>()
            + (self.slots.capacity() + self.distinct.capacity()) * size_of::<u32>()
            + bvh_bytes(&self.bvh)
            + self
                .slot_names
                .iter()
                .map(|s| s.group.capacity() + s.usemtl.as_ref().map_or(0, |u| u.capacity()))
                .sum::<usize>()
            + self.slot_names.capacity() * size_of::<SlotName>()
    }
}

/// obvhs reserves room for a binary tree's node count; the wide tree needs about a tenth.
pub(crate) fn shrink(bvh: &mut CwBvh) {
    bvh.nodes.shrink_to_fit();
    bvh.primitive_indices.shrink_to_fit();
}

pub(crate) fn bvh_bytes(bvh: &CwBvh) -> usize {
    use std::mem::size_of;
    bvh.nodes.capacity() * size_of::<obvhs::cwbvh::node::CwBvhNode>()
        + bvh.primitive_indices.capacity() * size_of::<u32>()
        + bvh
            .exact_node_aabbs
            .as_ref()
            .map_or(0, |a| a.capacity() * size_of::<obvhs::aabb::Aabb>())
}

/// An obvhs ray whose inverse direction stays finite for zero components, so the node slab
/// test stays conservative (obvhs's own `safe_inverse` clamps at 1/ε, which
/// can cut rays that run nearly parallel to a slab).
#[inline(always)]
pub(crate) fn make_ray(origin: Vec3A, direction: Vec3A, tmax: f32) -> Ray {
    #[inline(always)]
    fn inv(x: f32) -> f32 {
        // The sign must follow obvhs's `direction < 0.0` slab choice, which counts -0 as positive.
        if x.abs() < 1e-20 {
            if x < 0.0 {
                -1e20
            } else {
                1e20
            }
        } else {
            1.0 / x
        }
    }
    Ray {
        origin,
        direction,
        inv_direction: Vec3A::new(inv(direction.x), inv(direction.y), inv(direction.z)),
        tmin: 0.0,
        tmax,
    }
}

/// Closest-hit traversal of `bvh`: obvhs's `CwBvh::ray_traverse` with [`node_hits`] for its
/// node test. `hit(ray, k)` tests the primitive at leaf place `k` against `ray`, whose `tmax`
/// is the nearest hit so far, and returns the hit's parameter (infinity for none).
#[inline(always)]
pub(crate) fn traverse_closest(bvh: &CwBvh, ray: Ray, mut hit: impl FnMut(&Ray, usize) -> f32) {
    use glam::UVec2;
    let mut ray = ray;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    obvhs::traverse!(bvh, node, state, node_hits(node, &ray, state.oct_inv4), {
        let t = hit(&ray, state.primitive_id as usize);
        if t < ray.tmax {
            ray.tmax = t;
        }
    });
}

/// Any-hit traversal of `bvh`: true when `hit` returns a parameter below `ray.tmax` for some
/// primitive (obvhs's `CwBvh::ray_traverse_miss`, negated, with [`node_hits`]).
#[inline(always)]
pub(crate) fn traverse_any(bvh: &CwBvh, ray: Ray, mut hit: impl FnMut(&Ray, usize) -> f32) -> bool {
    use glam::UVec2;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    let mut found = false;
    'outer: {
        obvhs::traverse!(bvh, node, state, node_hits(node, &ray, state.oct_inv4), {
            if hit(&ray, state.primitive_id as usize) < ray.tmax {
                found = true;
                break 'outer;
            }
        });
    }
    found
}

/// Which children of a wide node the ray enters: obvhs's `CwBvhNode::intersect_ray`, the same
/// products, sums, minima and maxima in the same order (so the same mask, bit for bit), with
/// the eight children in one AVX2 register instead of two SSE passes, and the mask built
/// without a branch per child.
#[inline(always)]
fn node_hits(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        // SAFETY: the target has AVX2 (checked at compile time above); every load reads 8
        // bytes of the node's own 8-byte arrays.
        unsafe { node_hits_avx2(node, ray, oct_inv4) }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        node.intersect_ray(ray, oct_inv4)
    }
}

#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
#[inline(always)]
unsafe fn node_hits_avx2(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    use std::arch::x86_64::*;
    // obvhs's node test clamps the entry distance at this (see `BACKOFF`)
    const EPSILON: f32 = 1e-4;
    let adj_dir_inv = node.compute_extent() * ray.inv_direction;
    let adj_origin = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    #[inline(always)]
    unsafe fn q(v: &[u8; 8]) -> __m256 {
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(v.as_ptr().cast())))
    }
    #[inline(always)]
    unsafe fn slab(lo: &[u8; 8], hi: &[u8; 8], neg: bool, inv: f32, orig: f32) -> (__m256, __m256) {
        let (near, far) = if neg { (q(hi), q(lo)) } else { (q(lo), q(hi)) };
        let (inv, orig) = (_mm256_set1_ps(inv), _mm256_set1_ps(orig));
        (
            _mm256_add_ps(_mm256_mul_ps(near, inv), orig),
            _mm256_add_ps(_mm256_mul_ps(far, inv), orig),
        )
    }
    let d = ray.direction;
    let (tmin_x, tmax_x) = slab(
        &node.child_min_x,
        &node.child_max_x,
        d.x < 0.0,
        adj_dir_inv.x,
        adj_origin.x,
    );
    let (tmin_y, tmax_y) = slab(
        &node.child_min_y,
        &node.child_max_y,
        d.y < 0.0,
        adj_dir_inv.y,
        adj_origin.y,
    );
    let (tmin_z, tmax_z) = slab(
        &node.child_min_z,
        &node.child_max_z,
        d.z < 0.0,
        adj_dir_inv.z,
        adj_origin.z,
    );
    let tmin = _mm256_max_ps(tmin_x, _mm256_max_ps(tmin_y, tmin_z));
    let tmax = _mm256_min_ps(tmax_x, _mm256_min_ps(tmax_y, tmax_z));
    let tmin = _mm256_max_ps(tmin, _mm256_set1_ps(EPSILON));
    let tmax = _mm256_min_ps(tmax, _mm256_set1_ps(ray.tmax));
    let entered = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OS>(tmin, tmax));
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let bits = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(child_bits8 as i64));
    let index = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(bit_index8 as i64));
    let v = _mm256_and_si256(_mm256_sllv_epi32(bits, index), entered);
    let v = _mm_or_si128(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
    let v = _mm_or_si128(v, _mm_shuffle_epi32::<0b01_00_11_10>(v));
    let v = _mm_or_si128(v, _mm_shuffle_epi32::<0b10_11_00_01>(v));
    _mm_cvtsi128_si32(v) as u32
}

/// Per-ray constants of the watertight ray-triangle test (Woop, Benthin, Wald 2013, JCGT 2(1)):
/// the ray is sheared so that it runs along +z, and edge functions are evaluated in 2D, so a
/// ray through a shared edge or vertex hits at least one of the triangles.
#[derive(Clone, Copy)]
pub(crate) struct WatertightRay {
    o: Vec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl WatertightRay {
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = if kz == 2 { 0 } else { kz + 1 };
        let mut ky = if kx == 2 { 0 } else { kx + 1 };
        // Swapping keeps the winding, hence the sign of det, independent of the ray's octant.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        WatertightRay {
            o,
            kx,
            ky,
            kz,
            sx: d[kx] / d[kz],
            sy: d[ky] / d[kz],
            sz: 1.0 / d[kz],
        }
    }

    /// Ray parameter of the hit, or infinity when there is none in (tmin, tmax).
    #[inline(always)]
    pub fn intersect(&self, tri: &[Vec3; 3], tmin: f32, tmax: f32) -> f32 {
        let a = tri[0] - self.o;
        let b = tri[1] - self.o;
        let c = tri[2] - self.o;
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // An edge function of exactly zero is re-evaluated in f64, as the paper does, so that
        // the sign test is consistent between the two triangles sharing that edge.
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let (cxd, byd, cyd, bxd) = (cx as f64, by as f64, cy as f64, bx as f64);
            let (axd, ayd) = (ax as f64, ay as f64);
            u = (cxd * byd - cyd * bxd) as f32;
            v = (axd * cyd - ayd * cxd) as f32;
            w = (bxd * ayd - byd * axd) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return f32::INFINITY;
        }
        let det = u + v + w;
        if det == 0.0 {
            return f32::INFINITY;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t = (u * az + v * bz + w * cz) / det;
        if t > tmin && t < tmax {
            t
        } else {
            f32::INFINITY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh of many small triangles and a few long ones (whose boxes the build splits):
    /// the long ones stand in several leaves, yet `distinct` names every triangle once, at a
    /// place holding that triangle.
    #[test]
    fn distinct_names_each_triangle_once_when_boxes_are_split() {
        let mut tris = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
                tris.push([
                    Vec3::new(x, y, 0.0),
                    Vec3::new(x + 0.05, y, 0.0),
                    Vec3::new(x, y + 0.05, 0.01),
                ]);
            }
        }
        for k in 0..4 {
            let z = 1.0 + k as f32;
            tris.push([
                Vec3::new(0.0, 0.0, z),
                Vec3::new(4.0, 4.0, z + 2.0),
                Vec3::new(0.1, 0.0, z),
            ]);
        }
        let n = tris.len();
        let mesh = MeshData {
            slots: (0..n as u32).map(|i| i % 3).collect(),
            tris,
            slot_names: Vec::new(),
            offset: DVec3::ZERO,
        };
        let blas = Blas::build(&mesh);
        assert!(
            blas.tris.len() > n,
            "no box was split ({} references of {n} triangles): the test shows nothing",
            blas.tris.len()
        );
        assert_eq!(blas.distinct.len(), n);
        let mut seen = vec![false; n];
        for &k in &blas.distinct {
            let i = blas.bvh.primitive_indices[k as usize] as usize;
            assert!(!std::mem::replace(&mut seen[i], true), "triangle {i} twice");
            assert_eq!(blas.tris[k as usize], mesh.tris[i]);
            assert_eq!(blas.slots[k as usize], mesh.slots[i]);
        }
        assert!(
            blas.distinct.windows(2).all(|w| w[0] < w[1]),
            "not in leaf order"
        );
        let area: f64 = blas
            .distinct()
            .map(|(t, _)| (t[1] - t[0]).cross(t[2] - t[0]).length() as f64)
            .sum();
        let want: f64 = mesh
            .tris
            .iter()
            .map(|t| (t[1] - t[0]).cross(t[2] - t[0]).length() as f64)
            .sum();
        assert!((area - want).abs() <= 1e-9 * want, "{area} against {want}");
    }

    /// The node test gives obvhs's mask bit for bit, for every node of a real tree and rays
    /// of every octant (axis-parallel and short ones among them), so traversals visit the
    /// same nodes in the same order.
    #[test]
    fn node_hits_match_obvhs_bit_for_bit() {
        let mut tris = Vec::new();
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..3000 {
            let c = Vec3::new(next() * 20.0, next() * 20.0, next() * 8.0);
            let e = |n: &mut dyn FnMut() -> f32| Vec3::new(n() - 0.5, n() - 0.5, n() - 0.5) * 0.6;
            tris.push([c, c + e(&mut next), c + e(&mut next)]);
        }
        let mesh = MeshData {
            slots: vec![0; tris.len()],
            tris,
            slot_names: Vec::new(),
            offset: DVec3::ZERO,
        };
        let blas = Blas::build(&mesh);
        assert!(
            blas.bvh.nodes.len() > 100,
            "too small a tree to show anything"
        );
        let (mut tested, mut entered) = (0u64, 0u64);
        for i in 0..400 {
            let o = Vec3A::new(
                next() * 24.0 - 2.0,
                next() * 24.0 - 2.0,
                next() * 12.0 - 2.0,
            );
            let mut d = Vec3A::new(next() - 0.5, next() - 0.5, next() - 0.5);
            // axis-parallel and signed-zero components
            match i % 8 {
                0 => d.x = 0.0,
                1 => d = Vec3A::new(-0.0, 0.0, -1.0),
                2 => d.y = -0.0,
                _ => {}
            }
            let d = d.normalize_or(Vec3A::Z);
            let tmax = if i % 3 == 0 {
                next() * 5.0
            } else {
                f32::INFINITY
            };
            let ray = make_ray(o, d, tmax);
            let oct = blas.bvh.new_traversal(ray.direction).oct_inv4;
            for node in &blas.bvh.nodes {
                let want = node.intersect_ray(&ray, oct);
                assert_eq!(node_hits(node, &ray, oct), want, "ray {i}");
                tested += 1;
                entered += (want != 0) as u64;
            }
        }
        assert!(
            entered > 0 && entered < tested,
            "{entered} of {tested}: nothing compared"
        );
    }

    #[test]
    fn watertight_hits_shared_edge_once_or_more() {
        // Two triangles sharing the diagonal of the unit square; rays through the diagonal
        // must hit at least one of them.
        let t1 = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
        ];
        let t2 = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        for i in 1..1000 {
            let s = i as f32 / 1000.0;
            let r = WatertightRay::new(Vec3::new(s, s, 1.0), Vec3::new(0.0, 0.0, -1.0));
            let h1 = r.intersect(&t1, 0.0, 10.0);
            let h2 = r.intersect(&t2, 0.0, 10.0);
            assert!(h1.is_finite() || h2.is_finite(), "gap at {s}");
        }
        let r = WatertightRay::new(Vec3::new(0.7, 0.2, 1.0), Vec3::new(0.0, 0.0, -1.0));
        assert!((r.intersect(&t1, 0.0, 10.0) - 1.0).abs() < 1e-6);
        assert!(r.intersect(&t2, 0.0, 10.0).is_infinite());
        // From below, through the back side.
        let r = WatertightRay::new(Vec3::new(0.7, 0.2, -2.0), Vec3::new(0.0, 0.0, 1.0));
        assert!((r.intersect(&t1, 0.0, 10.0) - 2.0).abs() < 1e-6);
        // Outside (tmin, tmax).
        assert!(r.intersect(&t1, 0.0, 1.5).is_infinite());
    }
}
