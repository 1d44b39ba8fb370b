//! How close the transport comes to the speed of its BVH: the queries a campaign's pulses make
//! (closest hits and visibility tests), counted and timed inside the transport, then replayed
//! alone against the same scene on the same threads.

use crate::error::Result;
use crate::pipeline::simulate::simulate;
use crate::scene::{FacetId, LoggedRay, Scene};
use indicatif::ProgressBar;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// One campaign's traversal figures.
#[derive(Clone, Debug)]
pub struct TraversalRow {
    pub name: String,
    pub pulses: usize,
    pub closest: usize,
    pub any_hit: usize,
    /// Queries per second within the simulation of those pulses (everything included: the
    /// waveforms built from each pulse's tally too).
    pub inside_per_s: f64,
    /// Queries per second of the tracing alone: over the time the threads spent in the
    /// transport's pulses (their summed time over the thread count), without the waveforms
    /// built after them.
    pub tracing_per_s: f64,
    /// Replayed alone: closest-hit and any-hit queries per second.
    pub closest_per_s: f64,
    pub any_hit_per_s: f64,
    /// All queries replayed alone, per second.
    pub bare_per_s: f64,
    /// The replay's time by kind of query, as fractions: closest hits that leave a sensor or
    /// the sun (a path's first segment, what tracing a pulse's rays together would share),
    /// closest hits that leave a surface (scattering), and visibility tests.
    pub shares: [f64; 3],
}

/// Simulates up to `max_pulses` of the campaign at `path` (spread over its plan) twice, once
/// timed and once logging the scene's queries, then replays the log.
pub fn measure(name: &str, path: &Path, max_pulses: usize) -> Result<TraversalRow> {
    let loaded = crate::plan::read_campaign(path)?;
    let mut scene = Scene::load_bands(&loaded.scene_path, loaded.campaign.wavelength_nm.all())?;
    let plan = crate::plan::Plan::new(&loaded.campaign)?;
    let pulses = plan.spread(max_pulses, loaded.campaign.seed);
    // the method the campaign's run would use (`auto`'s pick)
    let chosen = crate::pipeline::with_method_chosen(&loaded, &scene, &plan);
    let loaded = chosen.as_ref().unwrap_or(&loaded);
    let hidden = ProgressBar::hidden();
    let t = Instant::now();
    let (_, traced_s) = simulate(loaded, &scene, &pulses, &hidden, true);
    let inside_s = t.elapsed().as_secs_f64();
    let tracing_s = traced_s.iter().sum::<f64>() / rayon::current_num_threads() as f64;
    scene.start_ray_log();
    let _ = simulate(loaded, &scene, &pulses, &hidden, true);
    let log = scene.take_ray_log();
    let (first, scattered): (Vec<LoggedRay>, Vec<LoggedRay>) = log
        .iter()
        .filter(|r| matches!(r, LoggedRay::Closest { .. }))
        .partition(|r| matches!(r, LoggedRay::Closest { skip, .. } if *skip == FacetId::NONE));
    let any: Vec<LoggedRay> = log
        .iter()
        .filter(|r| matches!(r, LoggedRay::Occluded { .. }))
        .copied()
        .collect();
    let replay = |rays: &[LoggedRay]| {
        let t = Instant::now();
        let hits: usize = rays
            .par_iter()
            .map(|r| match *r {
                LoggedRay::Closest {
                    origin,
                    dir,
                    t_max,
                    skip,
                } => scene.intersect(origin, dir, t_max, skip).is_some() as usize,
                LoggedRay::Occluded {
                    a,
                    b,
                    skip_a,
                    skip_b,
                } => scene.occluded(a, b, skip_a, skip_b) as usize,
            })
            .sum();
        std::hint::black_box(hits);
        t.elapsed().as_secs_f64().max(1e-9)
    };
    let (tf, ts, ta) = (replay(&first), replay(&scattered), replay(&any));
    let (tc, closest) = (tf + ts, first.len() + scattered.len());
    Ok(TraversalRow {
        name: name.to_string(),
        pulses: pulses.len(),
        closest,
        any_hit: any.len(),
        inside_per_s: log.len() as f64 / inside_s.max(1e-9),
        tracing_per_s: log.len() as f64 / tracing_s.max(1e-9),
        closest_per_s: closest as f64 / tc,
        any_hit_per_s: any.len() as f64 / ta,
        bare_per_s: log.len() as f64 / (tc + ta),
        shares: [tf, ts, ta].map(|t| t / (tc + ta)),
    })
}

impl TraversalRow {
    /// Pulses a second the campaign would simulate were the transport's own work free: the
    /// queries a pulse makes, at the bare BVH's rate. A bound no leaner transport passes,
    /// only cheaper or fewer queries.
    pub fn bound_pulses_per_s(&self) -> f64 {
        let queries = (self.closest + self.any_hit) as f64;
        if queries > 0.0 {
            self.pulses as f64 * self.bare_per_s / queries
        } else {
            f64::INFINITY
        }
    }
}

/// The markdown table of the traversal rows.
pub fn table(rows: &[TraversalRow]) -> String {
    let mut s = String::from(
        "\n### Traversals: inside the transport against the bare BVH\n\nThe queries a campaign's pulses make (closest hits and visibility tests), counted in a timed simulation of those pulses, then replayed alone on the same threads. \"Inside the simulation\" is over the simulation's wall time, waveforms built from the tallies included; \"inside the tracing\" over the time the threads spent tracing the pulses' paths (their summed time over the thread count). \"Bound\" is the pulses a second the transport would simulate were its own work free: the queries a pulse makes at the bare BVH's rate. \"Alone, by kind\" splits the replay's time: closest hits leaving the laser, the aperture or the sun (paths' first segments, what tracing a pulse's rays together could share), closest hits leaving a surface (scattered light), and visibility tests.\n\n| campaign | pulses | closest-hit queries | any-hit queries | inside the simulation /s | inside the tracing /s | closest hit alone /s | any hit alone /s | all alone /s | simulation / alone | tracing / alone | bound, pulses/s | alone, by kind: first / scattered / visibility |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.0}% | {:.0}% | {:.0} | {:.0}% / {:.0}% / {:.0}% |",
            r.name,
            r.pulses,
            r.closest,
            r.any_hit,
            r.inside_per_s,
            r.tracing_per_s,
            r.closest_per_s,
            r.any_hit_per_s,
            r.bare_per_s,
            100.0 * r.inside_per_s / r.bare_per_s,
            100.0 * r.tracing_per_s / r.bare_per_s,
            r.bound_pulses_per_s(),
            100.0 * r.shares[0],
            100.0 * r.shares[1],
            100.0 * r.shares[2]
        );
    }
    s
}
