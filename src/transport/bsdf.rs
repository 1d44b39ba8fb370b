//! Scattering at a facet (physics.md, "Surfaces"): Lambertian reflection and transmission or
//! RPV glossy reflection ([`crate::scene::Rpv`]), their density over directions, and sampling
//! from it. Directions are sampled the same way for both (cosine-shaped on the side chosen in
//! proportion to ρ and τ), so an RPV surface changes a path's weight (and so its Russian
//! roulette), never its densities: every strategy's MIS weight is as for a Lambertian surface of
//! the same ρ0.

use super::Rng;
use crate::scene::Surface;
use crate::sensor::Frame;
use glam::DVec3;
use std::f64::consts::{FRAC_1_PI, PI};

/// Lambertian BSDF of a facet between the unit directions `a` and `b` (both pointing away
/// from the surface): ρ/π on the side they share, τ/π through the facet.
#[inline]
pub fn bsdf(s: &Surface, n: DVec3, a: DVec3, b: DVec3) -> f64 {
    if let Some(w) = &s.water {
        // smooth: a Dirac distribution, nothing for directions chosen elsewhere
        return if w.mss > 0.0 {
            rough::f(w, n, a, b)
        } else {
            0.0
        };
    }
    let (ca, cb) = (n.dot(a), n.dot(b));
    if ca * cb > 0.0 {
        let rho = if ca > 0.0 {
            s.reflectance
        } else {
            s.back_reflectance
        };
        match &s.rpv {
            Some(rpv) => rpv.brf(rho, n, a, b) * FRAC_1_PI,
            None => rho * FRAC_1_PI,
        }
    } else if ca * cb < 0.0 {
        s.transmittance * FRAC_1_PI
    } else {
        0.0
    }
}

/// Solid-angle density with which [`sample_bsdf`] picks `w_next` at a facet reached from
/// `w_prev`: reflection with probability ρ_side / a, transmission τ / a, each cosine-shaped.
#[inline]
pub fn bsdf_pdf(s: &Surface, n: DVec3, w_prev: DVec3, w_next: DVec3) -> f64 {
    if let Some(w) = &s.water {
        return if w.mss > 0.0 {
            rough::pdf(w, n, w_prev, w_next)
        } else {
            0.0
        };
    }
    let c = n.dot(w_prev);
    let rho = if c > 0.0 {
        s.reflectance
    } else {
        s.back_reflectance
    };
    let a = rho + s.transmittance;
    let co = n.dot(w_next);
    if c == 0.0 || a <= 0.0 || co == 0.0 {
        return 0.0;
    }
    let p = if c * co > 0.0 { rho } else { s.transmittance };
    p / a * co.abs() * FRAC_1_PI
}

/// Unpolarised Fresnel reflectance of a smooth interface for light arriving at cosine
/// `cos_i` (> 0) from the medium of index n_i into that of n_t, `eta` = n_t / n_i (1 beyond the
/// critical angle: total internal reflection).
pub fn fresnel(cos_i: f64, eta: f64) -> f64 {
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (parallel * parallel + perpendicular * perpendicular)
}

/// The smooth water surface of index `n_water` (air on the side of `n`): reflection with
/// probability F, refraction otherwise, each direction a Dirac one. The throughput factor is
/// 1, except refraction on a receiver sub-path, whose importance (like radiance) changes by
/// (n_i / n_t)² into the other medium (pbrt's non-symmetric transmission, Veach 1997 ch. 5).
fn sample_water(
    n_water: f64,
    n: DVec3,
    w_prev: DVec3,
    light: bool,
    u: f64,
) -> Option<(DVec3, f64)> {
    let c = n.dot(w_prev);
    if c == 0.0 {
        return None;
    }
    // the path arrives from w_prev's side (index n_i) and may enter the other (n_t)
    let (eta, side) = if c > 0.0 {
        (n_water, n)
    } else {
        (1.0 / n_water, -n)
    };
    let cos_i = c.abs();
    let f = fresnel(cos_i, eta);
    if u < f {
        return Some((2.0 * cos_i * side - w_prev, 1.0));
    }
    let cos_t = (1.0 - (1.0 - cos_i * cos_i) / (eta * eta)).max(0.0).sqrt();
    let t = (-w_prev / eta + (cos_i / eta - cos_t) * side).normalize();
    Some((t, if light { 1.0 } else { 1.0 / (eta * eta) }))
}

/// Samples the next direction at a facet reached from `w_prev` (unit, pointing back along the
/// path) on a light (`light`) or a receiver sub-path. Returns it with the throughput factor
/// f |cos| / pdf (the albedo a of a Lambertian facet, the reflectance factor ρ(w_prev, next) of
/// an RPV one) and whether the scattering was specular.
#[inline]
pub(super) fn sample_bsdf(
    s: &Surface,
    n: DVec3,
    w_prev: DVec3,
    light: bool,
    rng: &mut Rng,
) -> Option<(DVec3, f64, bool)> {
    if let Some(water) = &s.water {
        if water.mss > 0.0 {
            let u = [rng.uniform(), rng.uniform(), rng.uniform()];
            let d = rough::sample(water, n, w_prev, u)?;
            // f |cos| / pdf, f taken the way light flows: from the light side to the sensor's
            let (l, v) = if light { (w_prev, d) } else { (d, w_prev) };
            let p = rough::pdf(water, n, w_prev, d);
            let weight = rough::f(water, n, l, v) * n.dot(d).abs() / p;
            return (p > 0.0 && weight.is_finite()).then_some((d, weight, false));
        }
        let (d, w) = sample_water(water.n, n, w_prev, light, rng.uniform())?;
        return Some((d, w, true));
    }
    let c = n.dot(w_prev);
    if c == 0.0 {
        return None;
    }
    let side = if c > 0.0 { n } else { -n };
    let rho = if c > 0.0 {
        s.reflectance
    } else {
        s.back_reflectance
    };
    let a = rho + s.transmittance;
    if a <= 0.0 {
        return None;
    }
    let axis = if rng.uniform() * a < rho { side } else { -side };
    let (u1, u2) = (rng.uniform(), rng.uniform());
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let d =
        Frame::from_axis(axis).to_world(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
    let d = d.normalize();
    match &s.rpv {
        // f cos / (cos / π) with f = ρ(w_prev, d) / π; an RPV facet transmits nothing, so
        // the side was the reflecting one
        Some(rpv) => Some((d, rpv.brf(rho, side, w_prev, d), false)),
        None => Some((d, a, false)),
    }
}

/// The wind-roughened water surface: a microfacet dielectric (Walter, Marschner, Li &
/// Torrance 2007) whose facet slopes are Cox and Munk's isotropic Gaussian, which is
/// Beckmann's distribution with α² = σ², the mean square slope:
///
///   D(h) = exp(−tan²θ_h / σ²) / (π σ² cos⁴θ_h),
///   f_r(l→v) = F(l·h) D(h) G / (4 |n·l| |n·v|),            h = ±(l + v)/|l + v|,
///   f_t(l→v) = |l·h| |v·h| n_v² (1 − F(l·h)) D(h) G / (|n·l| |n·v| (n_l l·h + n_v v·h)²),
///                                                            h = ±(n_l l + n_v v)/|…|,
///
/// for light arriving from l and leaving towards v (n_l, n_v the indices on their sides),
/// with Smith's shadowing G = G₁(l) G₁(v) (Walter's rational fit for Beckmann). Facets are
/// drawn from D(h) cos θ_h around the side the path arrives from, then reflection with
/// probability F, refraction otherwise; the densities below are those of that sampling.
mod rough {
    use super::fresnel;
    use crate::scene::WaterInterface;
    use glam::DVec3;
    use std::f64::consts::PI;

    /// Indices on the sides of `a` and `b` (air where the normal points) and the facet normal
    /// of the pair (towards the air), or None where they make no valid microfacet geometry.
    fn half(w: &WaterInterface, n: DVec3, a: DVec3, b: DVec3) -> Option<(f64, f64, DVec3)> {
        let (ca, cb) = (n.dot(a), n.dot(b));
        if ca == 0.0 || cb == 0.0 {
            return None;
        }
        let index = |c: f64| if c > 0.0 { 1.0 } else { w.n };
        let (na, nb) = (index(ca), index(cb));
        let h = if ca * cb > 0.0 {
            a + b
        } else {
            -(na * a + nb * b)
        };
        let len = h.length();
        if len == 0.0 {
            return None;
        }
        // towards the air, so that the test below reads the same whichever of a, b comes first
        let h = if h.dot(n) < 0.0 { -h / len } else { h / len };
        // each direction on the facet's side it claims (Smith's χ⁺)
        if a.dot(h) * ca <= 0.0 || b.dot(h) * cb <= 0.0 {
            return None;
        }
        Some((na, nb, h))
    }

    fn d(w: &WaterInterface, n: DVec3, h: DVec3) -> f64 {
        let c = n.dot(h).abs();
        if c <= 0.0 {
            return 0.0;
        }
        let c2 = c * c;
        let tan2 = (1.0 - c2) / c2;
        (-tan2 / w.mss).exp() / (PI * w.mss * c2 * c2)
    }

    fn g1(w: &WaterInterface, n: DVec3, v: DVec3) -> f64 {
        let c = n.dot(v).abs().min(1.0);
        let tan = (1.0 - c * c).max(0.0).sqrt() / c;
        if tan == 0.0 {
            return 1.0;
        }
        let a = 1.0 / (w.mss.sqrt() * tan);
        if a >= 1.6 {
            1.0
        } else {
            (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
        }
    }

    /// The index across the interface from a side of index `here`.
    fn other(w: &WaterInterface, here: f64) -> f64 {
        if here == 1.0 {
            w.n
        } else {
            1.0
        }
    }

    /// f(l→v), light from `l` leaving towards `v` (both unit, away from the surface).
    pub fn f(w: &WaterInterface, n: DVec3, l: DVec3, v: DVec3) -> f64 {
        let Some((nl, nv, h)) = half(w, n, l, v) else {
            return 0.0;
        };
        let (cl, cv) = (n.dot(l).abs(), n.dot(v).abs());
        let g = g1(w, n, l) * g1(w, n, v);
        let (lh, vh) = (l.dot(h), v.dot(h));
        if nl == nv {
            let fr = fresnel(lh.abs(), other(w, nl) / nl);
            return fr * d(w, n, h) * g / (4.0 * cl * cv);
        }
        let ft = 1.0 - fresnel(lh.abs(), nv / nl);
        let denom = nl * lh + nv * vh;
        lh.abs() * vh.abs() * nv * nv * ft * d(w, n, h) * g / (cl * cv * denom * denom)
    }

    /// Density (solid angle) of `w_next` drawn by [`sample`] at a path arriving from `w_prev`.
    pub fn pdf(w: &WaterInterface, n: DVec3, w_prev: DVec3, w_next: DVec3) -> f64 {
        let Some((ni, nt, h)) = half(w, n, w_prev, w_next) else {
            return 0.0;
        };
        let (oh, ih) = (w_prev.dot(h), w_next.dot(h));
        let f = fresnel(oh.abs(), other(w, ni) / ni);
        let dh = d(w, n, h) * n.dot(h).abs();
        if ni == nt {
            f * dh / (4.0 * oh.abs())
        } else {
            let denom = ni * oh + nt * ih;
            (1.0 - f) * dh * nt * nt * ih.abs() / (denom * denom)
        }
    }

    /// Draws the next direction at a path arriving from `w_prev`: a facet normal from
    /// D(h) cos θ_h about the side of `w_prev`, then reflection with probability F or
    /// refraction. None where the draw leaves no valid direction (a loss the densities count).
    pub fn sample(w: &WaterInterface, n: DVec3, w_prev: DVec3, u: [f64; 3]) -> Option<DVec3> {
        let c = n.dot(w_prev);
        if c == 0.0 {
            return None;
        }
        let side = if c > 0.0 { n } else { -n };
        let eta = if c > 0.0 { w.n } else { 1.0 / w.n };
        let tan2 = -w.mss * (1.0 - u[0]).ln();
        let cos_h = 1.0 / (1.0 + tan2).sqrt();
        let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
        let phi = 2.0 * PI * u[1];
        let frame = crate::sensor::Frame::from_axis(side);
        let h = frame
            .to_world(sin_h * phi.cos(), sin_h * phi.sin(), cos_h)
            .normalize();
        let cos_o = w_prev.dot(h);
        if cos_o <= 0.0 {
            return None;
        }
        let f = fresnel(cos_o, eta);
        let d = if u[2] < f {
            2.0 * cos_o * h - w_prev
        } else {
            let cos_t = (1.0 - (1.0 - cos_o * cos_o) / (eta * eta)).max(0.0).sqrt();
            -w_prev / eta + (cos_o / eta - cos_t) * h
        };
        let d = d.normalize();
        let same = d.dot(side) > 0.0;
        // reflection must stay on the arriving side, refraction cross to the other
        ((u[2] < f) == same).then_some(d)
    }
}
