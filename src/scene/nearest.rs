//! The distance from a point to the nearest facet: one descent of the two trees by box
//! distance, where casting rays in a fan of directions would only bound it from above (and
//! cost a traversal per direction).

use super::{Instance, Scene};
use glam::{DVec3, Vec3, Vec3A};
use obvhs::cwbvh::CwBvh;

impl Scene {
    /// Euclidean distance (m) from `at` (world) to the nearest facet of the scene, or `reach`
    /// when none is nearer. In a repeated scene the copies around the point count too.
    pub fn nearest_surface(&self, at: DVec3, reach: f64) -> f64 {
        if self.instances.is_empty() || !at.is_finite() || reach.is_nan() || reach <= 0.0 {
            return reach;
        }
        if !self.repeat {
            return self.nearest_copy(at, reach);
        }
        let (lo, hi) = (self.world_lo, self.world_hi);
        let period = self.period_hi - self.period_lo;
        // the copies whose geometry (which may overhang its period) comes within `reach` of
        // the point, as whole periods
        let cells = |x: f64, lo: f64, hi: f64, w: f64| {
            if w > 0.0 {
                let a = ((x - reach - hi) / w).floor();
                let b = ((x + reach - lo) / w).ceil();
                (a as i64, b as i64)
            } else {
                (0, 0)
            }
        };
        let (ax, bx) = cells(at.x, lo.x, hi.x, period.x);
        let (ay, by) = cells(at.y, lo.y, hi.y, period.y);
        let mut best = reach;
        for kx in ax..=bx {
            for ky in ay..=by {
                let shift = DVec3::new(kx as f64 * period.x, ky as f64 * period.y, 0.0);
                best = best.min(self.nearest_copy(at - shift, best));
            }
        }
        best
    }

    /// [`Scene::nearest_surface`] in the scene's own copy.
    fn nearest_copy(&self, at: DVec3, reach: f64) -> f64 {
        let p = Vec3A::from((at - self.origin).as_vec3());
        let mut best2 = (reach * reach) as f32;
        // one stack for the top level, one reused by every instance's descent, both kept by
        // the thread from query to query rather than allocated for each point
        STACKS.with_borrow_mut(|(top, inner)| {
            descend(&self.tlas, p, &mut best2, top, |id, best2| {
                let inst: &Instance = &self.instances[id];
                let blas = &self.meshes[inst.mesh as usize];
                // instances rotate about z and scale uniformly: a local distance times the
                // scale is the scene's
                let scale2 = 1.0 / (inst.inv_scale * inst.inv_scale);
                let q = inst.point_to_local(p);
                let mut local2 = *best2 / scale2;
                descend(&blas.bvh, q, &mut local2, inner, |k, local2| {
                    let d2 = distance2_to_triangle(Vec3::from(q), &blas.tris[k]);
                    if d2 < *local2 {
                        *local2 = d2;
                    }
                });
                *best2 = best2.min(local2 * scale2);
            });
        });
        (best2 as f64).sqrt().min(reach)
    }
}

/// A thread's scratch stacks for [`Scene::nearest_surface`].
type Stack = Vec<(u32, f32)>;

thread_local! {
    static STACKS: std::cell::RefCell<(Stack, Stack)> = const {
        std::cell::RefCell::new((Vec::new(), Vec::new()))
    };
}

/// Visits every leaf primitive of `bvh` whose box lies nearer to `p` than `sqrt(best2)`,
/// nearest boxes first, so that `leaf(index, best2)` can shrink the radius early and spare
/// most of the tree. `index` is the primitive's place in leaf order; `stack` is scratch.
fn descend(
    bvh: &CwBvh,
    p: Vec3A,
    best2: &mut f32,
    stack: &mut Vec<(u32, f32)>,
    mut leaf: impl FnMut(usize, &mut f32),
) {
    if bvh.nodes.is_empty() {
        return;
    }
    stack.clear();
    stack.push((0, 0.0));
    while let Some((n, d2)) = stack.pop() {
        if d2 >= *best2 {
            continue;
        }
        let node = &bvh.nodes[n as usize];
        let mut inner: [(u32, f32); 8] = [(0, 0.0); 8];
        let mut count = 0;
        for c in 0..8 {
            if node.is_child_empty(c) {
                continue;
            }
            let b = node.child_aabb(c);
            let gap = (b.min - p).max(p - b.max).max(Vec3A::ZERO);
            let d2 = gap.length_squared();
            if d2 >= *best2 {
                continue;
            }
            if node.is_leaf(c) {
                let (start, len) = node.child_primitives(c);
                for k in start..start + len {
                    leaf(k as usize, best2);
                }
            } else {
                inner[count] = (node.child_node_index(c), d2);
                count += 1;
            }
        }
        // the nearest popped first
        inner[..count].sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
        stack.extend_from_slice(&inner[..count]);
    }
}

/// Squared distance from `p` to the triangle `t` (closest point by Voronoi regions,
/// Ericson, Real-Time Collision Detection, 5.1.5).
fn distance2_to_triangle(p: Vec3, t: &[Vec3; 3]) -> f32 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length_squared();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length_squared();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (ap - ab * v).length_squared();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length_squared();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (ap - ac * w).length_squared();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (bp - (c - b) * w).length_squared();
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (ap - ab * v - ac * w).length_squared()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each Voronoi region of a triangle: above the face, beside each edge, beyond each
    /// corner, and a degenerate (zero-area) triangle, against brute force over a fine
    /// sampling of the triangle.
    #[test]
    fn triangle_distance_matches_brute_force() {
        let t = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.5, 1.5, 0.0),
        ];
        let flat = [t[0], t[1], Vec3::new(1.0, 0.0, 0.0)];
        let mut rng = crate::rng::SplitMix64::new(3);
        for tri in [t, flat] {
            for _ in 0..300 {
                let p = Vec3::new(
                    (rng.uniform() * 6.0 - 2.0) as f32,
                    (rng.uniform() * 6.0 - 2.0) as f32,
                    (rng.uniform() * 2.0 - 1.0) as f32,
                );
                let n = 400;
                let mut brute = f32::INFINITY;
                for i in 0..=n {
                    for j in 0..=n - i {
                        let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                        let q = tri[0] + (tri[1] - tri[0]) * u + (tri[2] - tri[0]) * v;
                        brute = brute.min((p - q).length());
                    }
                }
                let d = distance2_to_triangle(p, &tri).sqrt();
                // the sampling's spacing bounds brute force's excess
                assert!(
                    d <= brute + 1e-5 && brute - d < 0.006,
                    "{p:?}: {d} against {brute}"
                );
            }
        }
    }
}
