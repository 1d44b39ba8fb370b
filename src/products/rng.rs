//! A small deterministic generator for photon counting and for tests.
//!
//! Products must be reproducible from (seed, pulse id) alone, independent of thread
//! scheduling, so each pulse gets its own stream; SplitMix64 is enough for that (no
//! cryptographic or long-period needs) and avoids a dependency.

/// SplitMix64 (Steele, Lea & Flood 2014).
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// A stream for one pulse: mixing the id first keeps neighbouring ids uncorrelated.
    pub fn for_pulse(seed: u64, pulse_id: u64) -> Self {
        SplitMix64(mix(seed ^ mix(pulse_id.wrapping_add(0x9e37_79b9_7f4a_7c15))))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix(self.0)
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in (0, 1]: safe under a logarithm.
    pub fn uniform_pos(&mut self) -> f64 {
        1.0 - self.uniform()
    }

    /// Poisson variate: multiplication method below 12, Hörmann's PTRS above (exact,
    /// O(1) per draw, so bright bins cost no more than dim ones).
    pub fn poisson(&mut self, mu: f64) -> u64 {
        if mu.is_nan() || mu <= 0.0 {
            return 0;
        }
        if mu < 12.0 {
            let limit = (-mu).exp();
            let mut k = 0u64;
            let mut p = self.uniform_pos();
            while p > limit {
                k += 1;
                p *= self.uniform_pos();
            }
            return k;
        }
        let smu = mu.sqrt();
        let b = 0.931 + 2.53 * smu;
        let a = -0.059 + 0.02483 * b;
        let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
        let vr = 0.9277 - 3.6224 / (b - 2.0);
        let ln_mu = mu.ln();
        loop {
            let u = self.uniform() - 0.5;
            let v = self.uniform_pos();
            let us = 0.5 - u.abs();
            let k = ((2.0 * a / us + b) * u + mu + 0.43).floor();
            if us >= 0.07 && v <= vr {
                return k as u64;
            }
            if k < 0.0 || (us < 0.013 && v > us) {
                continue;
            }
            if v.ln() + inv_alpha.ln() - (a / (us * us) + b).ln()
                <= -mu + k * ln_mu - ln_factorial(k as u64)
            {
                return k as u64;
            }
        }
    }
}

/// ln k!, exact summation for small k, Stirling's series beyond (error < 1e-12).
pub fn ln_factorial(k: u64) -> f64 {
    if k < 20 {
        return (2..=k).map(|i| (i as f64).ln()).sum();
    }
    let x = k as f64;
    let inv = 1.0 / x;
    let inv2 = inv * inv;
    x * x.ln() - x
        + 0.5 * (2.0 * std::f64::consts::PI * x).ln()
        + inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 / 1260.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poisson_mean_and_variance() {
        let mut r = SplitMix64::new(7);
        for &mu in &[0.3, 4.0, 11.9, 12.0, 57.0, 3000.0] {
            let n = 200_000;
            let xs: Vec<f64> = (0..n).map(|_| r.poisson(mu) as f64).collect();
            let m = xs.iter().sum::<f64>() / n as f64;
            let v = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1) as f64;
            let se = (mu / n as f64).sqrt();
            assert!((m - mu).abs() < 5.0 * se, "mu {mu}: mean {m}");
            assert!((v / mu - 1.0).abs() < 0.02, "mu {mu}: variance {v}");
        }
    }

    #[test]
    fn ln_factorial_matches_sum() {
        let direct: f64 = (2..=40u64).map(|i| (i as f64).ln()).sum();
        assert!((ln_factorial(40) - direct).abs() < 1e-10);
    }
}
