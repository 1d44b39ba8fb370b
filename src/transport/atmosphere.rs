//! The plane-parallel exponential atmosphere of campaign.md: layer i has extinction
//! β_i(z) = (τ_i / H_i) e^(-z/H_i) per metre at height z above z = 0 (heights below 0 count
//! as 0), so a straight segment from z1 to z2 of length ℓ (μ = |z2 - z1| / ℓ) has optical depth
//!
//!   Σ_i τ_i |e^(-z1/H_i) - e^(-z2/H_i)| / μ,   and ℓ Σ_i (τ_i / H_i) e^(-z/H_i) when z1 = z2 = z,
//!
//! computed as ℓ (τ/H) e^(-z_lo/H) (1 - e^(-Δ/H)) / (Δ/H), which is both at once and never
//! overflows. Every segment of every path is weighted by its transmittance e^(-depth): the
//! sampling densities do not change, so every strategy's estimate and MIS weight stay as they
//! are, and the weights change no random draw.

use crate::campaign;
use glam::DVec3;

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Atmosphere {
    /// (1 / H_i, τ_i) of each layer at the campaign's wavelength.
    layers: Vec<(f64, f64)>,
}

/// (1 - e^(-x)) / x, 1 at x = 0.
fn mean_decay(x: f64) -> f64 {
    if x.abs() < 1e-12 {
        1.0
    } else {
        -(-x).exp_m1() / x
    }
}

impl Atmosphere {
    /// The atmosphere at `wavelength_nm`, or why a layer has no optical depth for it.
    pub fn new(config: &campaign::Atmosphere, wavelength_nm: f64) -> Result<Atmosphere, String> {
        let layers = config
            .layers
            .iter()
            .map(|l| Ok((1.0 / l.scale_height_m, l.optical_depth.at(wavelength_nm)?)))
            .collect::<Result<Vec<_>, String>>()?;
        Ok(Atmosphere { layers })
    }

    /// The atmosphere whose optical depths are this one's less `reference`'s, layer by layer
    /// (same scale heights): optical depth is linear in τ, so its transmittance is this one's
    /// over the reference's, without the 0/0 of two vanishing transmittances.
    pub fn relative_to(&self, reference: &Atmosphere) -> Atmosphere {
        Atmosphere {
            layers: self
                .layers
                .iter()
                .zip(&reference.layers)
                .map(|(&(k, t), &(_, r))| (k, t - r))
                .collect(),
        }
    }

    /// Optical depth of the straight segment from `a` to `b`.
    pub fn optical_depth(&self, a: DVec3, b: DVec3) -> f64 {
        let length = (b - a).length();
        let (lo, hi) = (a.z.min(b.z), a.z.max(b.z));
        // the part of the segment below z = 0 and the part above it
        let below = if hi > lo {
            (hi.min(0.0) - lo).max(0.0) / (hi - lo)
        } else if lo < 0.0 {
            1.0
        } else {
            0.0
        };
        let z0 = lo.max(0.0);
        let rise = (hi - z0).max(0.0);
        self.layers
            .iter()
            .map(|&(k, tau)| {
                let above = tau * k * (-z0 * k).exp() * mean_decay(rise * k);
                length * (below * tau * k + (1.0 - below) * above)
            })
            .sum()
    }

    pub fn transmittance(&self, a: DVec3, b: DVec3) -> f64 {
        (-self.optical_depth(a, b)).exp()
    }

    /// Transmittance from `p` along the unit direction `up` to the top of the atmosphere: the
    /// sun's path down to `p` (with `up` towards the sun). Nothing leaves downwards.
    pub fn transmittance_to_top(&self, p: DVec3, up: DVec3) -> f64 {
        if up.z <= 0.0 {
            return 0.0;
        }
        let depth: f64 = self
            .layers
            .iter()
            .map(|&(k, tau)| tau * ((-p.z.max(0.0) * k).exp() + (-p.z).max(0.0) * k))
            .sum();
        (-depth / up.z).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::spectral::Spectral;

    fn atmosphere() -> Atmosphere {
        let config = campaign::Atmosphere {
            layers: vec![
                campaign::AtmosphereLayer {
                    scale_height_m: 8000.0,
                    optical_depth: Spectral::Table(vec![(532.0, 0.12), (1064.0, 0.008)]),
                },
                campaign::AtmosphereLayer {
                    scale_height_m: 1500.0,
                    optical_depth: Spectral::Single(0.2),
                },
            ],
        };
        Atmosphere::new(&config, 532.0).unwrap()
    }

    #[test]
    fn slant_and_horizontal_segments_follow_the_spec() {
        let a = atmosphere();
        // the spec's slant formula
        let (p, q) = (DVec3::new(0.0, 0.0, 100.0), DVec3::new(300.0, 0.0, 2500.0));
        let mu = (q.z - p.z) / (q - p).length();
        let want: f64 = [(8000.0f64, 0.12f64), (1500.0, 0.2)]
            .iter()
            .map(|&(h, t)| t * ((-p.z / h).exp() - (-q.z / h).exp()).abs() / mu)
            .sum();
        assert!((a.optical_depth(p, q) / want - 1.0).abs() < 1e-12);
        assert!((a.optical_depth(q, p) / want - 1.0).abs() < 1e-12);
        // horizontal, and its limit
        let (h0, h1) = (DVec3::new(0.0, 0.0, 700.0), DVec3::new(50.0, 0.0, 700.0));
        let want: f64 = [(8000.0f64, 0.12f64), (1500.0, 0.2)]
            .iter()
            .map(|&(h, t)| t * (-700.0f64 / h).exp() * 50.0 / h)
            .sum();
        assert!((a.optical_depth(h0, h1) / want - 1.0).abs() < 1e-12);
        let nearly = a.optical_depth(h0, h1 + DVec3::Z * 1e-9);
        assert!((nearly / want - 1.0).abs() < 1e-9);
        // the whole column from 419 km to the ground is the sum of the optical depths
        let col = a.optical_depth(DVec3::new(0.0, 0.0, 419e3), DVec3::ZERO);
        assert!((col - 0.32).abs() < 1e-12, "{col}");
        let up = a.transmittance_to_top(DVec3::ZERO, DVec3::new(0.5, 0.0, 0.75f64.sqrt()));
        assert!((up - (-0.32 / 0.75f64.sqrt()).exp()).abs() < 1e-12);
    }

    #[test]
    fn heights_below_zero_count_as_zero() {
        let a = atmosphere();
        let k: f64 = 0.12 / 8000.0 + 0.2 / 1500.0;
        let flat = a.optical_depth(DVec3::new(0.0, 0.0, -5.0), DVec3::new(10.0, 0.0, -5.0));
        assert!((flat / (10.0 * k) - 1.0).abs() < 1e-12);
        // 4 m of a vertical segment below 0, then 0 to 6 m
        let crossing = a.optical_depth(DVec3::new(0.0, 0.0, -4.0), DVec3::new(0.0, 0.0, 6.0));
        let want = 4.0 * k + a.optical_depth(DVec3::ZERO, DVec3::new(0.0, 0.0, 6.0));
        assert!((crossing / want - 1.0).abs() < 1e-12);
    }
}
