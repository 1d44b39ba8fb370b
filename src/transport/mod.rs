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

pub mod atmosphere;
pub mod bands;
mod bdpt;
mod bsdf;
mod mis;
pub mod order_tail;
mod tally;
#[cfg(test)]
mod tests;

pub use bsdf::{bsdf, bsdf_pdf};
pub use mis::{link, mis_weight};
pub use tally::Tally;

use bdpt::{trace_ray, Buffers, FirstDims};
use tally::Accum;

use crate::campaign::{Method, MisHeuristic, ReceiverDepth, Sampler};
use crate::rng::{Rng, Sobol2};
use crate::scene::{FacetId, Scene};
use crate::sensor::{Gate, Laser, Receiver, SunSource};
use glam::DVec3;
use std::sync::Mutex;

/// Rays per random stream and per unit of parallel work. Small enough that one pulse of a few
/// thousand rays (the GEDI ladder's 2000, the orchard's 20000) is split evenly between the
/// threads: cut into a few large tasks, the thread that finishes its share first sits idle
/// for most of a task. A chunk's cost beyond its rays is one tally to fill and merge.
pub const CHUNK_RAYS: u64 = 256;

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
    /// Sub-bins kept on each side of the gate for energy that arrives just outside it, whose
    /// pulse tails the convolution spreads into the gate's first or last bins (0: none kept, a
    /// waveform with no pulse convolution).
    pub edge_sub_bins: usize,
    pub method: Method,
    pub heuristic: MisHeuristic,
    pub sampler: Sampler,
    /// The receiver sub-path's vertices that join the laser's light (bdpt only).
    pub receiver_depth: ReceiverDepth,
    /// The sun, when the campaign has one: its paths share the receiver sub-paths.
    pub sun: Option<SunSource>,
    /// The atmosphere at the campaign's wavelength; `None` is vacuum and costs nothing.
    pub atmosphere: Option<&'a atmosphere::Atmosphere>,
    /// Several bands in one pass; `None` for one band, which then costs nothing.
    pub bands: Option<&'a bands::Bands>,
    pub max_order: u32,
    pub seed: u64,
    pub pulse_id: u64,
}

impl PulseSetup<'_> {
    /// Whether light sub-paths that reach their cap still look for the aperture (t = 0):
    /// over a smooth water surface, whose specular vertices no strategy connects to, a path
    /// of the highest order through it has no other strategy. Elsewhere it would cost a query
    /// per path for a strategy the others already cover.
    pub fn crossing_after_cap(&self) -> bool {
        self.caps().0 > 1 && self.scene.water.as_ref().is_some_and(|w| w.mss == 0.0)
    }

    /// Whether both sub-paths extend past their end points (bdpt). Only then does a strategy
    /// read the densities that a surface vertex keeps ([`link`]): with one sub-path capped,
    /// a path has at most two strategies, whose weight needs only the densities of the
    /// junction, made afresh for each connection (and, for an aperture crossing, that
    /// point's own density), so they are not made for every vertex.
    pub fn both_subpaths(&self) -> bool {
        let (s, t) = self.caps();
        s > 1 && t > 1
    }

    /// Most vertices the light and the receiver sub-paths may have, end points included.
    pub fn caps(&self) -> (usize, usize) {
        let full = self.max_order as usize + 1;
        match self.method {
            Method::Forward => (full, 1),
            Method::Backward => (1, full),
            // auto is resolved to one of the others before any pulse is traced
            Method::Bdpt | Method::Auto => (full, full),
        }
    }

    /// [`PulseSetup::caps`] for the paths of one light (`Laser` or `Sun`): the laser's light
    /// joins the receiver sub-path's first surface at most with `receiver_depth: first`.
    /// The paths of the two lights are apart, so each light's strategies are weighed among
    /// themselves.
    pub fn caps_for(&self, light: VertexKind) -> (usize, usize) {
        let (s, t) = self.caps();
        if light == VertexKind::Laser {
            (s, t.min(self.laser_receiver_cap()))
        } else {
            (s, t)
        }
    }

    /// Most receiver sub-path vertices (aperture included) that join the laser's light.
    fn laser_receiver_cap(&self) -> usize {
        let bdpt = matches!(self.method, Method::Bdpt | Method::Auto);
        if bdpt && self.receiver_depth == ReceiverDepth::First {
            2
        } else {
            usize::MAX
        }
    }

    /// Most vertices the receiver sub-path is walked to: every light's deepest.
    pub fn receiver_walk_cap(&self) -> usize {
        let (_, t) = self.caps();
        match self.sun {
            Some(_) => t,
            None => t.min(self.laser_receiver_cap()),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexKind {
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
    pub kind: VertexKind,
    pub p: DVec3,
    /// Front normal of a facet, or the sensor axis for the laser and the aperture.
    pub n: DVec3,
    pub surface: u32,
    pub facet: FacetId,
    /// Throughput of the sub-path up to this vertex over its sampling densities: energy (J)
    /// on a light sub-path, importance (m² sr) on a receiver sub-path.
    pub beta: f64,
    /// Length of the sub-path from its start to this vertex, as the time light takes over it
    /// in the first band (in vacuum metres: a length in water counts n_g times), m.
    pub len: f64,
    /// The geometric length of it in the water column, m: where the bands' group indexes part
    /// their times.
    pub wlen: f64,
    /// Area density of this vertex as sampled by its own sub-path.
    pub pdf_fwd: f64,
    /// Area density of this vertex if the other sub-path had sampled it.
    pub pdf_rev: f64,
    /// A specular scattering (a smooth water surface): no strategy connects to it, and the
    /// densities it makes are Dirac's (docs/physics.md, "Water").
    pub delta: bool,
}

impl Vertex {
    pub fn endpoint(kind: VertexKind, p: DVec3, axis: DVec3, pdf_fwd: f64) -> Vertex {
        Vertex {
            kind,
            p,
            n: axis,
            surface: u32::MAX,
            facet: FacetId::NONE,
            beta: 1.0,
            len: 0.0,
            wlen: 0.0,
            pdf_fwd,
            pdf_rev: 0.0,
            delta: false,
        }
    }
}

/// What a worker reuses from one pulse to the next: the tally and the sub-paths' buffers, so
/// that a pulse of few rays allocates nothing but its output.
#[derive(Default)]
pub struct Scratch {
    acc: Option<Accum>,
    bufs: Buffers,
}

/// Traces `rays` samples of one pulse, in chunks of [`CHUNK_RAYS`] run in parallel; each
/// chunk has its own random stream and the chunks are added over a tree of fixed shape
/// ([`sum_chunks`]), so the result is the same whatever the number of threads.
pub fn simulate_pulse(setup: &PulseSetup, rays: u64) -> Tally {
    simulate_pulse_in(setup, rays, &mut Scratch::default()).clone()
}

impl Scratch {
    /// Band `b`'s tally of the last pulse simulated in this scratch (0: the first band, the
    /// one [`simulate_pulse_in`] returns).
    pub fn band(&self, b: usize) -> &Tally {
        self.acc
            .as_ref()
            .expect("a pulse was simulated in this scratch")
            .band(b)
    }
}

/// The sum of `chunks` of one pulse traced by `trace` (see [`simulate_pulse_in`]), with the
/// buffers that traced its last chunk. The tallies and buffers of chunks already added wait in
/// `pool` for the next chunk.
fn sum_chunks<F>(
    chunks: std::ops::Range<u64>,
    trace: &F,
    setup: &PulseSetup,
    pool: &Mutex<Vec<(Accum, Buffers)>>,
) -> (Accum, Buffers)
where
    F: Fn(u64, &mut Accum, &mut Buffers) + Sync,
{
    let n = chunks.end - chunks.start;
    // a host that dropped the pulse (see `interrupt::abandon`) gets its chunks left untraced
    if n <= 1 || crate::interrupt::abandoning() {
        let reused = pool.lock().ok().and_then(|mut p| p.pop());
        let (mut acc, mut bufs) = reused.unwrap_or_else(|| (Accum::new(setup), Buffers::default()));
        acc.reset(setup);
        if n == 1 && !crate::interrupt::abandoning() {
            trace(chunks.start, &mut acc, &mut bufs);
        }
        return (acc, bufs);
    }
    let mid = chunks.start + n / 2;
    let (mut a, b) = rayon::join(
        || sum_chunks(chunks.start..mid, trace, setup, pool),
        || sum_chunks(mid..chunks.end, trace, setup, pool),
    );
    a.0.merge(&b.0);
    if let Ok(mut p) = pool.lock() {
        p.push(b);
    }
    a
}

/// Traces chunk `c` of a pulse of `rays` rays into `acc`: rays c·[`CHUNK_RAYS`] on, on the
/// chunk's own random stream.
fn trace_chunk(
    setup: &PulseSetup,
    sobol: Option<&Sobol2>,
    rays: u64,
    c: u64,
    acc: &mut Accum,
    bufs: &mut Buffers,
) {
    let chunk = CHUNK_RAYS;
    let mut rng = Rng::new(setup.seed, setup.pulse_id, c);
    for k in 0..chunk.min(rays - c * chunk) {
        let first = FirstDims::of(sobol, c * chunk + k);
        trace_ray(setup, &first, &mut rng, acc, bufs);
        acc.end_ray();
    }
    if setup.bands.is_some() {
        acc.add_underflows(&bands::take_underflows());
    }
}

/// The rays [`simulate_pulse`] traces (the same draws), each chunk's orders kept apart, for
/// each band (the first band's first): batches of independent rays, whose spread says how far
/// a figure made of several orders may be off ([`order_tail`]).
pub fn simulate_pulse_batches(setup: &PulseSetup, rays: u64) -> Vec<Vec<order_tail::Batch>> {
    let sobol = (setup.sampler == Sampler::Sobol).then(|| Sobol2::new(setup.seed, setup.pulse_id));
    let bands = setup.bands.map_or(1, |b| b.count);
    use rayon::prelude::*;
    let chunks: Vec<Vec<order_tail::Batch>> = (0..rays.div_ceil(CHUNK_RAYS))
        .into_par_iter()
        .map(|c| {
            let mut acc = Accum::new(setup);
            acc.reset(setup);
            trace_chunk(
                setup,
                sobol.as_ref(),
                rays,
                c,
                &mut acc,
                &mut Buffers::default(),
            );
            (0..bands)
                .map(|b| {
                    let t = acc.band(b);
                    order_tail::Batch {
                        order_sum: t.order_sum.clone(),
                        total_sq: t.total_sq,
                        rays: t.rays,
                    }
                })
                .collect()
        })
        .collect();
    (0..bands)
        .map(|b| chunks.iter().map(|c| c[b].clone()).collect())
        .collect()
}

/// [`simulate_pulse`] in a worker's scratch: the tally returned (the first band's) lives
/// there until its next pulse, with the other bands' ([`Scratch::band`]).
pub fn simulate_pulse_in<'s>(setup: &PulseSetup, rays: u64, scratch: &'s mut Scratch) -> &'s Tally {
    let chunk = CHUNK_RAYS;
    let chunks = rays.div_ceil(chunk);
    let acc = scratch.acc.get_or_insert_with(|| Accum::new(setup));
    acc.reset(setup);
    let sobol = (setup.sampler == Sampler::Sobol).then(|| Sobol2::new(setup.seed, setup.pulse_id));
    let trace = |c: u64, acc: &mut Accum, bufs: &mut Buffers| {
        trace_chunk(setup, sobol.as_ref(), rays, c, acc, bufs)
    };
    if chunks == 1 {
        // the common case of a campaign pulse: its one chunk is the total (adding it to
        // zeros would change no bit: every tallied value is ≥ 0)
        trace(0, acc, &mut scratch.bufs);
        return &acc.tally;
    }
    // the chunks summed over a tree of fixed shape, each half traced in parallel and the
    // halves added: the additions' order, so every bit, is the same on any number of threads,
    // no thread waits at a barrier between batches of chunks, and the tallies alive are a
    // tree's depth per thread (a tally per chunk of 10^19 rays would ask for 4·10^18 bytes)
    if chunks > 1 {
        let pool = Mutex::new(Vec::new());
        let (total, _) = sum_chunks(0..chunks, &trace, setup, &pool);
        acc.merge(&total);
    }
    &acc.tally
}
