//! What a pulse's rays add up to: energy per sub-bin and per order, with the sums of squares
//! over whole rays that standard errors need.

use super::bands::BandVec;
use super::PulseSetup;

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
    /// Scene queries (closest hits and visibility tests) the rays made: their cost, counted
    /// the same on any machine.
    pub queries: u64,
    /// Contributions whose weight was not a finite number (NaN or infinite), left out of every
    /// sum: none is expected, and the run log says so when one is.
    pub non_finite: u64,
    /// Path weights of this band that fell below the smallest double while the path's other
    /// bands carried light (its light along them under ~1e-308 of theirs): counted as 0, and
    /// reported by the run log (see [`bands`](super::bands)).
    pub underflows: u64,
    /// Bins [lo, hi) that received energy in the gate (lo = hi: none). Every per-bin and
    /// per-sub-bin sum is zero outside them, so a pulse of few paths in a long gate (3152
    /// bins of 0.067 ns over a forest) is reset and turned into a waveform over its span only.
    pub lit: (usize, usize),
    /// Energy that arrived within [`PulseSetup::edge_sub_bins`] sub-bins before the gate (0)
    /// and after it (1), per sub-bin, with its moments as in `sub_moment`: counted `outside`,
    /// yet its pulse tails reach into the gate's first or last bins.
    pub edge_sub: [Vec<f64>; 2],
    pub edge_moment: [Vec<f64>; 2],
    /// Whether any energy fell in `edge_sub`: else they are zeros, neither added nor cleared.
    pub edge_lit: bool,
}

impl Tally {
    pub(super) fn new(bins: usize, sub_bins: usize, max_order: u32, edge: usize) -> Tally {
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
            queries: 0,
            non_finite: 0,
            underflows: 0,
            solar_sum: 0.0,
            solar_sq: 0.0,
            lit: (0, 0),
            edge_sub: [vec![0.0; edge], vec![0.0; edge]],
            edge_moment: [vec![0.0; edge], vec![0.0; edge]],
            edge_lit: false,
        }
    }

    /// Adds bins [lo, hi) to the span that received energy.
    fn light(&mut self, lo: usize, hi: usize) {
        if lo >= hi {
            return;
        }
        self.lit = if self.lit.0 >= self.lit.1 {
            (lo, hi)
        } else {
            (self.lit.0.min(lo), self.lit.1.max(hi))
        };
    }

    pub(super) fn merge(&mut self, o: &Tally) {
        let add = |a: &mut [f64], b: &[f64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        // over `o`'s lit span only: outside it `o` holds zeros, and x + 0 is x for x ≥ 0
        // (adding a whole gate for each chunk of a many-chunk pulse: the same bits for more
        // work)
        let (lo, hi) = o.lit;
        let (lo, hi) = (lo.min(hi), hi);
        let per_bin = o.sub.len() / o.bin_sq.len().max(1);
        let subs = lo * per_bin..hi * per_bin;
        add(&mut self.sub[subs.clone()], &o.sub[subs.clone()]);
        add(&mut self.sub_moment[subs.clone()], &o.sub_moment[subs]);
        add(&mut self.bin_sq[lo..hi], &o.bin_sq[lo..hi]);
        for (a, b) in self.class_bins.iter_mut().zip(&o.class_bins) {
            add(&mut a[lo..hi], &b[lo..hi]);
        }
        add(&mut self.order_sum, &o.order_sum);
        add(&mut self.order_sq, &o.order_sq);
        self.outside += o.outside;
        self.total_sq += o.total_sq;
        self.rays += o.rays;
        self.paths += o.paths;
        self.solar_sum += o.solar_sum;
        self.solar_sq += o.solar_sq;
        self.queries += o.queries;
        self.non_finite += o.non_finite;
        self.underflows += o.underflows;
        self.light(o.lit.0, o.lit.1);
        if o.edge_lit {
            for k in 0..2 {
                add(&mut self.edge_sub[k], &o.edge_sub[k]);
                add(&mut self.edge_moment[k], &o.edge_moment[k]);
            }
            self.edge_lit = true;
        }
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

    /// Standard error of bin `b`'s impulse energy, J.
    pub fn bin_se(&self, b: usize, sub_bins: usize) -> f64 {
        let sum = self.sub[b * sub_bins..(b + 1) * sub_bins].iter().sum();
        se(sum, self.bin_sq[b], self.rays)
    }
}

/// Standard error of a mean from the sum and sum of squares of n samples.
pub(super) fn se(sum: f64, sq: f64, n: u64) -> f64 {
    if n < 2 {
        return 0.0;
    }
    let n = n as f64;
    let mean = sum / n;
    ((sq / n - mean * mean).max(0.0) / (n - 1.0)).sqrt()
}

/// Per-chunk accumulator. A ray's contributions are staged per order and per bin, so that
/// sums of squares are over whole rays (a ray is one sample of the estimator).
pub(super) struct Accum {
    pub(super) tally: Tally,
    t0: f64,
    sub_dt: f64,
    sub_bins: usize,
    ray_order: Vec<f64>,
    ray_bin: Vec<f64>,
    touched_orders: Vec<u32>,
    touched_bins: Vec<u32>,
    ray_solar: f64,
    /// The accumulators of bands 2, 3, … of a run of several bands (this one is band 1's).
    pub(super) bands: Vec<Accum>,
}

impl Accum {
    pub(super) fn new(setup: &PulseSetup) -> Accum {
        let mut a = Accum::one_band(setup);
        let more = setup.bands.map_or(0, |b| b.count - 1);
        a.bands = (0..more).map(|_| Accum::one_band(setup)).collect();
        a
    }

    fn one_band(setup: &PulseSetup) -> Accum {
        Accum {
            tally: Tally::new(
                setup.gate.bins,
                setup.sub_bins,
                setup.max_order,
                setup.edge_sub_bins,
            ),
            t0: setup.gate.t0,
            sub_dt: setup.gate.dt / setup.sub_bins as f64,
            sub_bins: setup.sub_bins,
            ray_order: vec![0.0; setup.max_order as usize],
            ray_bin: vec![0.0; setup.gate.bins],
            touched_orders: Vec::with_capacity(16),
            touched_bins: Vec::with_capacity(16),
            ray_solar: 0.0,
            bands: Vec::new(),
        }
    }

    /// The tally of band `b` (0: the first).
    pub(super) fn band(&self, b: usize) -> &Tally {
        if b == 0 {
            &self.tally
        } else {
            &self.bands[b - 1].tally
        }
    }

    /// Merges another pulse chunk's accumulators, band by band.
    pub(super) fn merge(&mut self, o: &Accum) {
        self.tally.merge(&o.tally);
        for (a, b) in self.bands.iter_mut().zip(&o.bands) {
            a.tally.merge(&b.tally);
        }
    }

    /// [`Accum::add`] in every band, band b's energy being `energy × r[b]`.
    /// `length`: the path's length in the first band's time, its geometric length in water
    /// and the water's group index per band (empty without water), which part the bands' times.
    pub(super) fn add_bands(
        &mut self,
        (length, water, group): (f64, f64, &[f64]),
        energy: f64,
        order: usize,
        class: usize,
        r: &BandVec,
    ) {
        self.add(length, energy * r[0], order, class);
        for (b, (a, f)) in self.bands.iter_mut().zip(&r[1..]).enumerate() {
            let slower = match (group.first(), group.get(b + 1)) {
                (Some(first), Some(g)) if water > 0.0 => (g - first) * water,
                _ => 0.0,
            };
            a.add(length + slower, energy * f, order, class);
        }
    }

    /// Adds each band's count of weights lost to underflow (see [`super::bands::take_underflows`]).
    pub(super) fn add_underflows(&mut self, lost: &[u64]) {
        self.tally.underflows += lost[0];
        for (a, n) in self.bands.iter_mut().zip(&lost[1..]) {
            a.tally.underflows += n;
        }
    }

    /// [`Accum::add_solar`] in every band.
    pub(super) fn add_solar_bands(&mut self, power: f64, r: &BandVec) {
        self.add_solar(power * r[0]);
        for (a, f) in self.bands.iter_mut().zip(&r[1..]) {
            a.add_solar(power * f);
        }
    }

    /// Ready for another pulse: every sum zero, sized for `setup`'s gate and orders, the
    /// memory kept. The per-bin sums are zero outside the last pulse's lit span, so only
    /// that span is cleared before they are sized for the new gate.
    pub(super) fn reset(&mut self, setup: &PulseSetup) {
        let more = setup.bands.map_or(0, |b| b.count - 1);
        if self.bands.len() != more {
            self.bands = (0..more).map(|_| Accum::one_band(setup)).collect();
        }
        for a in &mut self.bands {
            a.reset_band(setup);
        }
        self.reset_band(setup);
    }

    /// [`Accum::reset`] of this band's sums alone.
    fn reset_band(&mut self, setup: &PulseSetup) {
        let (bins, sub_bins) = (setup.gate.bins, setup.sub_bins);
        let zero = |v: &mut Vec<f64>, n: usize| {
            v.clear();
            v.resize(n, 0.0);
        };
        let t = &mut self.tally;
        let (lo, hi) = t.lit;
        let old = self.sub_bins;
        let span = |v: &mut Vec<f64>, (a, b): (usize, usize), n: usize| {
            let end = b.min(v.len());
            v[a.min(end)..end].fill(0.0);
            v.resize(n, 0.0);
        };
        span(&mut t.sub, (lo * old, hi * old), bins * sub_bins);
        span(&mut t.sub_moment, (lo * old, hi * old), bins * sub_bins);
        span(&mut t.bin_sq, (lo, hi), bins);
        for c in &mut t.class_bins {
            span(c, (lo, hi), bins);
        }
        span(&mut self.ray_bin, (lo, hi), bins);
        t.lit = (0, 0);
        for v in t.edge_sub.iter_mut().chain(t.edge_moment.iter_mut()) {
            if t.edge_lit || v.len() != setup.edge_sub_bins {
                zero(v, setup.edge_sub_bins);
            }
        }
        t.edge_lit = false;
        zero(&mut t.order_sum, setup.max_order as usize);
        zero(&mut t.order_sq, setup.max_order as usize);
        (t.outside, t.total_sq, t.rays, t.paths) = (0.0, 0.0, 0, 0);
        (t.solar_sum, t.solar_sq, t.queries, t.non_finite) = (0.0, 0.0, 0, 0);
        t.underflows = 0;
        self.t0 = setup.gate.t0;
        self.sub_dt = setup.gate.dt / sub_bins as f64;
        self.sub_bins = sub_bins;
        zero(&mut self.ray_order, setup.max_order as usize);
        self.touched_orders.clear();
        self.touched_bins.clear();
        self.ray_solar = 0.0;
    }

    /// A solar path carrying `power` watts (the sun is continuous: no time, no bin).
    pub(super) fn add_solar(&mut self, power: f64) {
        if !power.is_finite() {
            debug_assert!(false, "a solar contribution of {power} W");
            self.tally.non_finite += 1;
        } else if power > 0.0 {
            self.ray_solar += power;
            self.tally.paths += 1;
        }
    }

    /// A path of `length` metres and `order` surface interactions carrying `energy` joules.
    pub(super) fn add(&mut self, length: f64, energy: f64, order: usize, class: usize) {
        if !(energy.is_finite() && length.is_finite()) {
            debug_assert!(false, "a contribution of {energy} J at {length} m");
            self.tally.non_finite += 1;
            return;
        }
        if energy <= 0.0 || order == 0 {
            return;
        }
        let x = (length / crate::C - self.t0) / self.sub_dt;
        if x >= 0.0 && (x as usize) < self.tally.sub.len() {
            let i = x as usize;
            self.tally.sub[i] += energy;
            self.tally.sub_moment[i] += energy * (x - i as f64);
            let b = i / self.sub_bins;
            self.tally.light(b, b + 1);
            self.tally.class_bins[class][b] += energy;
            if self.ray_bin[b] == 0.0 {
                self.touched_bins.push(b as u32);
            }
            self.ray_bin[b] += energy;
        } else {
            self.tally.outside += energy;
            self.add_at_edge(x, energy);
        }
        let k = order - 1;
        if self.ray_order[k] == 0.0 {
            self.touched_orders.push(k as u32);
        }
        self.ray_order[k] += energy;
        self.tally.paths += 1;
    }

    /// Energy at `x` sub-bins from the gate's start, outside the gate, kept in the edge's
    /// sub-bins where it lies within them.
    fn add_at_edge(&mut self, x: f64, energy: f64) {
        let t = &mut self.tally;
        let m = t.edge_sub[0].len() as f64;
        let (side, y) = if x < 0.0 {
            (0, x + m)
        } else {
            (1, x - t.sub.len() as f64)
        };
        if y >= 0.0 && y < m {
            let j = y as usize;
            t.edge_sub[side][j] += energy;
            t.edge_moment[side][j] += energy * (y - j as f64);
            t.edge_lit = true;
        }
    }

    pub(super) fn end_ray(&mut self) {
        for a in &mut self.bands {
            a.end_ray();
        }
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
