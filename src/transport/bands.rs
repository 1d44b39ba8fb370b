//! Several bands in one pass (campaign.md, `wavelength_nm: [..]`). A path's geometry does not
//! depend on the wavelength, only its throughput does, so each path is sampled once and
//! carries one factor per band:
//!
//!   β_b = β Π_vertices f_b / f  Π_segments T_b / T,
//!
//! where f is the BSDF the path was sampled and weighted with and T the transmittance of the
//! first band's atmosphere (in water, of the band that attenuates least). f takes, for reflection and for transmission separately, the
//! largest of the bands' ρ and τ (ρ_max, τ_max): no band whose material scatters is left
//! unsampled, every factor f_b / f = ρ_b / ρ_max (or ρ_back or τ, by the side the path takes)
//! is at most 1, so no band's weight grows along a path, and paths are as long as the
//! brightest band needs (a mean would cut the near-infrared band's multiple scattering short
//! and weight its survivors up). T_b / T = exp(-(d_b - d_0)) with d the optical depth, and
//! exp(-(c_b - c_min) ℓ) ≤ 1 over ℓ of water: a band the water absorbs (near-infrared light
//! under metres of it) fades in its own factor and never drags the others' weights to 0. The
//! sampling densities are the same for every band, so every strategy's MIS weight is shared
//! and each band's estimate stays unbiased; Russian roulette, decided on the sampled albedo
//! ρ_max + τ_max (which may exceed 1: then no roulette), divides every band alike.

use super::atmosphere::Atmosphere;
use super::{PulseSetup, Vertex, VertexKind};
use crate::campaign::spectral::MAX_BANDS;
use crate::scene::{Rpv, Scene, WaterBody};
use glam::DVec3;

thread_local! {
    /// Band weights this thread's paths lost to underflow since the last
    /// [`take_underflows`]: a factor (water's or the atmosphere's attenuation, a ratio of
    /// BSDFs) that is positive but brought a positive weight to 0.
    static UNDERFLOWS: std::cell::Cell<[u64; MAX_BANDS]> = const { std::cell::Cell::new([0; MAX_BANDS]) };
}

/// The band weights lost to underflow on this thread since the last call, and zero again: a
/// chunk of rays is traced on one thread, which takes them at its end.
pub fn take_underflows() -> [u64; MAX_BANDS] {
    UNDERFLOWS.with(|c| c.replace([0; MAX_BANDS]))
}

/// `r[b] × f` for a ratio of BSDFs f, counting a positive weight that a positive f brings
/// to 0 (f = 0 is a band that does not scatter there: no loss).
#[inline]
fn scale(r: &mut BandVec, b: usize, f: f64) {
    let before = r[b];
    r[b] *= f;
    if r[b] == 0.0 && before > 0.0 && f > 0.0 {
        underflowed(b);
    }
}

/// `r[b] × t` for a transmittance t of a finite optical depth, which is never 0 but may
/// underflow to it: a positive weight brought to 0 is counted.
#[inline]
fn attenuate(r: &mut BandVec, b: usize, t: f64) {
    let before = r[b];
    r[b] *= t;
    if r[b] == 0.0 && before > 0.0 {
        underflowed(b);
    }
}

fn underflowed(b: usize) {
    UNDERFLOWS.with(|c| {
        let mut n = c.get();
        n[b] += 1;
        c.set(n);
    });
}

/// One factor per band (lanes past the campaign's bands are unused).
pub type BandVec = [f64; MAX_BANDS];

/// Every band's factor 1: the start of a sub-path (the laser's energy, the sun's irradiance
/// and the receiver's importance are the same in every band).
pub const ONES: BandVec = [1.0; MAX_BANDS];

/// What turns a path sampled with the bands' mean into each band's throughput.
#[derive(Clone, Debug)]
pub struct Bands {
    pub count: usize,
    /// Per surface and band (index surface × count + band): ρ_b / ρ_max, ρ_back,b / ρ_back,max
    /// and τ_b / τ_max (0 where the largest is 0: no path scatters that way).
    surface: Vec<[f64; 3]>,
    /// Per band, the atmosphere of transmittance T_b / T_0; empty in vacuum.
    atmosphere: Vec<Atmosphere>,
    /// The water column and each band's attenuation less the least of them, per metre.
    water: Option<(WaterBody, Vec<f64>)>,
    /// Per surface, for an RPV one: the shape and amplitudes (front, back) paths are weighted
    /// with, then each band's. Its f_b / f depends on the directions, so it is evaluated.
    rpv: Vec<Option<RpvBands>>,
}

#[derive(Clone, Debug)]
struct RpvBands {
    sampled: (Rpv, [f64; 2]),
    bands: Vec<(Rpv, [f64; 2])>,
}

impl Bands {
    /// The factors of `scene`'s surfaces (loaded in every band, [`Scene::load_bands`]) and, with an atmosphere, of
    /// its transmittance in each band (`per_band[b]`, the first being the one paths use).
    pub fn new(scene: &Scene, per_band: &[Atmosphere]) -> Bands {
        let count = scene.surfaces.first().map_or(1, |s| s.bands.len()).max(1);
        let ratio = |x: f64, mean: f64| if mean > 0.0 { x / mean } else { 0.0 };
        let surface = scene
            .surfaces
            .iter()
            .flat_map(|s| {
                s.bands.iter().map(|b| {
                    if s.water.is_some() {
                        // Fresnel's laws at one refractive index for every band
                        return [1.0; 3];
                    }
                    [
                        ratio(b[0], s.reflectance),
                        ratio(b[1], s.back_reflectance),
                        ratio(b[2], s.transmittance),
                    ]
                })
            })
            .collect();
        let atmosphere = per_band
            .iter()
            .map(|a| a.relative_to(&per_band[0]))
            .collect();
        let rpv = scene
            .surfaces
            .iter()
            .map(|s| {
                s.rpv.map(|shape| RpvBands {
                    sampled: (shape, [s.reflectance, s.back_reflectance]),
                    bands: s
                        .band_rpv
                        .iter()
                        .zip(&s.bands)
                        .map(|(r, b)| (*r, [b[0], b[1]]))
                        .collect(),
                })
            })
            .collect();
        let water = scene.water.as_ref().map(|w| {
            let least = w.attenuation_min;
            (w.clone(), w.attenuation.iter().map(|c| c - least).collect())
        });
        Bands {
            count,
            surface,
            atmosphere,
            rpv,
            water,
        }
    }

    /// Multiplies `r` by each band's f_b / f of the scattering at facet `surface` (normal `n`)
    /// between the unit directions `a` and `b`, both pointing away from it (as
    /// [`bsdf`](super::bsdf)).
    #[inline]
    pub fn scatter(&self, r: &mut BandVec, surface: u32, n: DVec3, a: DVec3, b: DVec3) {
        let (ca, cb) = (n.dot(a), n.dot(b));
        let event = if ca * cb > 0.0 {
            usize::from(ca <= 0.0)
        } else {
            2
        };
        if let (Some(rpv), true) = (&self.rpv[surface as usize], event < 2) {
            let brf = |(shape, rho): &(Rpv, [f64; 2])| shape.brf(rho[event], n, a, b);
            let sampled = brf(&rpv.sampled);
            for (b, band) in rpv.bands.iter().enumerate() {
                if sampled > 0.0 {
                    scale(r, b, brf(band) / sampled);
                } else {
                    r[b] = 0.0;
                }
            }
            return;
        }
        let row = &self.surface[surface as usize * self.count..][..self.count];
        for (b, f) in row.iter().enumerate() {
            scale(r, b, f[event]);
        }
    }

    /// Multiplies `r` by each band's T_b / T of the segment from vertex `a` to the point `b`
    /// (as [`segment_transmittance`](super::bdpt::segment_transmittance)). In water T is the
    /// least attenuating band's, so every band's factor, the first's included, is at most 1.
    #[inline]
    pub fn segment(&self, r: &mut BandVec, a: &Vertex, b: DVec3) {
        if let Some((w, extra)) = &self.water {
            if w.holds(a.p, b) {
                let len = (b - a.p).length();
                for (k, c) in extra.iter().enumerate() {
                    attenuate(r, k, (-c * len).exp());
                }
                return;
            }
        }
        for (k, atm) in self.atmosphere.iter().enumerate().skip(1) {
            let t = if a.kind == VertexKind::Sun {
                atm.transmittance_to_top(b, -a.n)
            } else {
                atm.transmittance(a.p, b)
            };
            attenuate(r, k, t);
        }
    }

    /// Each band's factor of the path light[..s] + cam[..t] joined by a connection: the
    /// sub-paths' own factors, the scattering at both ends of the new segment and its
    /// transmittance.
    pub fn connection(
        &self,
        setup: &PulseSetup,
        light: &[Vertex],
        cam: &[Vertex],
        (lr, cr): (&BandVec, &BandVec),
    ) -> BandVec {
        let (s, t) = (light.len(), cam.len());
        let (x, y) = (&light[s - 1], &cam[t - 1]);
        let mut r: BandVec = *lr;
        for (b, &c) in cr.iter().enumerate() {
            scale(&mut r, b, c);
        }
        let w = if s == 1 && x.kind == VertexKind::Sun {
            setup.sun.map_or(DVec3::ZERO, |sun| sun.dir)
        } else {
            (y.p - x.p).normalize()
        };
        if s >= 2 {
            let towards_prev = (light[s - 2].p - x.p).normalize();
            self.scatter(&mut r, x.surface, x.n, towards_prev, w);
        }
        if t >= 2 {
            let towards_prev = (cam[t - 2].p - y.p).normalize();
            self.scatter(&mut r, y.surface, y.n, -w, towards_prev);
        }
        self.segment(&mut r, x, y.p);
        r
    }
}
