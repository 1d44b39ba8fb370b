//! The Rahman-Pinty-Verstraete (RPV) reflectance model (Rahman, Pinty & Verstraete 1993,
//! J. Geophys. Res. 98(D11), 20791-20801), the parametric glossy BRDF of soils and roofs in
//! DART and Eradiate. Its reflectance factor between the unit directions a and b, both leaving
//! the surface on the side of its normal n (μ = |n·a|, |n·b|), is
//!
//!   ρ(a, b) = ρ0 [μ_a μ_b (μ_a + μ_b)]^(k−1) F(g) (1 + R(G)),
//!   F(g) = (1 − Θ²) / (1 + 2Θ cos g + Θ²)^(3/2),   cos g = a·b,
//!   1 + R(G) = 1 + (1 − ρ_c) / (1 + G),   G² = tan²θ_a + tan²θ_b − 2 tan θ_a tan θ_b cos Δφ,
//!
//! and its BRDF is ρ/π. g is the angle between the two outgoing directions: g = 0 and G = 0 at
//! the hot spot a = b (the monostatic LiDAR geometry), and Θ < 0 scatters backwards. ρ is
//! symmetric in a and b, so the BRDF is reciprocal. tan θ_a tan θ_b cos Δφ = (a·b − μ_a μ_b) /
//! (μ_a μ_b): the projections of a and b on the surface, over the cosines.

use glam::DVec3;

/// Largest incidence angle at which an RPV albedo above 1 refuses the material, degrees: RPV
/// was fitted to observations at moderate angles, where parameters that create energy are
/// wrong ones.
pub const MAX_REFUSED_DEG: u32 = 80;

/// Largest incidence angle, degrees, up to which a material's RPV albedo is checked and, past
/// [`MAX_REFUSED_DEG`], held to 1 by [`Rpv::limited`]: with k < 1 RPV's albedo grows without
/// bound towards grazing incidence (the factor (μ_a μ_b (μ_a + μ_b))^(k−1)), a property of the
/// model that common soil parameters do not escape (0.92 at 88°, 1.29 at 89.5° for ρ0 = 0.3,
/// k = 0.75, Θ = −0.15).
pub const MAX_CHECKED_DEG: f64 = 89.9;

/// Nodes of [`Limit`]'s tables, uniform in ln μ from cos [`MAX_CHECKED_DEG`] to 1.
const LIMIT_NODES: usize = 64;

/// RPV's shape: k (k < 1 bowl-shaped, > 1 bell-shaped), Θ (the Henyey-Greenstein asymmetry)
/// and ρ_c (the hot spot's amplitude; `None`: ρ0, as in Rahman et al.'s original model), and
/// the limit that keeps its albedo at most 1 near grazing incidence, when it needs one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rpv {
    pub k: f64,
    pub theta: f64,
    pub rho_c: Option<f64>,
    pub limit: Option<Limit>,
}

/// The albedo of an RPV shape as two tables over the incidence cosine μ, independent of ρ0:
/// A(μ) = ρ0 (A₁(μ) + (1 − ρ_c) A₂(μ)), with A₁ = ∫ S F μ_b dω / π and
/// A₂ = ∫ S F / (1 + G) μ_b dω / π (S the shape factor, F the Henyey-Greenstein term).
/// The BRF is divided by max(1, A(μ_a), A(μ_b)): symmetric in a and b, so still reciprocal,
/// and its albedo from any incidence a is then at most A(μ_a) / max(1, A(μ_a)) ≤ 1. Where
/// the albedo is at most 1 from both directions the BRF is unchanged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    a1: [f32; LIMIT_NODES],
    a2: [f32; LIMIT_NODES],
}

impl Limit {
    /// ln of the first node's μ (cos 89.9°).
    fn ln_mu_min() -> f64 {
        MAX_CHECKED_DEG.to_radians().cos().ln()
    }

    /// max(1, A(μ)) for amplitude `rho0` and hot-spot amplitude `rho_c`, A linear in ln μ
    /// between nodes (and the first node's below it).
    fn bound(&self, rho0: f64, rho_c: f64, mu: f64) -> f64 {
        let lo = Self::ln_mu_min();
        let x =
            ((mu.ln() - lo) / -lo * (LIMIT_NODES - 1) as f64).clamp(0.0, (LIMIT_NODES - 1) as f64);
        let i = (x.floor() as usize).min(LIMIT_NODES - 2);
        let f = x - i as f64;
        let at = |t: &[f32; LIMIT_NODES]| t[i] as f64 * (1.0 - f) + t[i + 1] as f64 * f;
        (rho0 * (at(&self.a1) + (1.0 - rho_c) * at(&self.a2))).max(1.0)
    }
}

impl Rpv {
    /// The reflectance factor ρ(a, b) with amplitude `rho0`, for unit directions `a` and `b` on
    /// the side of the unit normal `n` (0 where either is grazing).
    #[inline]
    pub fn brf(&self, rho0: f64, n: DVec3, a: DVec3, b: DVec3) -> f64 {
        let (ma, mb) = (n.dot(a).abs(), n.dot(b).abs());
        if ma < 1e-12 || mb < 1e-12 {
            return 0.0;
        }
        let cos_g = a.dot(b).clamp(-1.0, 1.0);
        let shape = (ma * mb * (ma + mb)).powf(self.k - 1.0);
        let t = self.theta;
        let hg = (1.0 - t * t) / (1.0 + 2.0 * t * cos_g + t * t).powf(1.5);
        let (ta2, tb2) = ((1.0 - ma * ma) / (ma * ma), (1.0 - mb * mb) / (mb * mb));
        let cross = (cos_g - ma * mb) / (ma * mb);
        let g = (ta2 + tb2 - 2.0 * cross).max(0.0).sqrt();
        let rho_c = self.rho_c.unwrap_or(rho0);
        let f = rho0 * shape * hg * (1.0 + (1.0 - rho_c) / (1.0 + g));
        match &self.limit {
            None => f,
            Some(l) => f / l.bound(rho0, rho_c, ma).max(l.bound(rho0, rho_c, mb)),
        }
    }

    /// The same shape with a [`Limit`] that holds its albedo to 1 up to [`MAX_CHECKED_DEG`].
    pub fn limited(self) -> Rpv {
        let raw = Rpv {
            limit: None,
            ..self
        };
        let lo = Limit::ln_mu_min();
        let (mut a1, mut a2) = ([0f32; LIMIT_NODES], [0f32; LIMIT_NODES]);
        for i in 0..LIMIT_NODES {
            let mu = (lo * (1.0 - i as f64 / (LIMIT_NODES - 1) as f64)).exp();
            // the BRF with ρ0 = 1 is S F (1 + (1 − ρ_c)/(1 + G)): ρ_c = 1 leaves A₁, ρ_c = 0
            // A₁ + A₂
            let one = |rho_c| {
                Rpv {
                    rho_c: Some(rho_c),
                    ..raw
                }
                .albedo(1.0, mu, 400, 120)
            };
            let first = one(1.0);
            a1[i] = first as f32;
            a2[i] = (one(0.0) - first).max(0.0) as f32;
        }
        Rpv {
            limit: Some(Limit { a1, a2 }),
            ..self
        }
    }

    /// The directional-hemispherical reflectance (albedo) for light from the direction of
    /// zenith cosine `mu` (0 < μ ≤ 1): ∫ ρ(a, b)/π μ_b dω_b, by the midpoint rule in
    /// (sin²θ_b, φ_b), where μ_b dω_b = ds dφ / 2 (`n_s` × `n_phi` cells).
    pub fn albedo(&self, rho0: f64, mu: f64, n_s: usize, n_phi: usize) -> f64 {
        let a = DVec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
        let mut sum = 0.0;
        for i in 0..n_s {
            let s = (i as f64 + 0.5) / n_s as f64;
            let (st, ct) = (s.sqrt(), (1.0 - s).sqrt());
            for j in 0..n_phi {
                let phi = std::f64::consts::TAU * (j as f64 + 0.5) / n_phi as f64;
                let b = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
                sum += self.brf(rho0, DVec3::Z, a, b);
            }
        }
        // (1/π) ∫∫ ρ ds dφ / 2, with ds dφ = 2π / (n_s n_phi) per cell
        sum / (n_s * n_phi) as f64
    }

    /// The largest albedo over incidence angles from `from_deg` to `to_deg` (whole degrees,
    /// then `to_deg` itself), by [`Rpv::albedo`], and its angle: a surface whose albedo exceeds
    /// 1 would create energy.
    pub fn max_albedo(&self, rho0: f64, from_deg: f64, to_deg: f64) -> (f64, f64) {
        let whole = (from_deg.ceil() as i64..=to_deg.floor() as i64).map(|d| d as f64);
        whole
            .chain(std::iter::once(to_deg))
            .filter(|d| (from_deg..=to_deg).contains(d))
            .map(|deg| {
                let mu = deg.to_radians().cos();
                (self.albedo(rho0, mu, 200, 60), deg)
            })
            .fold((0.0, 0.0), |best, x| if x.0 > best.0 { x } else { best })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOIL: Rpv = Rpv {
        k: 0.75,
        theta: -0.15,
        rho_c: None,
        limit: None,
    };

    /// Reciprocal, hot spot at a = b with G = 0, and Lambertian when k = 1, Θ = 0 and
    /// ρ_c = 1 (ρ(a, b) = ρ0 · 2^0 ... = ρ0 (μ_a μ_b (μ_a + μ_b))^0 · 1 · 1).
    #[test]
    fn reciprocal_with_a_hot_spot_and_lambert_as_a_special_case() {
        let n = DVec3::Z;
        let a = DVec3::new(0.3, -0.2, 0.9).normalize();
        let b = DVec3::new(-0.5, 0.1, 0.6).normalize();
        let (ab, ba) = (SOIL.brf(0.3, n, a, b), SOIL.brf(0.3, n, b, a));
        assert!((ab - ba).abs() < 1e-15 * ab.abs().max(1.0));
        // hot spot: G = 0, cos g = 1
        let mu = a.z;
        let want = 0.3 * (mu * mu * 2.0 * mu).powf(-0.25) * (1.0 - 0.0225) / (0.85f64).powi(3)
            * (1.0 + 0.7);
        // (G is the square root of a difference of squares: 1e-16 in a·a becomes 1e-8 in G)
        assert!((SOIL.brf(0.3, n, a, a) / want - 1.0).abs() < 1e-7);
        // the hot spot is a peak: nearby directions give less
        let near = (a + DVec3::new(0.02, 0.0, 0.0)).normalize();
        assert!(SOIL.brf(0.3, n, a, near) < SOIL.brf(0.3, n, a, a));
        let lambert = Rpv {
            k: 1.0,
            theta: 0.0,
            rho_c: Some(1.0),
            limit: None,
        };
        assert!((lambert.brf(0.42, n, a, b) - 0.42).abs() < 1e-15);
        assert!((lambert.albedo(0.42, 0.7, 200, 60) - 0.42).abs() < 1e-12);
        // the back side (normal −z) mirrors the front
        let (am, bm) = (
            a * DVec3::new(1.0, 1.0, -1.0),
            b * DVec3::new(1.0, 1.0, -1.0),
        );
        assert!((SOIL.brf(0.3, -n, am, bm) - ab).abs() < 1e-15);
    }

    /// The limit holds the albedo to 1 up to 89.9° where RPV's own exceeds it (a soil whose
    /// albedo is 0.92 at 88° and 1.29 at 89.5°), stays reciprocal, and leaves the BRF
    /// unchanged where the albedo from both directions is under 1.
    #[test]
    fn the_limit_holds_the_albedo_to_one_near_grazing_incidence() {
        let rho0 = 0.3;
        let raw = SOIL.max_albedo(rho0, 80.0, MAX_CHECKED_DEG);
        assert!(raw.0 > 1.2, "{raw:?}");
        let limited = SOIL.limited();
        let (top, deg) = limited.max_albedo(rho0, 0.0, MAX_CHECKED_DEG);
        println!("albedo up to {} at {deg}° unlimited, {top} limited", raw.0);
        // the albedo's quadrature is good to about 1e-3
        assert!(top <= 1.0 + 2e-3, "{top} at {deg}°");
        let n = DVec3::Z;
        let a = DVec3::new(1.0, 0.0, 0.005).normalize();
        let b = DVec3::new(-0.3, 0.2, 0.9).normalize();
        let (ab, ba) = (limited.brf(rho0, n, a, b), limited.brf(rho0, n, b, a));
        assert!((ab - ba).abs() < 1e-15 * ab.abs().max(1.0));
        assert!(ab < SOIL.brf(rho0, n, a, b));
        let c = DVec3::new(0.5, 0.1, 0.8).normalize();
        assert_eq!(limited.brf(rho0, n, b, c), SOIL.brf(rho0, n, b, c));
    }
}
