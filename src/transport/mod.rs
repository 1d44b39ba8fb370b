//! Light transport: time-resolved path sampling between the laser and the receiver.
//!
//! The measurement (physics.md, "Receiver") is
//!   Q = ∫_{A_tel} ∫_{θ ≤ θ_fov} L(q, ω) cos θ dω dA,
//! time-resolved by path length l (τ = l / c, Eq. 11-12). Two unidirectional estimators:
//!
//! - `forward` (light tracing): the laser emits Q_e along a direction drawn from Eq. 6, so the
//!   light sub-path starts with throughput β = Q_e. At every surface vertex x the path is
//!   connected to a point q drawn uniformly on the aperture (pdf 1/A_tel):
//!     ΔQ = β f(x) |cos θ_x| cos θ_q / |x - q|² · A_tel,  if x is seen from q within θ_fov.
//! - `backward` (receiver path tracing): q uniform on the aperture and a direction through
//!   the sub-sensor disk (Eq. 9) give β = W_e cos θ / (p_A p_ω) = A_tel A_sub cos⁴θ. At every
//!   vertex y the path is connected to the laser, a point source of intensity Q_e p_L(ω):
//!     ΔQ = β f(y) |cos θ_y| Q_e p_L(ω) / |y - P_L|².
//!
//! Both continue by sampling the Lambertian BSDF (reflection on the incident side or
//! transmission) in proportion to ρ and τ, so the throughput is multiplied by the albedo
//! ρ_side + τ at each bounce; Russian roulette on that albedo after a few bounces keeps the
//! estimate unbiased, and `max_order` caps the number of surface interactions.

pub mod rng;

use crate::campaign::Method;
use crate::scene::{FacetId, Scene, Surface};
use crate::sensor::{Gate, Laser, Receiver};
use glam::DVec3;
use rayon::prelude::*;
use rng::Rng;
use std::f64::consts::{FRAC_1_PI, PI};

/// Rays per independent random stream and per unit of parallel work.
pub const CHUNK_RAYS: u64 = 2048;
/// Bounces before Russian roulette may stop a path.
const ROULETTE_AFTER: u32 = 3;

/// Everything one pulse's paths need.
#[derive(Clone, Copy)]
pub struct PulseSetup<'a> {
    pub scene: &'a Scene,
    pub laser: Laser,
    pub receiver: Receiver,
    pub gate: Gate,
    /// Sub-bins per bin: contributions are kept at this finer time resolution so the pulse
    /// convolution does not depend on where a path falls inside its bin.
    pub sub_bins: usize,
    pub method: Method,
    pub max_order: u32,
    pub seed: u64,
    pub pulse_id: u64,
}

/// Received laser energy of one pulse, by time and by scattering order, with the sums of
/// squares over rays needed for standard errors.
#[derive(Clone, Debug, PartialEq)]
pub struct Tally {
    /// Energy per sub-bin over the gate, J.
    pub sub: Vec<f64>,
    /// Energy whose time fell outside the gate, J.
    pub outside: f64,
    /// Σ over rays of each ray's energy per order (index 0 = order 1).
    pub order_sum: Vec<f64>,
    /// Σ over rays of the square of each ray's energy per order.
    pub order_sq: Vec<f64>,
    /// Σ over rays of the square of each ray's total energy.
    pub total_sq: f64,
    pub rays: u64,
    /// Connections that carried energy (paths found), over all rays.
    pub paths: u64,
}

impl Tally {
    fn new(sub_len: usize, max_order: u32) -> Tally {
        Tally {
            sub: vec![0.0; sub_len],
            outside: 0.0,
            order_sum: vec![0.0; max_order as usize],
            order_sq: vec![0.0; max_order as usize],
            total_sq: 0.0,
            rays: 0,
            paths: 0,
        }
    }

    fn merge(&mut self, o: &Tally) {
        for (a, b) in self.sub.iter_mut().zip(&o.sub) {
            *a += b;
        }
        self.outside += o.outside;
        for (a, b) in self.order_sum.iter_mut().zip(&o.order_sum) {
            *a += b;
        }
        for (a, b) in self.order_sq.iter_mut().zip(&o.order_sq) {
            *a += b;
        }
        self.total_sq += o.total_sq;
        self.rays += o.rays;
        self.paths += o.paths;
    }

    /// Mean received energy per order over the rays, J (the estimate of Q_k).
    pub fn order_energy(&self) -> Vec<f64> {
        let n = self.rays.max(1) as f64;
        self.order_sum.iter().map(|s| s / n).collect()
    }

    /// Standard error of each order's estimate, J.
    pub fn order_se(&self) -> Vec<f64> {
        self.order_sum
            .iter()
            .zip(&self.order_sq)
            .map(|(s, q)| se(*s, *q, self.rays))
            .collect()
    }

    pub fn total_energy(&self) -> f64 {
        self.order_sum.iter().sum::<f64>() / self.rays.max(1) as f64
    }

    pub fn total_se(&self) -> f64 {
        se(self.order_sum.iter().sum(), self.total_sq, self.rays)
    }
}

/// Standard error of a mean from the sum and sum of squares of n samples.
fn se(sum: f64, sq: f64, n: u64) -> f64 {
    if n < 2 {
        return 0.0;
    }
    let n = n as f64;
    let mean = sum / n;
    ((sq / n - mean * mean).max(0.0) / (n - 1.0)).sqrt()
}

/// Per-chunk accumulator: one ray's contributions are staged per order, so that the
/// sums of squares are over whole rays.
struct Accum<'a> {
    tally: Tally,
    gate: &'a Gate,
    sub_dt: f64,
    ray_order: Vec<f64>,
    touched: Vec<u32>,
}

impl<'a> Accum<'a> {
    fn new(setup: &'a PulseSetup) -> Accum<'a> {
        Accum {
            tally: Tally::new(setup.gate.bins * setup.sub_bins, setup.max_order),
            gate: &setup.gate,
            sub_dt: setup.gate.dt / setup.sub_bins as f64,
            ray_order: vec![0.0; setup.max_order as usize],
            touched: Vec::with_capacity(8),
        }
    }

    /// A path of `length` metres and `order` surface interactions carrying `energy` joules.
    fn add(&mut self, length: f64, energy: f64, order: u32) {
        if !(energy > 0.0) || !energy.is_finite() {
            return;
        }
        let tau = length / crate::C;
        let x = (tau - self.gate.t0) / self.sub_dt;
        if x >= 0.0 && (x as usize) < self.tally.sub.len() {
            self.tally.sub[x as usize] += energy;
        } else {
            self.tally.outside += energy;
        }
        let k = order as usize - 1;
        if self.ray_order[k] == 0.0 {
            self.touched.push(k as u32);
        }
        self.ray_order[k] += energy;
        self.tally.paths += 1;
    }

    fn end_ray(&mut self) {
        let mut total = 0.0;
        for &k in &self.touched {
            let x = self.ray_order[k as usize];
            self.tally.order_sum[k as usize] += x;
            self.tally.order_sq[k as usize] += x * x;
            total += x;
            self.ray_order[k as usize] = 0.0;
        }
        self.touched.clear();
        self.tally.total_sq += total * total;
        self.tally.rays += 1;
    }
}

/// Lambertian BSDF of a facet for light arriving from `wi` and leaving along `wo` (both unit,
/// pointing away from the surface): ρ/π on the side the light comes from, τ/π through it.
#[inline]
pub fn bsdf(s: &Surface, n: DVec3, wi: DVec3, wo: DVec3) -> f64 {
    let ci = n.dot(wi);
    let co = n.dot(wo);
    if ci * co > 0.0 {
        (if ci > 0.0 {
            s.reflectance
        } else {
            s.back_reflectance
        }) * FRAC_1_PI
    } else if ci * co < 0.0 {
        s.transmittance * FRAC_1_PI
    } else {
        0.0
    }
}

/// Samples the next direction at a facet reached from `w_prev` (unit, pointing back along the
/// path): reflection on that side with probability ρ_side / a, transmission with τ / a, each
/// cosine-distributed. Returns the direction and the throughput factor f cos / pdf = a.
#[inline]
fn sample_bsdf(s: &Surface, n: DVec3, w_prev: DVec3, rng: &mut Rng) -> Option<(DVec3, f64)> {
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
    let u1 = rng.uniform();
    let u2 = rng.uniform();
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let f = crate::sensor::Frame::from_axis(axis);
    let d = f.to_world(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
    Some((d.normalize(), a))
}

/// Russian roulette on the albedo just applied: survive with probability a, and undo the
/// factor on survival, so the expectation is unchanged.
#[inline]
fn roulette(order: u32, beta: &mut f64, a: f64, rng: &mut Rng) -> bool {
    if order < ROULETTE_AFTER || a >= 1.0 {
        return true;
    }
    let p = a.max(0.05);
    if rng.uniform() >= p {
        return false;
    }
    *beta /= p;
    true
}

fn trace_forward(setup: &PulseSetup, rng: &mut Rng, acc: &mut Accum) {
    let scene = setup.scene;
    let (laser, recv) = (&setup.laser, &setup.receiver);
    let (mut dir, _) = laser.sample(rng.uniform(), rng.uniform());
    let mut origin = laser.position;
    let mut beta = laser.energy;
    let mut length = 0.0;
    let mut skip = FacetId::NONE;
    for order in 1..=setup.max_order {
        let Some(hit) = scene.intersect(origin, dir, f64::INFINITY, skip) else {
            break;
        };
        length += hit.t;
        let x = hit.position;
        let surf = &scene.surfaces[hit.surface as usize];
        let wi = -dir;
        // Connect to a point of the aperture.
        let q = recv.sample_point(rng.uniform(), rng.uniform());
        let d = x - q;
        let r2 = d.length_squared();
        let r = r2.sqrt();
        let dn = d / r;
        if let Some(cos_q) = recv.accepts(dn) {
            let wo = -dn;
            let f = bsdf(surf, hit.normal, wi, wo);
            let cos_x = hit.normal.dot(wo).abs();
            if f > 0.0 && cos_x > 0.0 && !scene.occluded(x, q, hit.facet, FacetId::NONE) {
                acc.add(length + r, beta * f * cos_x * cos_q / r2 * recv.area, order);
            }
        }
        if order == setup.max_order {
            break;
        }
        let Some((next, a)) = sample_bsdf(surf, hit.normal, wi, rng) else {
            break;
        };
        beta *= a;
        if !roulette(order, &mut beta, a, rng) {
            break;
        }
        origin = x;
        dir = next;
        skip = hit.facet;
    }
}

fn trace_backward(setup: &PulseSetup, rng: &mut Rng, acc: &mut Accum) {
    let scene = setup.scene;
    let (laser, recv) = (&setup.laser, &setup.receiver);
    let mut origin = recv.sample_point(rng.uniform(), rng.uniform());
    let (mut dir, w) = recv.sample_direction(rng.uniform(), rng.uniform());
    let mut beta = recv.area * w;
    let mut length = 0.0;
    let mut skip = FacetId::NONE;
    for order in 1..=setup.max_order {
        let Some(hit) = scene.intersect(origin, dir, f64::INFINITY, skip) else {
            break;
        };
        length += hit.t;
        let y = hit.position;
        let surf = &scene.surfaces[hit.surface as usize];
        let wo = -dir;
        // Connect to the laser, a point source.
        let d = y - laser.position;
        let r2 = d.length_squared();
        let r = r2.sqrt();
        let dn = d / r;
        let p = laser.pdf(dn);
        if p > 0.0 {
            let wi = -dn;
            let f = bsdf(surf, hit.normal, wi, wo);
            let cos_y = hit.normal.dot(wi).abs();
            if f > 0.0
                && cos_y > 0.0
                && !scene.occluded(y, laser.position, hit.facet, FacetId::NONE)
            {
                acc.add(length + r, beta * f * cos_y * laser.energy * p / r2, order);
            }
        }
        if order == setup.max_order {
            break;
        }
        let Some((next, a)) = sample_bsdf(surf, hit.normal, wo, rng) else {
            break;
        };
        beta *= a;
        if !roulette(order, &mut beta, a, rng) {
            break;
        }
        origin = y;
        dir = next;
        skip = hit.facet;
    }
}

/// Traces `rays` paths of one pulse, in chunks of [`CHUNK_RAYS`] run in parallel; each chunk
/// has its own random stream and the chunks are merged in order, so the result is the same
/// whatever the number of threads.
pub fn simulate_pulse(setup: &PulseSetup, rays: u64) -> Tally {
    let chunks = rays.div_ceil(CHUNK_RAYS);
    let parts: Vec<Tally> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(setup.seed, setup.pulse_id, c);
            let mut acc = Accum::new(setup);
            let n = CHUNK_RAYS.min(rays - c * CHUNK_RAYS);
            for _ in 0..n {
                match setup.method {
                    Method::Forward => trace_forward(setup, &mut rng, &mut acc),
                    Method::Backward => trace_backward(setup, &mut rng, &mut acc),
                    Method::Bdpt => unreachable!("bdpt is rejected when the campaign is validated"),
                }
                acc.end_ray();
            }
            acc.tally
        })
        .collect();
    let mut total = Tally::new(setup.gate.bins * setup.sub_bins, setup.max_order);
    for p in &parts {
        total.merge(p);
    }
    total
}
