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
    if s.water.is_some() {
        // a Dirac distribution: nothing for directions chosen elsewhere
        return 0.0;
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
    if s.water.is_some() {
        return 0.0;
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
    if let Some(n_water) = s.water {
        let (d, w) = sample_water(n_water, n, w_prev, light, rng.uniform())?;
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
