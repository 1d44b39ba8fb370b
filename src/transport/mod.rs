//! Light transport: time-resolved bidirectional path tracing with multiple importance
//! sampling (paper section 2.3, Eq. 10-17; Veach 1997, ch. 10; pbrt-v4's BDPTIntegrator).
//!
//! The measurement (physics.md, "Receiver") is
//!   Q = ∫_{A_tel} ∫_{θ ≤ θ_fov} L(q, ω) cos θ dω dA,
//! resolved in time by each path's length l (τ = l / c). A path x_0 … x_n runs from the
//! laser x_0 to a point x_n of the aperture through n - 1 surface interactions (its order).
//!
//! Every sample traces a light sub-path from the laser (x_0 is a delta position, the first
//! direction follows Eq. 6) and a receiver sub-path from the aperture (uniform point, direction
//! through the sub-sensor disk, Eq. 9), then joins them in every way:
//! - s = 1, t ≥ 2: a receiver vertex is connected to the laser ("connect to light");
//! - s ≥ 2, t = 1: a light vertex is connected to a point drawn on the aperture ("connect to
//!   receiver");
//! - s ≥ 2, t ≥ 2: a light vertex is connected to a receiver vertex ("connect vertices");
//! - t = 0: the light sub-path itself crosses the aperture within the field of view.
//!
//! A receiver sub-path never hits the laser (a point), so s = 0 has no weight.
//!
//! Each strategy's estimate f/p is weighted by the power (or balance) heuristic over the
//! strategies that could have made the same path (Eq. 16-17). Vertices keep the area densities
//! of being sampled forwards (`pdf_fwd`, by their own sub-path) and in reverse (`pdf_rev`, by
//! the other one), so a weight costs O(n) and only the densities next to the junction are
//! recomputed per connection.
//!
//! `forward` and `backward` are this same tracer with one sub-path capped (paper section 4.2):
//! forward keeps the receiver sub-path to its aperture point (strategies t ≤ 1), backward the
//! light sub-path to the laser (s = 1). So the three methods cannot drift apart.

use crate::campaign::{Method, MisHeuristic};
use crate::rng::Rng;
use crate::scene::{FacetId, Scene, Surface};
use crate::sensor::{Frame, Gate, Laser, Receiver, SunSource};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, PI};

/// Rays per independent random stream and per unit of parallel work.
pub const CHUNK_RAYS: u64 = 2048;
/// Surface interactions before Russian roulette may stop a sub-path.
const ROULETTE_AFTER: usize = 3;

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
    pub heuristic: MisHeuristic,
    /// The sun, when the campaign has one: its paths share the receiver sub-paths.
    pub sun: Option<SunSource>,
    pub max_order: u32,
    pub seed: u64,
    pub pulse_id: u64,
}

impl PulseSetup<'_> {
    /// Most vertices the light and the receiver sub-paths may have, end points included.
    pub fn caps(&self) -> (usize, usize) {
        let full = self.max_order as usize + 1;
        match self.method {
            Method::Forward => (full, 1),
            Method::Backward => (1, full),
            Method::Bdpt => (full, full),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Laser,
    /// A point of the sun's disk: a delta direction, so its position is fixed by the next
    /// vertex and the density that matters is that of the first surface point.
    Sun,
    Aperture,
    Surface,
}

/// A vertex of a light or receiver sub-path.
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub kind: Kind,
    pub p: DVec3,
    /// Front normal of a facet, or the sensor axis for the laser and the aperture.
    pub n: DVec3,
    pub surface: u32,
    pub facet: FacetId,
    /// Throughput of the sub-path up to this vertex over its sampling densities: energy (J)
    /// on a light sub-path, importance (m² sr) on a receiver sub-path.
    pub beta: f64,
    /// Length of the sub-path from its start to this vertex, m.
    pub len: f64,
    /// Area density of this vertex as sampled by its own sub-path.
    pub pdf_fwd: f64,
    /// Area density of this vertex if the other sub-path had sampled it.
    pub pdf_rev: f64,
}

impl Vertex {
    pub fn endpoint(kind: Kind, p: DVec3, axis: DVec3, pdf_fwd: f64) -> Vertex {
        Vertex {
            kind,
            p,
            n: axis,
            surface: u32::MAX,
            facet: FacetId::NONE,
            beta: 1.0,
            len: 0.0,
            pdf_fwd,
            pdf_rev: 0.0,
        }
    }
}

/// Received laser energy of one pulse, by time and by scattering order, with the sums of
/// squares over rays needed for standard errors.
#[derive(Clone, Debug, PartialEq)]
pub struct Tally {
    /// Energy per sub-bin over the gate, J.
    pub sub: Vec<f64>,
    /// Σ energy × position within its sub-bin (0..1) per sub-bin: the energy's mean time in
    /// each sub-bin, so that the pulse convolution puts a return where it was, not at a
    /// sub-bin centre (up to σ/8 off otherwise, 1.9 cm of range for a 4 ns pulse).
    pub sub_moment: Vec<f64>,
    /// Σ over rays of the square of each ray's energy per bin.
    pub bin_sq: Vec<f64>,
    /// Energy per bin by the class of the surface the laser lit first (ground, vegetation,
    /// building, other): the truth a real scanner never knows, for labelling returns.
    pub class_bins: [Vec<f64>; 4],
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
    /// Σ over rays of each ray's received solar power, W, and of its square.
    pub solar_sum: f64,
    pub solar_sq: f64,
}

impl Tally {
    fn new(bins: usize, sub_bins: usize, max_order: u32) -> Tally {
        Tally {
            sub: vec![0.0; bins * sub_bins],
            sub_moment: vec![0.0; bins * sub_bins],
            bin_sq: vec![0.0; bins],
            class_bins: std::array::from_fn(|_| vec![0.0; bins]),
            outside: 0.0,
            order_sum: vec![0.0; max_order as usize],
            order_sq: vec![0.0; max_order as usize],
            total_sq: 0.0,
            rays: 0,
            paths: 0,
            solar_sum: 0.0,
            solar_sq: 0.0,
        }
    }

    fn merge(&mut self, o: &Tally) {
        let add = |a: &mut [f64], b: &[f64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        add(&mut self.sub, &o.sub);
        add(&mut self.sub_moment, &o.sub_moment);
        add(&mut self.bin_sq, &o.bin_sq);
        for (a, b) in self.class_bins.iter_mut().zip(&o.class_bins) {
            add(a, b);
        }
        add(&mut self.order_sum, &o.order_sum);
        add(&mut self.order_sq, &o.order_sq);
        self.outside += o.outside;
        self.total_sq += o.total_sq;
        self.rays += o.rays;
        self.paths += o.paths;
        self.solar_sum += o.solar_sum;
        self.solar_sq += o.solar_sq;
    }

    /// Mean received solar power over the receiver band, W, and its standard error.
    pub fn solar_power(&self) -> (f64, f64) {
        (
            self.solar_sum / self.rays.max(1) as f64,
            se(self.solar_sum, self.solar_sq, self.rays),
        )
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

    /// Standard error of each bin's impulse energy, J.
    pub fn bin_se(&self, sub_bins: usize) -> Vec<f64> {
        self.sub
            .chunks(sub_bins)
            .zip(&self.bin_sq)
            .map(|(c, q)| se(c.iter().sum(), *q, self.rays))
            .collect()
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

/// Per-chunk accumulator. A ray's contributions are staged per order and per bin, so that
/// sums of squares are over whole rays (a ray is one sample of the estimator).
struct Accum {
    tally: Tally,
    t0: f64,
    sub_dt: f64,
    sub_bins: usize,
    ray_order: Vec<f64>,
    ray_bin: Vec<f64>,
    touched_orders: Vec<u32>,
    touched_bins: Vec<u32>,
    ray_solar: f64,
}

impl Accum {
    fn new(setup: &PulseSetup) -> Accum {
        Accum {
            tally: Tally::new(setup.gate.bins, setup.sub_bins, setup.max_order),
            t0: setup.gate.t0,
            sub_dt: setup.gate.dt / setup.sub_bins as f64,
            sub_bins: setup.sub_bins,
            ray_order: vec![0.0; setup.max_order as usize],
            ray_bin: vec![0.0; setup.gate.bins],
            touched_orders: Vec::with_capacity(16),
            touched_bins: Vec::with_capacity(16),
            ray_solar: 0.0,
        }
    }

    /// A solar path carrying `power` watts (the sun is continuous: no time, no bin).
    fn add_solar(&mut self, power: f64) {
        if power > 0.0 && power.is_finite() {
            self.ray_solar += power;
            self.tally.paths += 1;
        }
    }

    /// A path of `length` metres and `order` surface interactions carrying `energy` joules.
    fn add(&mut self, length: f64, energy: f64, order: usize, class: usize) {
        if !(energy > 0.0 && energy.is_finite()) || order == 0 {
            return;
        }
        let x = (length / crate::C - self.t0) / self.sub_dt;
        if x >= 0.0 && (x as usize) < self.tally.sub.len() {
            let i = x as usize;
            self.tally.sub[i] += energy;
            self.tally.sub_moment[i] += energy * (x - i as f64);
            let b = i / self.sub_bins;
            self.tally.class_bins[class][b] += energy;
            if self.ray_bin[b] == 0.0 {
                self.touched_bins.push(b as u32);
            }
            self.ray_bin[b] += energy;
        } else {
            self.tally.outside += energy;
        }
        let k = order - 1;
        if self.ray_order[k] == 0.0 {
            self.touched_orders.push(k as u32);
        }
        self.ray_order[k] += energy;
        self.tally.paths += 1;
    }

    fn end_ray(&mut self) {
        let mut total = 0.0;
        for &k in &self.touched_orders {
            let x = std::mem::take(&mut self.ray_order[k as usize]);
            self.tally.order_sum[k as usize] += x;
            self.tally.order_sq[k as usize] += x * x;
            total += x;
        }
        for &b in &self.touched_bins {
            let x = std::mem::take(&mut self.ray_bin[b as usize]);
            self.tally.bin_sq[b as usize] += x * x;
        }
        self.touched_orders.clear();
        self.touched_bins.clear();
        let x = std::mem::take(&mut self.ray_solar);
        self.tally.solar_sum += x;
        self.tally.solar_sq += x * x;
        self.tally.total_sq += total * total;
        self.tally.rays += 1;
    }
}

/// Lambertian BSDF of a facet between the unit directions `a` and `b` (both pointing away
/// from the surface): ρ/π on the side they share, τ/π through the facet.
#[inline]
pub fn bsdf(s: &Surface, n: DVec3, a: DVec3, b: DVec3) -> f64 {
    let (ca, cb) = (n.dot(a), n.dot(b));
    if ca * cb > 0.0 {
        (if ca > 0.0 {
            s.reflectance
        } else {
            s.back_reflectance
        }) * FRAC_1_PI
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
/// path). Returns it with the throughput factor f |cos| / pdf, which is the albedo a.
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
    let (u1, u2) = (rng.uniform(), rng.uniform());
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let d =
        Frame::from_axis(axis).to_world(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
    Some((d.normalize(), a))
}

/// Area density at `to` of sampling it from `from`, itself reached from `prev` (the end
/// points' own distributions do not depend on a previous vertex).
fn pdf_area(setup: &PulseSetup, prev: Option<&Vertex>, from: &Vertex, to: &Vertex) -> f64 {
    let d = to.p - from.p;
    let r2 = d.length_squared();
    if r2 == 0.0 {
        return 0.0;
    }
    let w = d / r2.sqrt();
    let pdf_dir = match from.kind {
        // the disk's uniform density, projected onto the surface: no 1/r² for a direction
        Kind::Sun => {
            return setup
                .sun
                .map_or(0.0, |sun| to.n.dot(sun.dir).abs() / sun.disk_area());
        }
        Kind::Laser => setup.laser.pdf(w),
        Kind::Aperture => setup.receiver.pdf_dir(w),
        Kind::Surface => match prev {
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
pub fn mis_weight(
    setup: &PulseSetup,
    light: &[Vertex],
    cam: &[Vertex],
    scratch: &mut Vec<f64>,
) -> f64 {
    let (s, t) = (light.len(), cam.len());
    let nv = s + t;
    let (s_cap, t_cap) = setup.caps();
    let lo = nv.saturating_sub(t_cap).max(1);
    let hi = nv.min(s_cap);
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
    // The densities next to the junction depend on this connection.
    if t >= 1 {
        pl[s] = pdf_area(
            setup,
            if s >= 2 { Some(x(s - 2)) } else { None },
            x(s - 1),
            x(s),
        );
        if t >= 2 {
            pl[s + 1] = pdf_area(setup, Some(x(s - 1)), x(s), x(s + 1));
        }
        pc[s - 1] = pdf_area(
            setup,
            if t >= 2 { Some(x(s + 1)) } else { None },
            x(s),
            x(s - 1),
        );
        if s >= 2 {
            pc[s - 2] = pdf_area(setup, Some(x(s)), x(s - 1), x(s - 2));
        }
    } else {
        // t = 0: the light sub-path ends on the aperture, which the receiver samples uniformly.
        pc[nv - 1] = 1.0 / setup.receiver.area;
        pc[nv - 2] = pdf_area(setup, None, x(nv - 1), x(nv - 2));
    }
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
        sum += h(r);
    }
    r = 1.0;
    for k in (lo..s).rev() {
        r *= pc[k] / pl[k];
        if k == 1 {
            r /= q;
        }
        sum += h(r);
    }
    if sum.is_finite() {
        1.0 / sum
    } else {
        0.0
    }
}

/// Index of the surface class (ground, vegetation, building, other) of the path's first
/// surface: the one the laser lit, which a return's range points at.
#[inline]
fn class_of(setup: &PulseSetup, v: &Vertex) -> usize {
    use crate::scene::SurfaceClass;
    match setup
        .scene
        .surfaces
        .get(v.surface as usize)
        .map(|s| s.class)
    {
        Some(SurfaceClass::Ground) => 0,
        Some(SurfaceClass::Vegetation) => 1,
        Some(SurfaceClass::Building) => 2,
        _ => 3,
    }
}

/// Reusable per-thread buffers.
struct Buffers {
    light: Vec<Vertex>,
    cam: Vec<Vertex>,
    scratch: Vec<f64>,
}

fn surface_vertex(hit: &crate::scene::Hit, beta: f64, len: f64) -> Vertex {
    Vertex {
        kind: Kind::Surface,
        p: hit.position,
        n: hit.normal,
        surface: hit.surface,
        facet: hit.facet,
        beta,
        len,
        pdf_fwd: 0.0,
        pdf_rev: 0.0,
    }
}

/// Russian roulette on the albedo just applied: survive with probability a (at least 0.05)
/// and undo the factor on survival, so the expectation is unchanged.
#[inline]
fn survives(surfaces: usize, beta: &mut f64, a: f64, rng: &mut Rng) -> bool {
    if surfaces < ROULETTE_AFTER || a >= 1.0 {
        return true;
    }
    let p = a.max(0.05);
    if rng.uniform() >= p {
        return false;
    }
    *beta /= p;
    true
}

/// Extends a sub-path whose last vertex emits along `dir` with throughput `beta`, up to
/// `cap` vertices. On a light sub-path (`light`), a segment that crosses the aperture before
/// any facet is the strategy t = 0 and is scored on the way.
#[allow(clippy::too_many_arguments)]
fn walk(
    setup: &PulseSetup,
    path: &mut Vec<Vertex>,
    mut dir: DVec3,
    mut beta: f64,
    cap: usize,
    light: bool,
    rng: &mut Rng,
    acc: &mut Accum,
    scratch: &mut Vec<f64>,
) {
    let scene = setup.scene;
    let recv = &setup.receiver;
    while path.len() < cap {
        let last = *path.last().expect("a sub-path starts at its end point");
        let surfaces = path.len() - 1;
        let hit = scene.intersect(last.p, dir, f64::INFINITY, last.facet);
        if light && surfaces >= 1 {
            if let Some(tq) = recv.hit_distance(last.p, dir) {
                if hit.as_ref().is_none_or(|h| tq < h.t) && recv.accepts(-dir).is_some() {
                    let mut q =
                        Vertex::endpoint(Kind::Aperture, last.p + dir * tq, recv.frame.w, 0.0);
                    q.beta = beta;
                    q.len = last.len + tq;
                    path.push(q);
                    link(setup, path);
                    let w = mis_weight(setup, path, &[], scratch);
                    if path[0].kind == Kind::Sun {
                        acc.add_solar(beta * w);
                    } else {
                        acc.add(q.len, beta * w, surfaces, class_of(setup, &path[1]));
                    }
                    path.pop();
                }
            }
        }
        let Some(hit) = hit else { break };
        path.push(surface_vertex(&hit, beta, last.len + hit.t));
        link(setup, path);
        if path.len() >= cap {
            break;
        }
        let surf = &scene.surfaces[hit.surface as usize];
        let Some((next, a)) = sample_bsdf(surf, hit.normal, -dir, rng) else {
            break;
        };
        beta *= a;
        if !survives(surfaces + 1, &mut beta, a, rng) {
            break;
        }
        dir = next;
    }
}

/// Unweighted estimate f/p of the path light[..s] + cam[..t] (t ≥ 1, s ≥ 1, s + t ≥ 3) and
/// its length, or None when it carries nothing. Visibility is not tested here.
fn contribution(setup: &PulseSetup, light: &[Vertex], cam: &[Vertex]) -> Option<(f64, f64)> {
    let surfaces = &setup.scene.surfaces;
    let (s, t) = (light.len(), cam.len());
    let x = &light[s - 1];
    let y = &cam[t - 1];
    let d = y.p - x.p;
    let r2 = d.length_squared();
    if r2 == 0.0 {
        return None;
    }
    let r = r2.sqrt();
    let w = d / r; // from the light side towards the receiver side
    if s == 1 && x.kind == Kind::Sun {
        // irradiance E Δλ from a fixed direction: no distance, no falloff
        let sun = setup.sun?;
        let towards_prev = (cam[t - 2].p - y.p).normalize();
        let f_y = bsdf(&surfaces[y.surface as usize], y.n, -sun.dir, towards_prev)
            * y.n.dot(sun.dir).abs();
        let c = x.beta * sun.band_irradiance * f_y * y.beta;
        return (c > 0.0).then_some((c, 0.0));
    }
    let f_x = if s == 1 {
        // the laser: radiant intensity Q_e p_L(ω) per unit solid angle
        setup.laser.energy * setup.laser.pdf(w)
    } else {
        let towards_prev = (light[s - 2].p - x.p).normalize();
        bsdf(&surfaces[x.surface as usize], x.n, towards_prev, w) * x.n.dot(w).abs()
    };
    if f_x == 0.0 {
        return None;
    }
    let f_y = if t == 1 {
        // a point drawn on the aperture (pdf 1/A): W_e cos θ_q A
        setup.receiver.accepts(-w)? * setup.receiver.area
    } else {
        let towards_prev = (cam[t - 2].p - y.p).normalize();
        bsdf(&surfaces[y.surface as usize], y.n, -w, towards_prev) * y.n.dot(w).abs()
    };
    let c = x.beta * f_x * f_y * y.beta / r2;
    (c > 0.0).then_some((c, x.len + r + y.len))
}

fn trace_ray(setup: &PulseSetup, rng: &mut Rng, acc: &mut Accum, b: &mut Buffers) {
    let (s_cap, t_cap) = setup.caps();
    let (laser, recv) = (&setup.laser, &setup.receiver);
    let scene = setup.scene;

    // The light sub-path starts at one light, the sun with its selection probability q, else
    // the laser; its contributions are divided by q, which the light end point keeps as its
    // pdf_fwd for the MIS weights. A receiver vertex, by contrast, is connected to every light
    // (s = 1 strategies need no choice), which keeps the laser's variance what it is without
    // the sun.
    b.light.clear();
    let q_sun = setup.sun.map_or(0.0, |s| s.probability);
    let sun = setup.sun.filter(|_| rng.uniform() < q_sun);
    if let Some(sun) = sun {
        let x0 = sun.sample_origin(rng.uniform(), rng.uniform());
        b.light
            .push(Vertex::endpoint(Kind::Sun, x0, sun.dir, q_sun));
        if s_cap > 1 {
            let beta = sun.band_irradiance * sun.disk_area() / q_sun;
            walk(
                setup,
                &mut b.light,
                sun.dir,
                beta,
                s_cap,
                true,
                rng,
                acc,
                &mut b.scratch,
            );
        }
    } else {
        let q_laser = 1.0 - q_sun;
        b.light.push(Vertex::endpoint(
            Kind::Laser,
            laser.position,
            laser.frame.w,
            q_laser,
        ));
        if s_cap > 1 {
            let (dir, _) = laser.sample(rng.uniform(), rng.uniform());
            walk(
                setup,
                &mut b.light,
                dir,
                laser.energy / q_laser,
                s_cap,
                true,
                rng,
                acc,
                &mut b.scratch,
            );
        }
    }

    b.cam.clear();
    if t_cap > 1 {
        let q0 = recv.sample_point(rng.uniform(), rng.uniform());
        let (dir, w) = recv.sample_direction(rng.uniform(), rng.uniform());
        b.cam.push(Vertex::endpoint(
            Kind::Aperture,
            q0,
            recv.frame.w,
            1.0 / recv.area,
        ));
        walk(
            setup,
            &mut b.cam,
            dir,
            recv.area * w,
            t_cap,
            false,
            rng,
            acc,
            &mut b.scratch,
        );
    }

    let max_order = setup.max_order as usize;
    let mut q = [Vertex::endpoint(
        Kind::Aperture,
        recv.center,
        recv.frame.w,
        1.0 / recv.area,
    )];
    // s = 1: every receiver vertex to the laser, and to the sun when there is one
    let laser_end = Vertex::endpoint(Kind::Laser, laser.position, laser.frame.w, 1.0 - q_sun);
    for t in 2..=b.cam.len().min(max_order + 1) {
        let cam = &b.cam[..t];
        let y = &cam[t - 1];
        let laser_light = [laser_end];
        if let Some((c, length)) = contribution(setup, &laser_light, cam) {
            if !scene.occluded(laser_end.p, y.p, FacetId::NONE, y.facet) {
                let w = mis_weight(setup, &laser_light, cam, &mut b.scratch);
                acc.add(length, c * w, t - 1, class_of(setup, y));
            }
        }
        if let Some(sun) = setup.sun {
            // the sun's point for this connection is the one up-sun of the vertex
            let sun_light = [Vertex::endpoint(
                Kind::Sun,
                y.p - sun.dir * (4.0 * sun.radius),
                sun.dir,
                q_sun,
            )];
            if let Some((c, _)) = contribution(setup, &sun_light, cam) {
                if scene
                    .intersect(y.p, -sun.dir, f64::INFINITY, y.facet)
                    .is_none()
                {
                    let w = mis_weight(setup, &sun_light, cam, &mut b.scratch);
                    acc.add_solar(c * w);
                }
            }
        }
    }
    // s ≥ 2: the light sub-path's vertices to a point drawn on the aperture (t = 1) and to the
    // receiver sub-path's vertices (t ≥ 2)
    let is_sun = sun.is_some();
    let t_max = if t_cap > 1 { b.cam.len() } else { 1 };
    for s in 2..=b.light.len() {
        for t in 1..=t_max {
            let order = s + t - 2;
            if order > max_order {
                continue;
            }
            let light = &b.light[..s];
            let cam: &[Vertex] = if t == 1 {
                q[0].p = recv.sample_point(rng.uniform(), rng.uniform());
                &q
            } else {
                &b.cam[..t]
            };
            let Some((c, length)) = contribution(setup, light, cam) else {
                continue;
            };
            let (x, y) = (&light[s - 1], &cam[t - 1]);
            if scene.occluded(x.p, y.p, x.facet, y.facet) {
                continue;
            }
            let w = mis_weight(setup, light, cam, &mut b.scratch);
            if is_sun {
                acc.add_solar(c * w);
            } else {
                acc.add(length, c * w, order, class_of(setup, &light[1]));
            }
        }
    }
}

/// Traces `rays` samples of one pulse, in chunks of [`CHUNK_RAYS`] run in parallel; each
/// chunk has its own random stream and the chunks are merged in order, so the result is the
/// same whatever the number of threads.
pub fn simulate_pulse(setup: &PulseSetup, rays: u64) -> Tally {
    let chunks = rays.div_ceil(CHUNK_RAYS);
    let parts: Vec<Tally> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(setup.seed, setup.pulse_id, c);
            let mut acc = Accum::new(setup);
            let mut bufs = Buffers {
                light: Vec::new(),
                cam: Vec::new(),
                scratch: Vec::new(),
            };
            for _ in 0..CHUNK_RAYS.min(rays - c * CHUNK_RAYS) {
                trace_ray(setup, &mut rng, &mut acc, &mut bufs);
                acc.end_ray();
            }
            acc.tally
        })
        .collect();
    let mut total = Tally::new(setup.gate.bins, setup.sub_bins, setup.max_order);
    for p in &parts {
        total.merge(p);
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::Instrument;

    fn setup_scene(name: &str) -> Scene {
        let dir = std::env::temp_dir().join(format!("lidarsim-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.yaml");
        std::fs::write(
            &path,
            "name: s\nmaterials:\n  a: { reflectance: 0.4, back_reflectance: 0.2, transmittance: 0.3 }\n  b: { reflectance: 0.7 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [1, 1]], material: a }\n  - plane: { z: 1, extent: [[0, 0], [1, 1]], material: b }\n",
        )
        .unwrap();
        Scene::load(&path, 1064.0).unwrap()
    }

    fn instrument() -> Instrument {
        serde_yaml::from_str(
            "pulse_energy_j: 1\npulse_fwhm_ns: 0\nfootprint_half_angle_mrad: 600\nfov_half_angle_mrad: 700\nreceiver_area_m2: 0.01",
        )
        .unwrap()
    }

    fn setup<'a>(scene: &'a Scene, method: Method, heuristic: MisHeuristic) -> PulseSetup<'a> {
        let inst = instrument();
        let pos = DVec3::new(0.0, 0.0, 10.0);
        PulseSetup {
            scene,
            laser: Laser::new(&inst, pos, -DVec3::Z),
            receiver: Receiver::new(&inst, pos, -DVec3::Z),
            gate: Gate {
                t0: 0.0,
                dt: 1e-9,
                bins: 10,
            },
            sub_bins: 1,
            method,
            heuristic,
            sun: None,
            max_order: 12,
            seed: 1,
            pulse_id: 0,
        }
    }

    /// A random full path: laser, `order` surface vertices, a point of the aperture. The first
    /// and last surface vertices lie inside the footprint and the field of view.
    fn random_path(st: &PulseSetup, rng: &mut Rng, order: usize) -> Vec<Vertex> {
        let mut v = vec![Vertex::endpoint(
            Kind::Laser,
            st.laser.position,
            -DVec3::Z,
            1.0,
        )];
        for i in 0..order {
            let near_axis = i == 0 || i == order - 1;
            let spread = if near_axis { 2.0 } else { 8.0 };
            let p = DVec3::new(
                (rng.uniform() - 0.5) * spread,
                (rng.uniform() - 0.5) * spread,
                rng.uniform() * 4.0,
            );
            let n = DVec3::new(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            )
            .normalize();
            // material 0 reflects on both sides (differently) and transmits: every path is
            // possible, so every strategy has a density
            let mut s = Vertex::endpoint(Kind::Surface, p, n, 0.0);
            s.surface = 0;
            v.push(s);
        }
        let q = st.receiver.sample_point(rng.uniform(), rng.uniform());
        v.push(Vertex::endpoint(
            Kind::Aperture,
            q,
            -DVec3::Z,
            1.0 / st.receiver.area,
        ));
        v
    }

    fn sub_path(st: &PulseSetup, vs: impl Iterator<Item = Vertex>) -> Vec<Vertex> {
        let mut out = Vec::new();
        for v in vs {
            out.push(v);
            link(st, &mut out);
        }
        out
    }

    #[test]
    fn mis_weights_of_a_path_sum_to_one() {
        let scene = setup_scene("mis-sum");
        let mut rng = Rng::new(5, 6, 7);
        let mut scratch = Vec::new();
        for (method, heuristic) in [
            (Method::Bdpt, MisHeuristic::Power),
            (Method::Bdpt, MisHeuristic::Balance),
            (Method::Forward, MisHeuristic::Power),
            (Method::Backward, MisHeuristic::Power),
        ] {
            let st = setup(&scene, method, heuristic);
            let (s_cap, t_cap) = st.caps();
            for trial in 0..400 {
                let order = 1 + trial % 8;
                let mut x = random_path(&st, &mut rng, order);
                // half the paths belong to a light chosen for sub-paths with probability 0.3
                if trial % 2 == 1 {
                    x[0].pdf_fwd = 0.3;
                }
                let nv = x.len();
                let mut sum = 0.0;
                let mut strategies = 0;
                for s in 1..=nv {
                    let t = nv - s;
                    if s > s_cap || t > t_cap {
                        continue;
                    }
                    let light = sub_path(&st, x[..s].iter().copied());
                    let cam = sub_path(&st, x[s..].iter().rev().copied());
                    let w = mis_weight(&st, &light, &cam, &mut scratch);
                    assert!(
                        (0.0..=1.0 + 1e-12).contains(&w),
                        "{method:?} s={s} t={t}: weight {w}"
                    );
                    sum += w;
                    strategies += 1;
                }
                assert!(strategies >= 1);
                assert!(
                    (sum - 1.0).abs() < 1e-9,
                    "{method:?} {heuristic:?} order {order}: weights sum to {sum}"
                );
            }
        }
    }

    #[test]
    fn a_wrong_density_breaks_the_sum() {
        // the check above can fail: perturb one stored density and the sum leaves 1
        let scene = setup_scene("mis-wrong");
        let st = setup(&scene, Method::Bdpt, MisHeuristic::Power);
        let mut rng = Rng::new(1, 2, 3);
        let mut scratch = Vec::new();
        let x = random_path(&st, &mut rng, 4);
        let nv = x.len();
        let mut sum = 0.0;
        for s in 1..=nv {
            let mut light = sub_path(&st, x[..s].iter().copied());
            let cam = sub_path(&st, x[s..].iter().rev().copied());
            if s >= 4 {
                light[1].pdf_rev *= 100.0;
            }
            sum += mis_weight(&st, &light, &cam, &mut scratch);
        }
        assert!((sum - 1.0).abs() > 1e-6, "{sum}");
    }
}
