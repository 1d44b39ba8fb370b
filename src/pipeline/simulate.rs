//! The simulate stage: pulses in [`Parts`], each part written when complete,
//! with per-pulse timing beside it.

use crate::campaign::{Loaded, MaxOrder, Method, ReceiverDepth, SunSelection, SunShare};
use crate::error::Result;
use crate::fsutil::{Committer, Pending};
use crate::plan::{Plan, Pulse};
use crate::progress::{log, progress};
use crate::scene::Scene;
use crate::transport::order_tail::{pulse_se, tail_bounds, Batch};
use crate::transport::{simulate_pulse, simulate_pulse_batches, PulseSetup, Scratch};
use crate::waveform::file::{part_name, waveforms_pending, Parts};
use crate::waveform::pulse::PulseSimulator;
use crate::waveform::Waveform;
use indicatif::ProgressBar;
use rayon::prelude::*;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

/// Simulates the given parts, each written when complete. Pulses within a part and each
/// pulse's ray chunks run in parallel, and a finished part is encoded and written on a thread
/// of its own while the workers go on with the next one: the queue holds one finished part
/// at most, so memory stays at about two parts. A signal (see [`crate::interrupt`]) stops it
/// before the next part, the parts in flight written. Returns (rays traced, parts written,
/// the signal that stopped it).
///
/// Long because the loop simulates part k + 1 while part k is written (one rayon join), and
/// logs progress and the stage's figures; the pulses themselves are [`simulate`]'s.
pub(super) fn simulate_parts(
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
    parts: Parts,
    todo: &[usize],
    out: &Path,
    fingerprint: &str,
) -> Result<(u64, usize, Option<i32>)> {
    let total: usize = todo.iter().map(|&k| parts.range(k).len()).sum();
    let bar = progress(total as u64, "simulating");
    let clock = crate::progress::StageClock::start();
    let mut rays = 0u64;
    let mut non_finite = 0u64;
    let mut done_pulses = 0usize;
    let terminal = crate::progress::interactive();
    let mut last_log = 0.0;
    let mut written = 0usize;
    let mut stopped = None;
    let bands = loaded.campaign.wavelength_nm.all().len();
    let mut underflows = vec![0u64; bands];
    // Part k is written while part k + 1 is simulated, as two halves of one rayon join: the
    // same threads do both, so no core waits for a writer (a writer thread beside the workers
    // would leave the cores idle whenever encoding is slower than simulating), and at most
    // two parts are in memory.
    // ... and synced and renamed into place on a thread of its own, which waits for the disk
    let committer = Committer::default();
    let write = |(n, k, waveforms, secs): (usize, usize, Vec<Waveform>, Vec<f64>)| -> Result<()> {
        let [part, sidecar] = waveforms_pending(&out.join(part_name(k)), &waveforms, fingerprint)?;
        let stats = pulse_stats_pending(
            &out.join(stats_name(k)),
            waveforms.iter().step_by(bands),
            &secs,
        )?;
        drop(waveforms);
        committer.commit(vec![part, sidecar, stats])?;
        crate::progress::release_after_part(n);
        Ok(())
    };
    let mut pending = None;
    for (i, &k) in todo.iter().enumerate() {
        if let Some(signal) = crate::interrupt::requested() {
            stopped = Some(signal);
            break;
        }
        let pulses = plan.pulses(parts.range(k));
        let (written_before, (waveforms, secs)) = rayon::join(
            || pending.take().map_or(Ok(()), write),
            // nothing is written beside the first part: its pulses are cut finely
            || simulate(loaded, scene, &pulses, &bar, i == 0),
        );
        written_before?;
        rays += waveforms
            .iter()
            .step_by(bands)
            .map(|w| w.rays as u64)
            .sum::<u64>();
        non_finite += waveforms.iter().map(|w| w.non_finite).sum::<u64>();
        for (k, w) in waveforms.iter().enumerate() {
            underflows[k % bands] += w.underflows;
        }
        done_pulses += pulses.len();
        let elapsed = clock.wall_s();
        let rate = done_pulses as f64 / elapsed;
        // a log, not a terminal: a line per tenth of the work, or per minute if slower
        let tenth = (i + 1) % todo.len().div_ceil(10).max(1) == 0;
        if !terminal && (tenth || elapsed - last_log >= 60.0) && i + 1 < todo.len() {
            last_log = elapsed;
            log(&format!(
                "simulate: part {} ({}/{} parts) simulated, {:.0} pulses/s, {:.0} s left",
                k,
                i + 1,
                todo.len(),
                rate,
                (total - done_pulses) as f64 / rate
            ));
        }
        pending = Some((i, k, waveforms, secs));
        written += 1;
    }
    // the last part simulated (or the one in hand when a signal came) is still written
    if let Some(last) = pending {
        write(last)?;
    }
    committer.finish()?;
    bar.finish_and_clear();
    if non_finite > 0 {
        log(&format!(
            "warning: {non_finite} contributions whose weight was not a finite number were left out of the waveforms: this is a bug, please report it with the campaign"
        ));
    }
    for (nm, n) in loaded.campaign.wavelength_nm.all().iter().zip(&underflows) {
        if *n > 0 {
            log(&format!(
                "warning: band {nm} nm: {n} path weights fell below the smallest double (light under about 1e-308 of the path's other bands, so none a detector could record) and count as 0"
            ));
        }
    }
    let secs = clock.wall_s();
    if done_pulses > 0 {
        // the share of the cores kept busy: what a serial step or a slow writer costs
        let busy = clock.busy(secs);
        log(&format!(
            "simulated {done_pulses} pulses, {rays} rays in {secs:.2} s ({:.1} pulses/s, {:.3e} rays/s{busy})",
            done_pulses as f64 / secs,
            rays as f64 / secs
        ));
    }
    Ok((rays, written, stopped))
}

/// Per-pulse counters beside the waveforms (of the first band): effective paths per ray and
/// time per ray. Kept out of the waveform files, which must not depend on timing.
/// Part `k`'s per-pulse timings, beside it.
pub(super) fn stats_name(k: usize) -> String {
    format!("waveforms/part-{k:05}.stats.csv")
}

/// Whether a part's timings file holds its header and one whole row per pulse: a damaged
/// one is made again with its part, as `--resume` trusts no damaged file.
pub(super) fn stats_are_whole(path: &Path, pulses: usize) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    let mut lines = text.lines();
    text.ends_with('\n')
        && lines.next() == Some("pulse_id,rays,paths_per_ray,seconds,seconds_per_ray")
        && lines.clone().count() == pulses
        && lines
            .all(|l| l.split(',').count() == 5 && l.split(',').all(|f| f.parse::<f64>().is_ok()))
}

pub(super) fn pulse_stats_pending<'w>(
    path: &Path,
    waveforms: impl Iterator<Item = &'w Waveform>,
    secs: &[f64],
) -> Result<Pending> {
    let rows = waveforms.zip(secs).map(|(w, s)| {
        vec![
            w.pulse_id.to_string(),
            w.rays.to_string(),
            w.paths_per_ray.to_string(),
            format!("{s:.6}"),
            format!("{:.4e}", s / w.rays.max(1) as f64),
        ]
    });
    let header = [
        "pulse_id",
        "rays",
        "paths_per_ray",
        "seconds",
        "seconds_per_ray",
    ];
    crate::fsutil::csv_pending(path, &header, rows)
}

/// Tasks each thread's share of pulses is cut into where they are cut finely (see
/// [`leaf_pulses`]), and otherwise.
const TASKS_PER_THREAD: usize = 64;
const TASKS_PER_THREAD_BESIDE_A_WRITE: usize = 8;

/// Pulses a task of a parallel loop over pulses holds at most: a [`TASKS_PER_THREAD`]th of a
/// thread's share with `finely`, else a [`TASKS_PER_THREAD_BESIDE_A_WRITE`]th. Rayon cuts a
/// slice into about as many pieces as threads and cuts one again only when a thread steals
/// it, so where nothing runs beside the loop a thread could sit idle at the end of a part.
/// Beside a write, threads steal once it ends: 8 tasks a thread keep the part's end busy,
/// where 64 cost measurably more CPU time (the figures are in the commit that made the choice).
fn leaf_pulses(pulses: usize, finely: bool) -> usize {
    let tasks = if finely {
        TASKS_PER_THREAD
    } else {
        TASKS_PER_THREAD_BESIDE_A_WRITE
    };
    (pulses / (rayon::current_num_threads() * tasks)).max(1)
}

/// Simulates pulses: pulses and each pulse's ray chunks run in parallel, the pulses cut
/// `finely` where nothing runs beside them ([`leaf_pulses`]). Returns the waveforms (one per
/// pulse and band, in pulse order then the campaign's band order) and each pulse's wall time
/// (with the threads it shared).
pub fn simulate(
    loaded: &Loaded,
    scene: &Scene,
    pulses: &[Pulse],
    bar: &ProgressBar,
    finely: bool,
) -> (Vec<Waveform>, Vec<f64>) {
    let c = &loaded.campaign;
    let sim = PulseSimulator::new(c, scene);
    // a scratch per thread, not per task: the tasks can be many (see `leaf_pulses`), and
    // each new scratch allocates its tally and buffers again
    let scratches: Vec<Mutex<Scratch>> = (0..rayon::current_num_threads())
        .map(|_| Mutex::default())
        .collect();
    // (the first band's row, the other bands' rows, seconds) per pulse: one band allocates
    // nothing beyond its row
    let per_pulse: Vec<(Waveform, Vec<Waveform>, f64)> = pulses
        .par_iter()
        .with_max_len(leaf_pulses(pulses.len(), finely))
        .map(|p| {
            // a thread that takes another pulse while this one waits for its chunks (a
            // pulse of many rays traces them in parallel) finds its scratch in use
            let mut own = Scratch::default();
            let mut held = rayon::current_thread_index()
                .and_then(|k| scratches.get(k))
                .and_then(|m| m.try_lock().ok());
            let scratch = held.as_deref_mut().unwrap_or(&mut own);
            let t = Instant::now();
            let (first, others) = sim.simulate(p, scratch);
            let secs = t.elapsed().as_secs_f64();
            bar.inc(1);
            (first, others, secs)
        })
        .collect();
    let mut rows = Vec::with_capacity(per_pulse.len() * c.wavelength_nm.all().len());
    let mut secs = Vec::with_capacity(per_pulse.len());
    for (first, others, s) in per_pulse {
        rows.push(first);
        rows.extend(others);
        secs.push(s);
    }
    (rows, secs)
}

/// The pulses of a small campaign simulated in memory as a run simulates them (the `auto`
/// choices made by the same pilots), one after another in `scratch`: their waveform rows,
/// one per pulse and band. What a single pulse asked for from Python is: pulse 0 of a
/// one-pulse campaign ([`crate::plan::OnePulse`]).
pub fn simulate_in_memory(
    loaded: &Loaded,
    scene: &Scene,
    scratch: &mut Scratch,
) -> Result<Vec<Waveform>> {
    let plan = Plan::new(&loaded.campaign)?;
    // refused as a run of the same campaign is: a gate of 10^12 bins would not fit
    super::memory::fits(loaded, scene, &plan)?;
    let chosen = with_method_chosen(loaded, scene, &plan);
    let c = &chosen.as_ref().unwrap_or(loaded).campaign;
    let sim = PulseSimulator::new(c, scene);
    let mut rows = Vec::new();
    for p in plan.pulses(0..plan.len()) {
        let (first, others) = sim.simulate(&p, scratch);
        if crate::interrupt::abandoning() {
            // its chunks were left untraced: the waveforms are not the pulse's
            return Err(crate::error::Error::interrupted(
                2,
                "the pulse in memory was dropped",
            ));
        }
        rows.push(first);
        rows.extend(others);
    }
    Ok(rows)
}

/// The pilot of `simulation.method: auto`: at most 2048 rays per pulse (so the pilot's draws
/// are those of the run's first eight chunks, traced in parallel), and pulses enough for
/// [`PILOT_RAY_BUDGET`] rays per method, but no more than a tenth of the campaign's rays (so
/// at most 30 % of a small campaign's cost over the three methods, under 1 % of a survey's),
/// and at least one pulse: a few-ray campaign's score rests on hundreds of pulses, not on a
/// handful whose few rays may find no energy at all.
const PILOT_RAYS: u64 = 8 * crate::transport::CHUNK_RAYS;
const PILOT_RAY_BUDGET: u64 = 8 * PILOT_RAYS;

/// The pilot's pulses and rays per pulse ([`PILOT_RAYS`], [`PILOT_RAY_BUDGET`]); no pulses
/// for an empty plan.
fn pilot_pulses(loaded: &Loaded, plan: &Plan) -> (Vec<Pulse>, u64) {
    let rays = loaded
        .campaign
        .simulation
        .rays_per_pulse
        .clamp(2, PILOT_RAYS);
    let total = (loaded.campaign.simulation.rays_per_pulse).saturating_mul(plan.len() as u64);
    let budget = PILOT_RAY_BUDGET.min(total / 10);
    let n = (plan.len() as u64).min((budget / rays).max(1)) as usize;
    if n == 0 {
        return (Vec::new(), rays);
    }
    (plan.spread(n, loaded.campaign.seed), rays)
}

/// A pilot's score for tracing `pulses` with `method` as `loaded` asks: the relative
/// variance of their total laser energy (plus that of their solar power, with a sun) times
/// the scene queries per pulse made. Variance falls as 1/rays and queries grow with rays,
/// so the product is the cost of a given error, counted in queries (the same on any machine
/// and thread count, so the choice, and the run's bytes, are too). Infinite where no energy
/// was found.
fn pilot_score(loaded: &Loaded, scene: &Scene, pulses: &[Pulse], rays: u64, method: Method) -> f64 {
    let t = pilot_sums(loaded, scene, pulses, rays, method);
    let relative = |v: f64, x: f64| if x > 0.0 { v / (x * x) } else { f64::INFINITY };
    let mut rv = relative(t.laser_var, t.laser);
    if loaded.campaign.sun.is_some() {
        rv += relative(t.sun_var, t.sun);
    }
    rv * t.queries as f64 / pulses.len().max(1) as f64
}

/// What a pilot's pulses found, summed over them.
#[derive(Default)]
struct PilotSums {
    /// Laser energy received, J, and its variance.
    laser: f64,
    laser_var: f64,
    /// Solar power, W, and its variance.
    sun: f64,
    sun_var: f64,
    /// Solar energy over each pulse's gate, J, and its variance.
    sun_in_gate: f64,
    sun_in_gate_var: f64,
    queries: u64,
}

/// The setup a pilot that chooses between estimators traces pulse `p` with: the run's, but
/// for its random streams, which are the run's own with a seed of their own. A pilot that drew
/// what the run then draws would choose by the run's own luck: of one pulse, the selection
/// that came out high, kept (35 % above the closed form for a sun's background over 1000
/// seeds, against 0 with streams apart).
fn pilot_setup<'a>(sim: &'a PulseSimulator, p: &Pulse, method: Method) -> PulseSetup<'a> {
    let mut setup = sim.setup(p, method);
    setup.seed = crate::rng::splitmix64(setup.seed ^ PILOT_STREAMS);
    setup
}

/// Mixed into the seed of a pilot's streams ([`pilot_setup`]).
const PILOT_STREAMS: u64 = 0x9117_07a1_5eed_5a17;

/// Traces `pulses` with `method` as `loaded` asks and sums what they found.
fn pilot_sums(
    loaded: &Loaded,
    scene: &Scene,
    pulses: &[Pulse],
    rays: u64,
    method: Method,
) -> PilotSums {
    let sim = PulseSimulator::new(&loaded.campaign, scene);
    let tallies: Vec<_> = pulses
        .par_iter()
        .with_max_len(leaf_pulses(pulses.len(), true))
        .map(|p| {
            let setup = pilot_setup(&sim, p, method);
            let gate_s = setup.gate.dt * setup.gate.bins as f64;
            (simulate_pulse(&setup, rays), gate_s)
        })
        .collect();
    let mut sums = PilotSums::default();
    for (t, gate_s) in &tallies {
        sums.laser += t.total_energy();
        sums.laser_var += t.total_se().powi(2);
        let (p, se) = t.solar_power();
        sums.sun += p;
        sums.sun_var += se * se;
        sums.sun_in_gate += p * gate_s;
        sums.sun_in_gate_var += (se * gate_s).powi(2);
        sums.queries += t.queries;
    }
    sums
}

/// The most the received energy's tail past the order `max_order: auto` picks may be, as a
/// fraction of a pulse's standard error at the campaign's rays.
pub const ORDER_TAIL_FRACTION: f64 = 0.1;

/// `simulation.max_order: auto`: the lowest order k past which the received energy's whole
/// tail is below [`ORDER_TAIL_FRACTION`] of a pulse's standard error, and why.
///
/// The pilot pulses are traced with the method chosen to [`MaxOrder::AUTO_CAP`], in batches of
/// rays ([`simulate_pulse_batches`], the run's own draws). A pulse's tail past k is the sum of
/// its energies of orders k + 1 to the cap (every order, not the next alone: at albedo 0.9 the
/// tail is about ten times its first term), bounded from above as [`tail_bounds`] does: the
/// pilot's own tail, and past the orders it measures their decay extrapolated, each plus
/// standard errors from the spread of the batches. The bound, averaged over the pilot pulses,
/// is held against the root mean square of their standard errors scaled to the campaign's
/// rays (the pilot's rays over the campaign's, square rooted). Energy past the cap is not
/// traced: the cap is the default order, so `auto` never traces less than the default would
/// have without evidence.
pub fn choose_max_order(loaded: &Loaded, scene: &Scene, plan: &Plan) -> (u32, String) {
    let cap = MaxOrder::AUTO_CAP;
    let (pulses, rays) = pilot_pulses(loaded, plan);
    let n = pulses.len();
    if n == 0 {
        return (cap, format!("max_order auto: no pulses to try, {cap}"));
    }
    let mut trial = loaded.clone();
    trial.campaign.simulation.max_order = MaxOrder::Order(cap);
    let method = trial.campaign.simulation.method;
    let sim = PulseSimulator::new(&trial.campaign, scene);
    // [pulse][band][batch]
    let runs: Vec<Vec<Vec<Batch>>> = pulses
        .par_iter()
        .with_max_len(leaf_pulses(n, true))
        .map(|p| simulate_pulse_batches(&sim.setup(p, method), rays))
        .collect();
    let k_max = cap as usize;
    let scale = rays as f64 / loaded.campaign.simulation.rays_per_pulse.max(1) as f64;
    // each band bounded on its own, the order the campaign keeps the highest of theirs
    let bands = runs.first().map_or(1, Vec::len);
    let (band, k, bounds, noise) = (0..bands)
        .map(|b| {
            let batches: Vec<Vec<Batch>> = runs.iter().map(|r| r[b].clone()).collect();
            let noise_sq: f64 = batches.iter().map(|x| pulse_se(x).powi(2) * scale).sum();
            let noise = (noise_sq / n as f64).sqrt();
            let bounds = tail_bounds(&batches, k_max);
            let k = (1..=k_max)
                .find(|&k| bounds.past[k] <= ORDER_TAIL_FRACTION * noise)
                .unwrap_or(k_max);
            (b, k, bounds, noise)
        })
        .fold(None, |best: Option<(usize, usize, _, f64)>, x| match best {
            Some(b) if b.1 >= x.1 => Some(b),
            _ => Some(x),
        })
        .expect("a campaign has a band");
    let of_band = if bands > 1 {
        format!(
            " (the {} nm band, which needs the most of the {bands})",
            loaded.campaign.wavelength_nm.all()[band]
        )
    } else {
        String::new()
    };
    let (seen, total) = (bounds.seen[k], bounds.seen[0]);
    let held = if total > 0.0 {
        format!("{:.6}", 1.0 - seen / total)
    } else {
        "all (none found)".into()
    };
    let pilot = format!(
        "{n} pulse{} of {rays} rays, {} to order {cap}, standard errors from the spread of {} batches of rays",
        if n == 1 { "" } else { "s" },
        method_name(method),
        bounds.batches
    );
    let t = bounds.sigmas;
    let how = match bounds.decay {
        Some(d) if d.last < k_max => format!(
            "the pilot's tail, with the orders past {} extrapolated at {:.3} of the one before ({}), + {t:.1} SE; {pilot}",
            d.last,
            d.ratio,
            if d.from < d.last {
                format!("the decay of orders {}-{}", d.from, d.last)
            } else {
                format!("order {} over order {}", d.last + 1, d.last)
            }
        ),
        _ => format!("the pilot's tail + {t:.1} SE; {pilot}"),
    };
    let rays_asked = loaded.campaign.simulation.rays_per_pulse;
    let note = if k < k_max {
        format!(
            "max_order auto chose {k}{of_band}: past order {k} the received energy is at most {:.3e} J a pulse ({how}), below {ORDER_TAIL_FRACTION} of a pulse's standard error at {rays_asked} rays ({noise:.3e} J); orders 1 to {k} hold {held} of the energy",
            bounds.past[k]
        )
    } else {
        // past the cap no run traces: say what the pilot knows of that energy
        let beyond = bounds.past[k_max];
        let past_cap = if beyond.is_finite() {
            format!("past it, which no run traces, the decay puts at most {beyond:.3e} J a pulse")
        } else {
            "what lies past it, which no run traces, the pilot cannot bound".into()
        };
        format!(
            "max_order auto chose {k}, the cap{of_band}: the pilot ({pilot}) bounds the received energy past no lower order below {ORDER_TAIL_FRACTION} of a pulse's standard error at {rays_asked} rays ({noise:.3e} J); orders 1 to {k} hold {held} of the energy it found; {past_cap}"
        )
    };
    (k as u32, note)
}

/// The shares of samples tracing the sun that `sun.share: auto` tries, the whole first
/// (ties go to it).
const SHARES: [f64; 3] = [1.0, 0.25, 0.0625];

/// A share as the run log gives it.
fn share_name(f: f64) -> String {
    match f {
        1.0 => "1".into(),
        0.25 => "1/4".into(),
        0.0625 => "1/16".into(),
        f => format!("{f}"),
    }
}

/// `sun.share: auto`: the share of samples tracing the sun whose estimate of the photons the
/// receiver counts (the laser's and the sun's over the gate) costs least for a given error,
/// and why. Unlike the other pilots' scores, which add the two lights' relative variances,
/// this one weighs them in photons: the sun's 0.05 photons a shot on a MABEL track beside
/// the laser's 5.5 may be noisier for a much cheaper laser. Score: the simulation variance
/// of those energies over their sum (the photon noise, in joules) times the scene queries
/// per pulse, on the method's pilot pulses with everything else as chosen.
pub fn choose_sun_share(loaded: &Loaded, scene: &Scene, plan: &Plan) -> (f64, String) {
    let (pulses, rays) = pilot_pulses(loaded, plan);
    let n = pulses.len();
    let method = loaded.campaign.simulation.method;
    if n == 0 || loaded.campaign.sun.is_none() {
        return (1.0, "sun.share auto: no pulses to try, 1".into());
    }
    let hv = crate::photon_energy_j(loaded.campaign.wavelength_nm.first());
    let scores: Vec<(f64, f64)> = SHARES
        .iter()
        .map(|&f| {
            let mut trial = loaded.clone();
            if let Some(sun) = trial.campaign.sun.as_mut() {
                sun.share = Some(SunShare::Fraction(f));
            }
            let t = pilot_sums(&trial, scene, &pulses, rays, method);
            let energy = t.laser + t.sun_in_gate;
            // photons² over photons: joules² over joules, over a photon's energy
            let score = if energy > 0.0 {
                (t.laser_var + t.sun_in_gate_var) / (energy * hv) * t.queries as f64 / n as f64
            } else {
                f64::INFINITY
            };
            (f, score)
        })
        .collect();
    let table = scores
        .iter()
        .map(|&(f, x)| format!("{} {x:.3e}", share_name(f)))
        .collect::<Vec<_>>()
        .join(", ");
    match cheapest(&scores) {
        Some(f) => (
            f,
            format!(
                "sun.share auto chose {}: simulation variance of the laser's and solar photons over their photon noise x scene queries per pulse over {n} pilot pulses of {rays} rays, {} (lower is better): {table}",
                share_name(f),
                method_name(method)
            ),
        ),
        None => (
            1.0,
            format!("sun.share auto: no light found in {n} pilot pulses of {rays} rays, 1"),
        ),
    }
}

/// Each candidate's score, as the run log and report.md give them: "bdpt 1.2e0, ...".
fn score_table<T: Copy>(scores: &[(T, f64)], name: fn(T) -> &'static str) -> String {
    scores
        .iter()
        .map(|&(m, x)| format!("{} {x:.3e}", name(m)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The campaign with its sun (if any) selected as `selection`.
fn with_selection(loaded: &Loaded, selection: SunSelection) -> Loaded {
    let mut c = loaded.clone();
    if let Some(sun) = c.campaign.sun.as_mut() {
        sun.selection = Some(selection);
    }
    c
}

/// The candidate with the least finite score, the first of equals; None when none is finite.
fn cheapest<T: Copy>(scores: &[(T, f64)]) -> Option<T> {
    scores
        .iter()
        .filter(|(_, x)| x.is_finite())
        .fold(None::<(T, f64)>, |b, &(m, x)| match b {
            Some((_, y)) if y <= x => b,
            _ => Some((m, x)),
        })
        .map(|(m, _)| m)
}

/// `simulation.method: auto`: the method whose estimate costs least for a given error on
/// this campaign ([`pilot_score`]), and why. Each method traces the same pilot pulses. A
/// method that finds no energy where another does scores infinity; ties go to bdpt. A sun
/// whose selection is still `auto` is taken as `fixed` here.
/// Returns the method, a note for the run log, the resolved campaign and report.md, and the
/// method's score.
pub fn choose_method(loaded: &Loaded, scene: &Scene, plan: &Plan) -> (Method, String, Option<f64>) {
    let (pulses, rays) = pilot_pulses(loaded, plan);
    let n = pulses.len();
    if n == 0 {
        return (
            Method::Bdpt,
            "simulation.method auto: no pulses to try, bdpt".into(),
            None,
        );
    }
    let excluded = excluded_methods(loaded, scene);
    let scores: Vec<(Method, f64)> = [Method::Bdpt, Method::Forward, Method::Backward]
        .into_iter()
        .filter(|m| !excluded.iter().any(|(x, _)| x == m))
        .map(|m| (m, pilot_score(loaded, scene, &pulses, rays, m)))
        .collect();
    let table = score_table(&scores, method_name);
    match cheapest(&scores) {
        Some(m) => (
            m,
            format!(
                "simulation.method auto chose {}: relative variance x scene queries per pulse over {n} pilot pulses of {rays} rays (lower is better): {table}{}",
                method_name(m),
                exclusions(&excluded)
            ),
            score_of(&scores, m),
        ),
        None => (
            Method::Bdpt,
            format!(
                "simulation.method auto: no method found energy in {n} pilot pulses of {rays} rays, bdpt (the default)"
            ),
            None,
        ),
    }
}

/// The methods `auto` must not pick for this campaign, each with why: an estimator that
/// cannot sample a contribution the campaign asks for would leave it out of the waveform, with
/// no error to say so, however well it scores on the rest.
/// - Backward tracing over water: the paths through a smooth surface (laser, specular surface,
///   bottom, specular surface, telescope) need a connection through a specular vertex, which
///   no strategy of a receiver sub-path makes.
/// - Forward tracing with the sun in a repeated scene: the sun's light sub-paths start on a
///   disk over one copy of the landscape, and the light the receiver sees from the others is
///   only found from the receiver's side.
pub fn excluded_methods(loaded: &Loaded, scene: &Scene) -> Vec<(Method, &'static str)> {
    let mut out = Vec::new();
    if scene.water.is_some() {
        out.push((
            Method::Backward,
            "it cannot find the paths through a smooth water surface",
        ));
    }
    if scene.is_repeated() && loaded.campaign.sun.is_some() {
        out.push((
            Method::Forward,
            "it cannot sample the sun's light over a repeated scene's other copies",
        ));
    }
    out
}

/// "; excluded: backward (why)" for the run log's note, empty when nothing was.
fn exclusions(excluded: &[(Method, &str)]) -> String {
    if excluded.is_empty() {
        return String::new();
    }
    let list: Vec<String> = excluded
        .iter()
        .map(|(m, why)| format!("{} ({why})", method_name(*m)))
        .collect();
    format!("; excluded: {}", list.join(", "))
}

/// The score of candidate `c` in `scores`.
fn score_of<T: Copy + PartialEq>(scores: &[(T, f64)], c: T) -> Option<f64> {
    scores.iter().find(|(x, _)| *x == c).map(|&(_, v)| v)
}

/// `sun.selection: auto`: `fixed` (0.5) or `power`, whichever costs least for the same laser
/// and solar errors with the campaign's method, on the method's pilot pulses, and why. Ties
/// go to fixed, the paper's.
pub fn choose_sun_selection(
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
) -> (SunSelection, String, Option<f64>) {
    let (pulses, rays) = pilot_pulses(loaded, plan);
    let n = pulses.len();
    let method = loaded.campaign.simulation.method;
    if n == 0 || loaded.campaign.sun.is_none() {
        return (
            SunSelection::Fixed,
            "sun.selection auto: no pulses to try, fixed".into(),
            None,
        );
    }
    let scores: Vec<(SunSelection, f64)> = [SunSelection::Fixed, SunSelection::Power]
        .into_iter()
        .map(|sel| {
            let trial = with_selection(loaded, sel);
            (sel, pilot_score(&trial, scene, &pulses, rays, method))
        })
        .collect();
    let table = score_table(&scores, selection_name);
    match cheapest(&scores) {
        Some(sel) => (
            sel,
            format!(
                "sun.selection auto chose {}: laser and solar relative variance x scene queries per pulse over {n} pilot pulses of {rays} rays, {} (lower is better): {table}",
                selection_name(sel),
                method_name(method)
            ),
            score_of(&scores, sel),
        ),
        None => (
            SunSelection::Fixed,
            format!(
                "sun.selection auto: no light found in {n} pilot pulses of {rays} rays, fixed (the paper's)"
            ),
            None,
        ),
    }
}

/// The campaign as it runs when it asks for `simulation.method: auto`, `sun.selection: auto`
/// or (with bdpt) `simulation.receiver_depth: auto`: the method its pilot picks
/// ([`choose_method`]), the sun's selection for the campaign's method
/// ([`choose_sun_selection`]), or both at once ([`choose_jointly`]), then bdpt's receiver
/// depth for them ([`choose_receiver_depth`]), written in, and the notes saying why; `None`
/// for a campaign that names them all. Everything that simulates a campaign's pulses goes
/// through this, so the transport never sees `auto` (but a receiver depth `auto` with
/// forward or backward, which have one sub-path and no use for it).
pub fn with_method_chosen(loaded: &Loaded, scene: &Scene, plan: &Plan) -> Option<Loaded> {
    let method_auto = loaded.campaign.simulation.method == Method::Auto;
    let sun_auto = loaded
        .campaign
        .sun
        .as_ref()
        .is_some_and(|s| s.selection() == SunSelection::Auto);
    let depth_auto = loaded.campaign.simulation.receiver_depth == ReceiverDepth::Auto;
    let bdpt_given = loaded.campaign.simulation.method == Method::Bdpt;
    let depth_to_choose = depth_auto && bdpt_given;
    let share_auto = loaded
        .campaign
        .sun
        .as_ref()
        .is_some_and(|s| s.share == Some(SunShare::Auto));
    let order_auto = loaded.campaign.simulation.max_order == MaxOrder::Auto;
    if !(method_auto || sun_auto || depth_to_choose || share_auto || order_auto) {
        return None;
    }
    let mut c = loaded.clone();
    // the chosen candidate's score: with bdpt, that of its every strategy, on the pulses the
    // depth's pilot traces again
    let (method, selection, note, score) = match (method_auto, sun_auto) {
        (true, true) => {
            let (method, selection, note, score) = choose_jointly(&c, scene, plan);
            (method, selection, Some(note), score)
        }
        (true, false) => {
            let (method, note, score) = choose_method(&c, scene, plan);
            (method, None, Some(note), score)
        }
        (false, true) => {
            let (selection, note, score) = choose_sun_selection(&c, scene, plan);
            (
                c.campaign.simulation.method,
                Some(selection),
                Some(note),
                score,
            )
        }
        (false, false) => (c.campaign.simulation.method, None, None, None),
    };
    c.campaign.simulation.method = method;
    if let Some(selection) = selection {
        c = with_selection(&c, selection);
    }
    let mut notes: Vec<String> = note.into_iter().collect();
    // the order next, on the method chosen: what the other choices then trace
    if order_auto {
        let (order, note) = choose_max_order(&c, scene, plan);
        c.campaign.simulation.max_order = MaxOrder::Order(order);
        notes.push(note);
    }
    if depth_auto {
        if method == Method::Bdpt {
            let (depth, note) = choose_receiver_depth(&c, scene, plan, score);
            c.campaign.simulation.receiver_depth = depth;
            notes.push(note);
        } else {
            c.campaign.simulation.receiver_depth = ReceiverDepth::Full;
        }
    }
    // last: the share weighs the sub-paths the other choices made
    if share_auto {
        let (share, note) = choose_sun_share(&c, scene, plan);
        if let Some(sun) = c.campaign.sun.as_mut() {
            sun.share = Some(SunShare::Fraction(share));
        }
        notes.push(note);
    }
    c.method_note = Some(notes.join("; "));
    Some(c)
}

/// Why `first` is no candidate over water, and why a campaign that names it there is warned.
pub const WATER_DEPTH: &str = "as the scene has water: a receiver sub-path's first surface is then often the water's, and the laser's light under it would be joined only through that surface (a smooth one joins none: no connection passes it), so left to the light sub-paths that cross the aperture";

/// `simulation.receiver_depth: auto` with bdpt: `full` or `first`, whichever costs least
/// for the same laser and solar errors with the campaign's sun selection, on the pilot
/// pulses of `simulation.method: auto`, and why. Ties go to full, all of bdpt's strategies.
/// `full_score`: full's score where a pilot before has it (the same pulses and draws, so the
/// same number), else it is traced.
pub fn choose_receiver_depth(
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
    full_score: Option<f64>,
) -> (ReceiverDepth, String) {
    if scene.water.is_some() {
        return (
            ReceiverDepth::Full,
            format!("simulation.receiver_depth auto: full, {WATER_DEPTH}"),
        );
    }
    let (pulses, rays) = pilot_pulses(loaded, plan);
    let n = pulses.len();
    if n == 0 {
        return (
            ReceiverDepth::Full,
            "simulation.receiver_depth auto: no pulses to try, full".into(),
        );
    }
    let scores: Vec<(ReceiverDepth, f64)> = [ReceiverDepth::Full, ReceiverDepth::First]
        .into_iter()
        .map(|depth| match (depth, full_score) {
            (ReceiverDepth::Full, Some(x)) => (depth, x),
            _ => {
                let mut trial = loaded.clone();
                trial.campaign.simulation.receiver_depth = depth;
                (
                    depth,
                    pilot_score(&trial, scene, &pulses, rays, Method::Bdpt),
                )
            }
        })
        .collect();
    let table = score_table(&scores, depth_name);
    let with_sun = match loaded.campaign.sun.as_ref() {
        Some(s) => format!(" with {}", selection_name(s.selection())),
        None => String::new(),
    };
    match cheapest(&scores) {
        Some(depth) => (
            depth,
            format!(
                "simulation.receiver_depth auto chose {}: laser and solar relative variance x scene queries per pulse over {n} pilot pulses of {rays} rays, bdpt{with_sun} (lower is better): {table}",
                depth_name(depth)
            ),
        ),
        None => (
            ReceiverDepth::Full,
            format!(
                "simulation.receiver_depth auto: no light found in {n} pilot pulses of {rays} rays, full (all of bdpt's strategies)"
            ),
        ),
    }
}

/// Both `auto`s at once: each method with each sun selection on the same pilot pulses
/// ([`pilot_score`]), and the cheapest pair. A method's best selection depends on it (by
/// power, bdpt's light sub-paths start at the laser; backward has none, so its selection
/// changes nothing and it is tried once). Ties go to the first: bdpt, then fixed.
fn choose_jointly(
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
) -> (Method, Option<SunSelection>, String, Option<f64>) {
    let (pulses, rays) = pilot_pulses(loaded, plan);
    let n = pulses.len();
    if n == 0 {
        return (
            Method::Bdpt,
            Some(SunSelection::Fixed),
            "simulation.method and sun.selection auto: no pulses to try, bdpt and fixed".into(),
            None,
        );
    }
    let excluded = excluded_methods(loaded, scene);
    let candidates = [
        (Method::Bdpt, SunSelection::Fixed),
        (Method::Bdpt, SunSelection::Power),
        (Method::Forward, SunSelection::Fixed),
        (Method::Forward, SunSelection::Power),
        // backward starts no light sub-path: the selection changes nothing for it
        (Method::Backward, SunSelection::Fixed),
    ]
    .into_iter()
    .filter(|(m, _)| !excluded.iter().any(|(x, _)| x == m));
    let scores: Vec<((Method, SunSelection), f64)> = candidates
        .into_iter()
        .map(|(m, sel)| {
            let trial = with_selection(loaded, sel);
            ((m, sel), pilot_score(&trial, scene, &pulses, rays, m))
        })
        .collect();
    let table = scores
        .iter()
        .map(|&((m, sel), x)| match m {
            Method::Backward => format!("{} {x:.3e}", method_name(m)),
            _ => format!("{} {} {x:.3e}", method_name(m), selection_name(sel)),
        })
        .collect::<Vec<_>>()
        .join(", ");
    match cheapest(&scores) {
        Some((m, sel)) => (
            m,
            Some(sel),
            format!(
                "simulation.method and sun.selection auto chose {} with {}: laser and solar relative variance x scene queries per pulse over {n} pilot pulses of {rays} rays (lower is better): {table}{}",
                method_name(m),
                selection_name(sel),
                exclusions(&excluded)
            ),
            score_of(&scores, (m, sel)),
        ),
        None => (
            Method::Bdpt,
            Some(SunSelection::Fixed),
            format!(
                "simulation.method and sun.selection auto: no light found in {n} pilot pulses of {rays} rays, bdpt and fixed (the defaults)"
            ),
            None,
        ),
    }
}

/// What a run's `auto` choices picked, as the simulate stage's fingerprint holds it: the
/// method, and the sun's selection when the run chose it.
pub fn choices_made(chosen: &Loaded, asked: &Loaded) -> String {
    let method = method_name(chosen.campaign.simulation.method);
    let sun_asked = asked.campaign.sun.as_ref().map(|s| s.selection());
    let mut made = match (sun_asked, chosen.campaign.sun.as_ref()) {
        (Some(SunSelection::Auto), Some(s)) => {
            format!("{method}; sun {}", selection_name(s.selection()))
        }
        _ => method.to_string(),
    };
    let depth_asked = asked.campaign.simulation.receiver_depth == ReceiverDepth::Auto;
    if depth_asked && chosen.campaign.simulation.method == Method::Bdpt {
        let depth = depth_name(chosen.campaign.simulation.receiver_depth);
        made.push_str(&format!("; receiver depth {depth}"));
    }
    if asked.campaign.simulation.max_order == MaxOrder::Auto {
        made.push_str(&format!(
            "; max order {}",
            chosen.campaign.simulation.max_order
        ));
    }
    let share_asked = asked
        .campaign
        .sun
        .as_ref()
        .is_some_and(|s| s.share == Some(SunShare::Auto));
    if let (true, Some(s)) = (share_asked, chosen.campaign.sun.as_ref()) {
        made.push_str(&format!("; sun share {}", share_name(s.share_fraction())));
    }
    made
}

/// A receiver depth as campaign files spell it.
pub fn depth_name(d: ReceiverDepth) -> &'static str {
    match d {
        ReceiverDepth::Full => "full",
        ReceiverDepth::First => "first",
        ReceiverDepth::Auto => "auto",
    }
}

/// A sun selection as campaign files spell it.
pub fn selection_name(s: SunSelection) -> &'static str {
    match s {
        SunSelection::Fixed => "fixed",
        SunSelection::Power => "power",
        SunSelection::Auto => "auto",
    }
}

/// A method as campaign files spell it.
pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::Bdpt => "bdpt",
        Method::Forward => "forward",
        Method::Backward => "backward",
        Method::Auto => "auto",
    }
}

/// Rays per second on this machine for this campaign, measured on up to 8 pulses spread
/// over the plan with at most 1000 rays each: the basis of `lidarsim check`'s time estimate.
pub fn probe_rays_per_second(loaded: &Loaded, scene: &Scene, plan: &Plan) -> f64 {
    let sample = plan.spread(8, loaded.campaign.seed);
    let mut probe = loaded.clone();
    probe.campaign.simulation.rays_per_pulse = probe.campaign.simulation.rays_per_pulse.min(1000);
    let t = Instant::now();
    let (w, _) = simulate(&probe, scene, &sample, &ProgressBar::hidden(), true);
    let rays: u64 = w.iter().map(|w| w.rays as u64).sum();
    rays as f64 / t.elapsed().as_secs_f64().max(1e-9)
}
