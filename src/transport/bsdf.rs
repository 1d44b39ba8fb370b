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

/// Samples the next direction at a facet reached from `w_prev` (unit, pointing back along the
/// path). Returns it with the throughput factor f |cos| / pdf: the albedo a of a Lambertian
/// facet, the reflectance factor ρ(w_prev, next) of an RPV one.
#[inline]
pub(super) fn sample_bsdf(
    s: &Surface,
    n: DVec3,
    w_prev: DVec3,
    rng: &mut Rng,
) -> Option<(DVec3, f64)> {
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
        Some(rpv) => Some((d, rpv.brf(rho, side, w_prev, d))),
        None => Some((d, a)),
    }
}
