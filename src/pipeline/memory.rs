//! What a run will hold in memory, bounded before it starts, and the refusal of a run that
//! cannot fit: an allocation that fails aborts the process with no word of which key asked
//! for it, and the products stage's (a DSM grid of 10⁻⁷ m cells) only after the simulation.

use crate::campaign::Loaded;
use crate::error::Result;
use crate::plan::Plan;
use crate::scene::Scene;

/// What a run holds beyond the scene, bytes, by what sizes it. Every stage works a part at a
/// time, so none of it depends on the number of pulses.
#[derive(Clone, Copy, Debug)]
pub struct Bound {
    /// Bins of the first pulse's gate.
    pub gate_bins: usize,
    /// The simulate stage: the part in the making, the one queued and the one being encoded,
    /// the Parquet writer's own buffers, and each worker's tally of the gate's sub-bins.
    pub simulate: f64,
    /// The products stage besides its DSM: the part the writers take, the part being
    /// decomposed and the next read ahead, a chunk of points, the distance histogram and the
    /// top view's sample.
    pub products: f64,
    /// The DSM grids over the scene's extent.
    pub dsm: f64,
    /// A row group of pulses or photons being written.
    pub writing: f64,
}

impl Bound {
    pub fn total(&self) -> f64 {
        self.simulate.max(self.products + self.dsm) + self.writing
    }
}

/// [`Bound`] of a run of `loaded` over `scene`, on the current thread pool.
pub fn bound(loaded: &Loaded, scene: &Scene, plan: &Plan) -> Bound {
    use crate::waveform::file::{gate_bins, pulse_bytes, Parts};
    let gate = gate_bins(loaded, scene, plan);
    // a part holds no more pulses than the run has: a one-pulse campaign's part is one pulse,
    // not the thousand a part of a survey may hold
    let pulses = Parts::of_run(loaded, scene, plan)
        .size()
        .min(plan.len().max(1));
    let part = pulses as f64 * pulse_bytes(loaded, gate);
    let bins = gate as f64;
    let threads = rayon::current_num_threads() as f64;
    // a part in the making, the one queued, and the one being encoded (its table and bytes),
    // with a part's worth for the allocator's slack, and the Parquet writer's own buffers and
    // compressors, measured at about 40 MB whatever the part
    let simulate = 5.0 * part + 40e6 + threads * bins * 64.0 * 8.0;
    let (lo, hi) = scene.bounds();
    let dsm_cells = match crate::products::stage::wanted(loaded).dsm {
        Some(res) => ((hi.x - lo.x) / res + 2.0) * ((hi.y - lo.y) / res + 2.0),
        None => 0.0,
    };
    let points = crate::products::points::spill::CHUNK as f64 * 2.0 * 80.0;
    let top_view = crate::products::figures::TOP_VIEW_MAX_POINTS as f64 * 32.0 * 3.0;
    Bound {
        gate_bins: gate,
        simulate,
        // three parts in hand, with a part's worth for the allocator's slack
        products: 4.0 * part + points + 4e6 + top_view,
        dsm: dsm_cells * 48.0,
        writing: crate::parquet_io::ROW_GROUP_ROWS as f64 * 2.0 * 80.0,
    }
}

/// The machine's memory, bytes (`MemTotal` of /proc/meminfo); None where it cannot be read.
fn machine_bytes() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// An error at the key that sizes a run whose [`Bound`] exceeds the machine's memory: the
/// DSM's cell size when its grids are most of it, else the gate's bins. The bound is generous
/// (several times a run's measured peak), so the run it refuses is one that could not have
/// finished, not one that might.
pub fn fits(loaded: &Loaded, scene: &Scene, plan: &Plan) -> Result<()> {
    let Some(machine) = machine_bytes() else {
        return Ok(());
    };
    let b = bound(loaded, scene, plan);
    let need = b.total() + scene.stats().memory_bytes as f64;
    if need.is_finite() && need <= machine {
        return Ok(());
    }
    let c = &loaded.campaign;
    let gb = |x: f64| {
        let g = x / 1e9;
        if g < 1e4 {
            format!("{g:.1} GB")
        } else {
            format!("{g:.1e} GB")
        }
    };
    let needs = format!(
        "the run would hold about {} in memory, more than this machine's {}",
        gb(need),
        gb(machine)
    );
    Err(if b.dsm >= b.simulate.max(b.products) {
        let res = crate::products::stage::wanted(loaded)
            .dsm
            .unwrap_or(f64::NAN);
        loaded.doc.error(
            "products.dsm.resolution_m",
            format!("{needs} (DSM grids of {res} m cells over the scene): use larger cells"),
        )
    } else if let Some(g) = &c.instrument.range_gate {
        loaded.doc.error(
            "instrument.range_gate.bins",
            format!(
                "{needs} (gates of {} bins): use fewer bins or wider ones (instrument.bin_ns)",
                g.bins
            ),
        )
    } else {
        // the gate spans the scene's ranges and the pulse's ±4σ on either side, in bins: a
        // bin far finer than the pulse, or a pulse far longer than any scene, sizes it
        let sigma_ns = crate::sensor::gate_sigma_s(&c.instrument) * 1e9;
        // a pulse longer than any LiDAR's (100 µs) is what sizes it: name the pulse's key
        let key = if c.instrument.pulse_fwhm_ns > 1e5 {
            "instrument.pulse_fwhm_ns"
        } else {
            "instrument.bin_ns"
        };
        loaded.doc.error(
            key,
            format!(
                "{needs} (gates of {} bins of {} ns over the scene's ranges and the pulse's ±4σ, \
                 σ = {sigma_ns:.3} ns): use wider bins, a shorter pulse or a range_gate",
                crate::campaign::shown(b.gate_bins as f64),
                crate::campaign::shown(c.instrument.bin_ns)
            ),
        )
    })
}
