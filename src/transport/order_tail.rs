//! How much of a pulse's received energy lies past each order of scattering: the bound
//! behind `simulation.max_order: auto`, from a pilot's rays traced in batches.
//!
//! A pilot's own tail past order k (its energies of orders k + 1 to the cap) is no bound past
//! the orders its paths reach: a path that survives Russian roulette to order 30 is rare, and
//! where none did the tail looks empty, yet inside an integrating sphere of albedo 0.8 the
//! energy past order 26 is four times that of order 26. Light that has scattered many times has
//! forgotten where it came from, and each order then holds the same share of the one before
//! (the transport's largest eigenvalue, below 1 where light escapes or is absorbed), a share
//! that grows with the order towards that limit. So the orders past the last one the pilot
//! measures are extrapolated from the measured ones' decay, and the tail past k is bounded by
//! the larger of the pilot's own tail and that model, each three standard errors up (more
//! where the batches below are few).
//!
//! Standard errors come from the spread of the pilot's batches (each pulse's chunks of rays,
//! or its pulses): the orders of one path are not independent (a path that survives longer
//! adds to every later order), so no error propagated from each order's own could be trusted
//! for a sum or a fit over them. A delete-one jackknife over the batches carries that
//! correlation into every figure.

use super::tally::se;

/// One batch of a pilot pulse's rays: the sums of each ray's energy per order (index 0 =
/// order 1) and of the square of each ray's total energy, over `rays` rays.
#[derive(Clone, Debug)]
pub struct Batch {
    pub order_sum: Vec<f64>,
    pub total_sq: f64,
    pub rays: u64,
}

/// A standard error at most this share of its order's energy marks an order the pilot
/// measures: its paths are many enough that their spread says how far the estimate may be off.
pub const ORDER_MEASURED: f64 = 0.1;

/// A bound is its estimate plus this many standard errors where those are known exactly: the
/// normal distribution's one-sided 99.87 %.
const SIGMAS: f64 = 3.0;

/// Standard errors a bound adds where they come from the spread of `batches` batches: Student's
/// t with batches - 1 degrees of freedom at the same 99.87 % ([`SIGMAS`] for many batches).
/// Exact to the third decimal up to 9 degrees of freedom, past them the Cornish-Fisher
/// expansion to its third term (at most 0.004 below).
fn sigmas(batches: usize) -> f64 {
    const EXACT: [f64; 9] = [
        235.799, 19.207, 9.219, 6.62, 5.507, 4.904, 4.53, 4.277, 4.094,
    ];
    let d = batches.saturating_sub(1);
    if d == 0 {
        return f64::INFINITY;
    }
    if d <= EXACT.len() {
        return EXACT[d - 1];
    }
    let (z, d) = (SIGMAS, d as f64);
    z + (z.powi(3) + z) / (4.0 * d)
        + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * d * d)
        + (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z) / (384.0 * d.powi(3))
}

/// What [`tail_bounds`] found.
#[derive(Clone, Debug)]
pub struct TailBounds {
    /// Bound on a pulse's mean received energy past each order k = 0..=cap, J; infinite where
    /// the pilot cannot bound it. Past the cap (which no run traces) it is the decay's
    /// extrapolation, infinite without one.
    pub past: Vec<f64>,
    /// The pilot's mean received energy past each order, J.
    pub seen: Vec<f64>,
    /// How the orders past the last measured one were extrapolated, when they were.
    pub decay: Option<Decay>,
    /// Batches whose spread gave the standard errors.
    pub batches: usize,
    /// Standard errors each bound adds ([`SIGMAS`], more for few batches).
    pub sigmas: f64,
}

/// The orders past `last` (the last the pilot measures) taken as `ratio` times the one before,
/// as orders `from` to `last` decay (or the next order's share of `last`'s, where `from` is
/// `last`).
#[derive(Clone, Copy, Debug)]
pub struct Decay {
    pub from: usize,
    pub last: usize,
    pub ratio: f64,
}

/// Bounds on the received energy past each order, averaged over the pilot's pulses, each
/// given as its batches of rays (every pulse's weight the same, whatever its rays).
pub fn tail_bounds(pulses: &[Vec<Batch>], cap: usize) -> TailBounds {
    let energy = pulse_mean(pulses, cap);
    let replicates = jackknife_replicates(pulses, cap);
    let batches = replicates.len();
    let t = sigmas(batches);
    // a figure made of the orders' energies, and its standard error
    let with_se = |stat: &dyn Fn(&[f64]) -> Vec<f64>| -> (Vec<f64>, Vec<f64>) {
        let full = stat(&energy);
        let reps: Vec<Vec<f64>> = replicates.iter().map(|r| stat(r)).collect();
        let se = jackknife_se(&full, &reps);
        (full, se)
    };
    let (seen, seen_se) = with_se(&suffix_sums);
    let (_, order_se) = with_se(&|e: &[f64]| e.to_vec());
    let measured =
        |j: usize| energy[j - 1] > 0.0 && order_se[j - 1] <= ORDER_MEASURED * energy[j - 1];
    let last = (1..=cap).rev().find(|&j| batches >= 2 && measured(j));
    let shape = last.map(|m| Shape::new(&energy, &order_se, m));
    let ratio = shape.as_ref().map(|s| s.decay(&energy).0);
    // the energy past each order as the model has it, and its standard error; past the cap
    // (traced by no run) as the decay extrapolates it. The decay must fall below 1 by its own
    // standard errors: orders that keep their energy within the pilot's errors (an enclosure
    // of albedo 1) have no tail a fit could bound, however close to 1 the fitted share
    let decaying = shape.as_ref().is_some_and(|s| {
        let (r, r_se) = with_se(&|e: &[f64]| vec![s.decay(e).0]);
        r[0] + t * r_se[0] < 1.0
    });
    let model = match &shape {
        Some(shape) if decaying => Some(with_se(&|e: &[f64]| shape.tail(e, cap))),
        _ => None,
    };
    let none_found = energy.iter().all(|&e| e <= 0.0);
    let past_cap = match &model {
        _ if none_found => 0.0,
        Some((m, m_se)) => m[cap] + t * m_se[cap],
        None => f64::INFINITY,
    };
    let past = (0..=cap)
        .map(|k| match &model {
            _ if none_found => 0.0,
            _ if k == cap => past_cap,
            Some((m, m_se)) => (seen[k] + t * seen_se[k] + past_cap).max(m[k] + t * m_se[k]),
            None => f64::INFINITY,
        })
        .collect();
    TailBounds {
        past,
        seen,
        decay: shape.zip(ratio).map(|(s, ratio)| Decay {
            from: s.from,
            last: s.last,
            ratio,
        }),
        batches,
        sigmas: t,
    }
}

/// The standard error of a pilot pulse's total received energy, J, from its batches.
pub fn pulse_se(batches: &[Batch]) -> f64 {
    let sum: f64 = batches.iter().flat_map(|b| &b.order_sum).sum();
    let sq: f64 = batches.iter().map(|b| b.total_sq).sum();
    se(sum, sq, batches.iter().map(|b| b.rays).sum())
}

/// The orders' decay past `last`: fitted over orders `from` to `last` (ln energy a line in the
/// order, by weighted least squares with the full pilot's inverse variances of the logarithms,
/// `weights`) or, where `from` is `last`, order last + 1's share of `last`.
struct Shape {
    from: usize,
    last: usize,
    weights: Vec<f64>,
}

impl Shape {
    /// The decay past order `last` from the pilot's orders, `energy` and `se`: fitted over the
    /// later two thirds of the measured orders past the first (the first is the surfaces the
    /// laser lights, whose share of the second bears on no later order), or the next order's
    /// share of `last` where fewer than two of them are measured.
    fn new(energy: &[f64], se: &[f64], last: usize) -> Shape {
        let from = (last / 3 + 1).max(2);
        let weights: Vec<f64> = (1..=energy.len())
            .map(|j| {
                let (e, s) = (energy[j - 1], se[j - 1]);
                if (from..=last).contains(&j) && e > 0.0 && s > 0.0 {
                    (e / s).powi(2)
                } else {
                    0.0
                }
            })
            .collect();
        let fitted = weights.iter().filter(|&&w| w > 0.0).count() >= 2;
        Shape {
            from: if fitted { from } else { last },
            last,
            weights,
        }
    }

    /// Each order's share of the one before past `last`, and order `last`'s energy as the
    /// decay gives it.
    fn decay(&self, e: &[f64]) -> (f64, f64) {
        let last = self.last;
        if self.from == last {
            let (a, b) = (e[last - 1], e.get(last).copied().unwrap_or(f64::INFINITY));
            return (if a > 0.0 { b / a } else { f64::INFINITY }, a);
        }
        let (mut w, mut wx, mut wy, mut wxx, mut wxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for j in self.from..=last {
            let (weight, v) = (self.weights[j - 1], e[j - 1]);
            if weight == 0.0 || v <= 0.0 {
                continue;
            }
            let (x, y) = (j as f64, v.ln());
            w += weight;
            wx += weight * x;
            wy += weight * y;
            wxx += weight * x * x;
            wxy += weight * x * y;
        }
        let spread = wxx - wx * wx / w;
        if !(w > 0.0 && spread > 0.0) {
            return (f64::INFINITY, 0.0);
        }
        let slope = (wxy - wx * wy / w) / spread;
        let at_last = wy / w + slope * (last as f64 - wx / w);
        (slope.exp(), at_last.exp())
    }

    /// The energy past each order k = 0..=cap: the orders up to `last` as measured, the ones
    /// past it geometric from the decay's value at `last`.
    fn tail(&self, e: &[f64], cap: usize) -> Vec<f64> {
        let (r, at_last) = self.decay(e);
        let last = self.last;
        if r.is_nan() || r >= 1.0 {
            return vec![f64::INFINITY; cap + 1];
        }
        let beyond = |k: usize| at_last * r.powi((k - last + 1) as i32) / (1.0 - r);
        let mut out = vec![0.0; cap + 1];
        out[cap] = beyond(cap);
        for k in (0..cap).rev() {
            out[k] = if k >= last {
                beyond(k)
            } else {
                out[k + 1] + e[k]
            };
        }
        out
    }
}

/// Sums of `e` past each order k = 0..=len: element k is e[k] + … + e[len - 1].
fn suffix_sums(e: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; e.len() + 1];
    for k in (0..e.len()).rev() {
        out[k] = out[k + 1] + e[k];
    }
    out
}

/// Each pulse's energy per order, its mean over its rays.
fn pulse_orders(batches: &[Batch], cap: usize) -> Vec<f64> {
    let rays = batches.iter().map(|b| b.rays).sum::<u64>().max(1) as f64;
    let mut out = vec![0.0; cap];
    for b in batches {
        for (o, s) in out.iter_mut().zip(&b.order_sum) {
            *o += s / rays;
        }
    }
    out
}

/// Each order's energy, the mean over the pulses of each pulse's mean over its rays.
fn pulse_mean(pulses: &[Vec<Batch>], cap: usize) -> Vec<f64> {
    let n = pulses.len().max(1) as f64;
    let mut out = vec![0.0; cap];
    for batches in pulses {
        for (o, v) in out.iter_mut().zip(pulse_orders(batches, cap)) {
            *o += v / n;
        }
    }
    out
}

/// The orders' energies with each batch left out in turn: a batch of a pulse of several, out
/// of that pulse's mean; a pulse of one batch, out of the mean over pulses.
fn jackknife_replicates(pulses: &[Vec<Batch>], cap: usize) -> Vec<Vec<f64>> {
    let n = pulses.len() as f64;
    let full = pulse_mean(pulses, cap);
    let mut reps = Vec::new();
    for batches in pulses {
        let own = pulse_orders(batches, cap);
        if batches.len() >= 2 {
            for leave in 0..batches.len() {
                let mut kept = batches.to_vec();
                kept.remove(leave);
                let without = pulse_orders(&kept, cap);
                reps.push(
                    (0..cap)
                        .map(|j| full[j] + (without[j] - own[j]) / n)
                        .collect(),
                );
            }
        } else if n >= 2.0 {
            reps.push(
                (0..cap)
                    .map(|j| (n * full[j] - own[j]) / (n - 1.0))
                    .collect(),
            );
        }
    }
    reps
}

/// The delete-one jackknife's standard error of each element of a statistic from its
/// replicates ((m - 1) / m times the replicates' sum of squared deviations, square rooted).
fn jackknife_se(full: &[f64], reps: &[Vec<f64>]) -> Vec<f64> {
    let m = reps.len() as f64;
    (0..full.len())
        .map(|i| {
            if reps.iter().any(|r| !r[i].is_finite()) {
                return f64::INFINITY;
            }
            let mean = reps.iter().map(|r| r[i]).sum::<f64>() / m;
            let ss: f64 = reps.iter().map(|r| (r[i] - mean).powi(2)).sum();
            ((m - 1.0) / m * ss).sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Batches of 256 rays whose orders follow `order` (energy per ray of order j, 1-based),
    /// each batch off by its own few per cent (the same for all its orders, as a path that
    /// survives longer lifts every later order), and nothing past `reached`: what a pilot
    /// whose paths ran out there shows.
    fn batches(order: impl Fn(usize) -> f64, reached: usize, cap: usize) -> Vec<Batch> {
        (0..8)
            .map(|b| {
                let off = 1.0 + 0.04 * (b as f64 - 3.5) / 3.5;
                let order_sum: Vec<f64> = (1..=cap)
                    .map(|j| {
                        if j <= reached {
                            256.0 * order(j) * off
                        } else {
                            0.0
                        }
                    })
                    .collect();
                let total: f64 = order_sum.iter().sum::<f64>() / 256.0;
                Batch {
                    order_sum,
                    total_sq: 256.0 * total * total * 4.0,
                    rays: 256,
                }
            })
            .collect()
    }

    #[test]
    fn a_geometric_tail_past_the_orders_reached_is_bounded() {
        // an integrating sphere of albedo 0.8: each order 0.8 of the one before, the pilot's
        // paths gone past order 26
        let (cap, r) = (100, 0.8f64);
        let order = |j: usize| 1e-9 * r.powi(j as i32 - 1);
        let b = tail_bounds(&[batches(order, 26, cap)], cap);
        for k in 1..cap {
            let truth = order(k + 1) / (1.0 - r);
            assert!(
                b.past[k] >= truth,
                "order {k}: {:.3e} < {truth:.3e}",
                b.past[k]
            );
            // the pilot's own tail is no bound past the orders it reached
            if k >= 26 {
                assert_eq!(b.seen[k], 0.0);
            }
        }
        let d = b.decay.expect("the orders decay");
        assert!((d.ratio - r).abs() < 1e-9, "{d:?}");
        assert_eq!(b.batches, 8);
        // past the cap, which no run traces, as the decay extrapolates it
        let beyond = order(cap + 1) / (1.0 - r);
        assert!(
            b.past[cap] >= beyond && b.past[cap] < 2.0 * beyond,
            "{:.3e} against {beyond:.3e}",
            b.past[cap]
        );
        // a bound, not a guess far above the truth: within a factor 2 where it matters
        let truth_30 = order(31) / (1.0 - r);
        assert!(b.past[30] < 2.0 * truth_30, "{:.3e}", b.past[30]);
    }

    #[test]
    fn a_growing_ratio_is_extrapolated_from_the_later_orders() {
        // a canopy: the second order a small share of the first, the share growing to 0.5
        let cap = 100;
        let order = |j: usize| match j {
            1 => 1e-8,
            j => 1e-10 * (0.5f64).powi(j as i32 - 2) * (1.0 - 0.5 / j as f64),
        };
        let b = tail_bounds(&[batches(order, 20, cap)], cap);
        for k in 1..cap {
            let truth: f64 = (k + 1..=cap).map(order).sum();
            assert!(
                b.past[k] >= truth,
                "order {k}: {:.3e} < {truth:.3e}",
                b.past[k]
            );
        }
    }

    #[test]
    fn nothing_past_the_first_order_bounds_its_tail_by_zero() {
        // over a plane no path scatters twice
        let cap = 100;
        let b = tail_bounds(&[batches(|_| 1e-9, 1, cap)], cap);
        assert_eq!(b.past[1], 0.0);
        assert!(b.past[0] > 0.0);
    }

    #[test]
    fn without_light_or_without_batches_to_compare() {
        let cap = 10;
        let dark = tail_bounds(&[batches(|_| 0.0, cap, cap)], cap);
        assert!(dark.past.iter().all(|&x| x == 0.0));
        // one batch: no spread, so no bound at all
        let one = vec![batches(|j| 0.5f64.powi(j as i32), cap, cap).remove(0)];
        let b = tail_bounds(&[one], cap);
        assert!(b.past.iter().all(|x| x.is_infinite()));
        assert_eq!(b.batches, 0);
    }

    #[test]
    fn few_batches_widen_the_bound_as_students_t() {
        assert!(sigmas(1).is_infinite());
        assert_eq!(sigmas(8), 4.53);
        assert!((sigmas(11) - 3.957).abs() < 0.005, "{}", sigmas(11));
        assert!((sigmas(31) - 3.27).abs() < 0.002, "{}", sigmas(31));
        assert!((sigmas(100_000) - SIGMAS).abs() < 1e-3);
    }

    #[test]
    fn pulses_of_one_batch_are_the_batches() {
        let cap = 5;
        let pulses: Vec<Vec<Batch>> = (0..20)
            .map(|p| {
                let mut b = batches(
                    |j| 0.1f64.powi(j as i32) * (1.0 + 0.01 * p as f64),
                    cap,
                    cap,
                );
                b.truncate(1);
                b
            })
            .collect();
        let b = tail_bounds(&pulses, cap);
        assert_eq!(b.batches, 20);
        assert!(b.past[1] >= b.seen[1] && b.past[1].is_finite());
    }
}
