//! Navigation errors (`platform.errors`): the recorded position and attitude differ from the
//! flown ones by first-order Gauss-Markov processes, each stationary with standard deviation σ
//! and autocorrelation exp(−|Δt| / τ) (white when τ = 0), sampled at the pulses' times.
//!
//! A pulse's error is found from its id alone (a plan makes any pulse on demand), by Lévy's
//! construction over the pulse ids: the first pulse's error is drawn, the last pulse's from the
//! first's by the process's transition, and every other pulse's as the midpoint of an interval
//! of ids whose ends are known, from the process's bridge. For times a ≤ m ≤ b, with
//! α = e^(−(t_m − t_a)/τ), β = e^(−(t_b − t_m)/τ), γ = αβ:
//!
//!   x_m | x_a, x_b ~ N( [α(1 − β²) x_a + β(1 − α²) x_b] / (1 − γ²),  σ² (1 − α²)(1 − β²) / (1 − γ²) )
//!
//! which is exact: the pulses' errors have the process's joint distribution whatever their
//! spacing (channels firing at once share one error). Each pulse's draw is hashed from the
//! seed, the process and the id, so the errors do not depend on threads or on which pulses
//! were asked for first. A query walks down from the whole plan to its pulse: log₂ N steps,
//! of which the first [`LEVELS`] are kept from the plan's making.

use crate::campaign::NavErrors;
use crate::rng::normal_at;

/// Levels of the bisection kept: 2^LEVELS midpoints, 3 numbers each per process.
const LEVELS: u32 = 15;

/// One three-dimensional Gauss-Markov process.
struct Process {
    sd: [f64; 3],
    tau: f64,
    stream: u64,
    /// The first and last pulses' values (the bisection's ends).
    ends: [[f64; 3]; 2],
    /// Midpoint of the bisection's node h (the root is 1; children 2h, 2h + 1).
    kept: Vec<[f64; 3]>,
}

pub(crate) struct Errors {
    seed: u64,
    n: u64,
    position: Option<Process>,
    attitude: Option<Process>,
}

impl Errors {
    /// The errors of a plan of `n` pulses whose GPS times `time` gives (non-decreasing in id);
    /// `None` when no error is drawn.
    pub(crate) fn new(
        e: &NavErrors,
        seed: u64,
        n: u64,
        time: &dyn Fn(u64) -> f64,
    ) -> Option<Errors> {
        let make = |sd: Option<[f64; 3]>, tau: Option<f64>, stream: u64| {
            let sd = sd.filter(|s| s.iter().any(|&v| v > 0.0))?;
            let mut p = Process {
                sd,
                tau: tau.unwrap_or(0.0),
                stream,
                ends: [[0.0; 3]; 2],
                kept: Vec::new(),
            };
            if p.tau > 0.0 && n > 0 {
                p.keep(seed, n, time);
            }
            Some(p)
        };
        let position = make(e.position_sd_m, e.position_correlation_s, 0x6e61_7600);
        let attitude = make(e.attitude_sd_deg, e.attitude_correlation_s, 0x6e61_7610);
        (position.is_some() || attitude.is_some()).then_some(Errors {
            seed,
            n,
            position,
            attitude,
        })
    }

    /// East, north, up position error (m) and roll, pitch, heading error (degrees) of pulse
    /// `id`.
    pub(crate) fn at(&self, id: u64, time: &dyn Fn(u64) -> f64) -> ([f64; 3], [f64; 3]) {
        let of = |p: &Option<Process>| {
            p.as_ref()
                .map_or([0.0; 3], |p| p.value(self.seed, self.n, id, time))
        };
        (of(&self.position), of(&self.attitude))
    }
}

impl Process {
    fn draw(&self, seed: u64, id: u64) -> [f64; 3] {
        std::array::from_fn(|d| normal_at(seed, self.stream + d as u64, id))
    }

    /// x_b from x_a over Δt = t_b − t_a: the process's transition.
    fn transition(&self, seed: u64, xa: [f64; 3], dt: f64, b: u64) -> [f64; 3] {
        let rho = (-dt / self.tau).exp();
        let keep = (-(-2.0 * dt / self.tau).exp_m1()).max(0.0).sqrt();
        let w = self.draw(seed, b);
        std::array::from_fn(|d| rho * xa[d] + self.sd[d] * keep * w[d])
    }

    /// x_m from the ends of its interval: the bridge (module doc).
    fn bridge(
        &self,
        seed: u64,
        (ta, tm, tb): (f64, f64, f64),
        xa: [f64; 3],
        xb: [f64; 3],
        m: u64,
    ) -> [f64; 3] {
        let one_g = -(-2.0 * (tb - ta) / self.tau).exp_m1();
        if one_g <= 0.0 {
            return xa;
        }
        let (da, db) = (tm - ta, tb - tm);
        let (alpha, beta) = ((-da / self.tau).exp(), (-db / self.tau).exp());
        let one_a = -(-2.0 * da / self.tau).exp_m1();
        let one_b = -(-2.0 * db / self.tau).exp_m1();
        let spread = (one_a * one_b / one_g).max(0.0).sqrt();
        let w = self.draw(seed, m);
        std::array::from_fn(|d| {
            (alpha * one_b * xa[d] + beta * one_a * xb[d]) / one_g + self.sd[d] * spread * w[d]
        })
    }

    /// Draws the ends and the first [`LEVELS`] levels of midpoints.
    fn keep(&mut self, seed: u64, n: u64, time: &dyn Fn(u64) -> f64) {
        let x0 = {
            let w = self.draw(seed, 0);
            std::array::from_fn(|d| self.sd[d] * w[d])
        };
        let last = n - 1;
        let xl = if last == 0 {
            x0
        } else {
            self.transition(seed, x0, time(last) - time(0), last)
        };
        self.ends = [x0, xl];
        self.kept = vec![[f64::NAN; 3]; 1 << LEVELS];
        // (node, a, b, x_a, x_b), depth first
        let mut stack = vec![(1usize, 0u64, last, x0, xl)];
        while let Some((h, a, b, xa, xb)) = stack.pop() {
            if h >= self.kept.len() || b - a < 2 {
                continue;
            }
            let m = a + (b - a) / 2;
            let xm = self.bridge(seed, (time(a), time(m), time(b)), xa, xb, m);
            self.kept[h] = xm;
            stack.push((2 * h, a, m, xa, xm));
            stack.push((2 * h + 1, m, b, xm, xb));
        }
    }

    fn value(&self, seed: u64, n: u64, id: u64, time: &dyn Fn(u64) -> f64) -> [f64; 3] {
        if self.tau <= 0.0 {
            // channels that fire together (a multibeam head's, one time) share one error:
            // the firing's first pulse's draw
            let t = time(id);
            let mut first = id;
            while first > 0 && time(first - 1) == t {
                first -= 1;
            }
            let w = self.draw(seed, first);
            return std::array::from_fn(|d| self.sd[d] * w[d]);
        }
        let last = n - 1;
        let [x0, xl] = self.ends;
        if id == 0 {
            return x0;
        }
        if id == last {
            return xl;
        }
        let (mut h, mut a, mut b, mut xa, mut xb) = (1usize, 0u64, last, x0, xl);
        loop {
            let m = a + (b - a) / 2;
            let xm = match self.kept.get(h) {
                Some(x) => *x,
                None => self.bridge(seed, (time(a), time(m), time(b)), xa, xb, m),
            };
            if id == m {
                return xm;
            }
            if id < m {
                (b, xb) = (m, xm);
                h *= 2;
            } else {
                (a, xa) = (m, xm);
                h = 2 * h + 1;
            }
        }
    }
}
