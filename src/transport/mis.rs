//! Multiple importance sampling (Eq. 16-17): area densities of a path's vertices sampled
//! forwards and in reverse, and one weight for every strategy.

use super::bsdf::bsdf_pdf;
use super::{PulseSetup, Vertex, VertexKind};
use crate::campaign::MisHeuristic;

/// Area density at `to` of sampling it from `from`, itself reached from `prev` (the end
/// points' own distributions do not depend on a previous vertex).
pub(super) fn pdf_area(
    setup: &PulseSetup,
    prev: Option<&Vertex>,
    from: &Vertex,
    to: &Vertex,
) -> f64 {
    let d = to.p - from.p;
    let r2 = d.length_squared();
    if r2 == 0.0 {
        return 0.0;
    }
    let w = d / r2.sqrt();
    let pdf_dir = match from.kind {
        // the disk's uniform density, projected onto the surface: no 1/r² for a direction
        // (0 where the disk's light does not reach: parts of a repeated landscape)
        VertexKind::Sun => {
            return setup.sun.map_or(0.0, |sun| {
                if sun.covers(to.p) {
                    to.n.dot(sun.dir).abs() / sun.disk_area()
                } else {
                    0.0
                }
            });
        }
        VertexKind::Laser => setup.laser.pdf(w),
        VertexKind::Aperture => setup.receiver.pdf_dir(w),
        VertexKind::Surface => match prev {
            Some(pv) => {
                let surf = &setup.scene.surfaces[from.surface as usize];
                bsdf_pdf(surf, from.n, (pv.p - from.p).normalize(), w)
            }
            None => 0.0,
        },
    };
    pdf_dir * to.n.dot(w).abs() / r2
}

/// Sets the densities that the last vertex of a sub-path makes known: its own forward
/// density, and the reverse density of the vertex two steps back.
pub fn link(setup: &PulseSetup, path: &mut [Vertex]) {
    let i = path.len() - 1;
    if i >= 1 {
        let prev = if i >= 2 { Some(path[i - 2]) } else { None };
        path[i].pdf_fwd = pdf_area(setup, prev.as_ref(), &path[i - 1], &path[i]);
    }
    if i >= 2 {
        path[i - 2].pdf_rev = pdf_area(setup, Some(&path[i]), &path[i - 1], &path[i - 2]);
    }
}

/// MIS weight of the strategy that joined `light` (s vertices, from the laser) and `cam`
/// (t vertices, from the aperture) into the path x_k = light[k] (k < s), cam[n - k] (k ≥ s).
///
/// With p_l[k] and p_c[k] the area densities of x_k sampled from the light side and from the
/// receiver side, strategy s' has density P(s') = Π_{k<s'} p_l[k] Π_{k≥s'} p_c[k], so
/// P(s'+1)/P(s') = p_l[s']/p_c[s']: the weight is 1 / Σ_{s'} (P(s')/P(s))^β over the strategies
/// the method allows (s' ≥ 1: the laser is a delta position).
///
/// Kept whole, like pbrt-v4's `MISWeight`: the density ratios along the path read as one
/// product, with the special cases (delta laser, receiver aperture, light selection) beside it.
pub fn mis_weight(
    setup: &PulseSetup,
    light: &[Vertex],
    cam: &[Vertex],
    scratch: &mut Vec<f64>,
) -> f64 {
    let (s, t) = (light.len(), cam.len());
    let nv = s + t;
    let (s_cap, t_cap) = setup.caps_for(light[0].kind);
    let lo = nv.saturating_sub(t_cap).max(1);
    // t = 0 with a light sub-path one longer than its cap: see `crossing_after_cap`
    let hi = if setup.crossing_after_cap() && nv == s_cap + 1 {
        nv
    } else {
        nv.min(s_cap)
    };
    if lo >= hi {
        return 1.0;
    }
    let x = |k: usize| -> &Vertex {
        if k < s {
            &light[k]
        } else {
            &cam[nv - 1 - k]
        }
    };
    scratch.clear();
    scratch.resize(2 * nv, 0.0);
    let (pl, pc) = scratch.split_at_mut(nv);
    for k in 0..nv {
        if k < s {
            pl[k] = light[k].pdf_fwd;
            pc[k] = light[k].pdf_rev;
        } else {
            pl[k] = cam[nv - 1 - k].pdf_rev;
            pc[k] = cam[nv - 1 - k].pdf_fwd;
        }
    }
    // The densities next to the junction depend on this connection. The sums below read
    // the densities of x_k for k in [lo, hi) only: the others are not made (with one
    // sub-path capped, most of them).
    let read = |k: usize| (lo..hi).contains(&k);
    if t >= 1 {
        if read(s) {
            pl[s] = pdf_area(
                setup,
                if s >= 2 { Some(x(s - 2)) } else { None },
                x(s - 1),
                x(s),
            );
        }
        if t >= 2 && read(s + 1) {
            pl[s + 1] = pdf_area(setup, Some(x(s - 1)), x(s), x(s + 1));
        }
        if read(s - 1) {
            pc[s - 1] = pdf_area(
                setup,
                if t >= 2 { Some(x(s + 1)) } else { None },
                x(s),
                x(s - 1),
            );
        }
        if s >= 2 && read(s - 2) {
            pc[s - 2] = pdf_area(setup, Some(x(s)), x(s - 1), x(s - 2));
        }
    } else {
        // t = 0: the light sub-path ends on the aperture, which the receiver samples uniformly.
        pc[nv - 1] = 1.0 / setup.receiver.area;
        if read(nv - 2) {
            pc[nv - 2] = pdf_area(setup, None, x(nv - 1), x(nv - 2));
        }
    }
    // Specular vertices (pbrt-v4's MISWeight): a density sampled from one is a Dirac's, kept
    // as 0, and read as 1 in the ratios; a strategy whose connection touches one has no
    // density at all and is left out of the sum.
    let any_delta = (0..nv).any(|k| x(k).delta);
    if any_delta {
        for k in 0..nv {
            if pl[k] == 0.0 && k >= 1 && x(k - 1).delta {
                pl[k] = 1.0;
            }
            if pc[k] == 0.0 && k + 1 < nv && x(k + 1).delta {
                pc[k] = 1.0;
            }
        }
    }
    // strategy s' joins x_(s'-1) and x_(s'); s' = n (t = 0) joins nothing
    let open = |sp: usize| !any_delta || sp >= nv || !(x(sp - 1).delta || x(sp).delta);
    let h = |r: f64| match setup.heuristic {
        MisHeuristic::Power => r * r,
        MisHeuristic::Balance => r,
    };
    // Strategies with a light sub-path (s' ≥ 2, and t = 0) chose its light with probability
    // q, kept as the light end point's pdf_fwd; connecting to a light (s' = 1) chooses none.
    let q = light[0].pdf_fwd;
    let mut sum = 1.0;
    let mut r = 1.0;
    for k in s..hi {
        r *= pl[k] / pc[k];
        if k == 1 {
            r *= q;
        }
        if open(k + 1) {
            sum += h(r);
        }
    }
    r = 1.0;
    for k in (lo..s).rev() {
        r *= pc[k] / pl[k];
        if k == 1 {
            r /= q;
        }
        if open(k) {
            sum += h(r);
        }
    }
    if sum.is_finite() {
        1.0 / sum
    } else {
        0.0
    }
}
