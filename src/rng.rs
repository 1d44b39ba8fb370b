//! Every random number of the program, from three small generators written here so that no
//! file depends on a random-number crate's version. Each result derives from the campaign's
//! seed and the identity of what it is for (a pulse, a chunk of rays, a part of a scene),
//! never from which thread ran it: the files are the same whatever the thread count.
//!
//! Three generators, not one, because each is part of what its files contain: changing one
//! changes every simulated waveform (`Rng`), photon record (`SplitMix64`) or generated
//! scene (`Rand`).

/// The SplitMix64 finaliser (Steele, Lea & Flood 2014): scatters the bits of a seed.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// One SplitMix64 step from `z`, used to scatter seeds.
pub fn splitmix64(z: u64) -> u64 {
    mix(z.wrapping_add(0x9E37_79B9_7F4A_7C15))
}

/// The transport's generator, one stream per (seed, pulse, chunk of rays): xoshiro256** (Blackman and Vigna), seeded through SplitMix64.
#[derive(Clone, Debug)]
pub struct Rng {
    s: [u64; 4],
}

impl Rng {
    pub fn new(seed: u64, stream: u64, chunk: u64) -> Rng {
        let mut x =
            splitmix64(seed ^ splitmix64(stream ^ splitmix64(chunk.wrapping_add(0x1234_5678))));
        let mut s = [0u64; 4];
        for v in &mut s {
            x = splitmix64(x);
            *v = x;
        }
        Rng { s }
    }

    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// The first dimensions of a pulse's ray samples: Owen-scrambled Sobol' points, in pairs
/// (Burley 2020, "Practical Hash-based Owen Scrambling"). Sample `index` of a pulse is the
/// same point however its rays are chunked or threaded; each pair has its own scramble and
/// its own shuffle of the index, so the pairs are independent of each other, while within a
/// pair any 2^k consecutive samples of the sequence fill every elementary interval of area
/// 2^-k of the square once: the footprint, the aperture and the field of view are covered
/// evenly by few rays, where independent draws leave gaps and clusters.
#[derive(Clone, Copy, Debug)]
pub struct Sobol2 {
    seed: u64,
}

impl Sobol2 {
    pub fn new(seed: u64, pulse_id: u64) -> Self {
        Sobol2 {
            seed: splitmix64(seed ^ splitmix64(pulse_id ^ 0x736f_626f_6c32_0000)),
        }
    }

    /// Point `index` of pair `pair`, in [0, 1)². Indices past 2^32 repeat the sequence.
    pub fn pair(&self, index: u64, pair: u32) -> [f64; 2] {
        let h = splitmix64(
            self.seed
                ^ u64::from(pair)
                    .wrapping_add(1)
                    .wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        let i = owen(index as u32, h as u32);
        let x = owen(i.reverse_bits(), (h >> 32) as u32);
        let y = owen(sobol_second(i), splitmix64(h) as u32);
        let unit = |v: u32| f64::from(v) * (1.0 / 4_294_967_296.0);
        [unit(x), unit(y)]
    }
}

/// The second dimension of Sobol's sequence, most significant bit first (its generator matrix
/// is Pascal's triangle mod 2).
fn sobol_second(mut i: u32) -> u32 {
    let (mut r, mut v) = (0u32, 1u32 << 31);
    while i != 0 {
        if i & 1 != 0 {
            r ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    r
}

/// Nested uniform (Owen) scrambling of a fixed-point value by a hash of its bits from the
/// most significant down (Laine-Karras permutation of the reversed bits).
fn owen(x: u32, seed: u32) -> u32 {
    let mut x = x.reverse_bits().wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x.reverse_bits()
}

/// Photon counting's generator, one stream per (seed, pulse): SplitMix64.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// The seed of band `band` (0-based) of a run of several bands: the campaign's seed for
    /// the first band (so a one-band run's draws are unchanged), a distinct one for each
    /// other, so that bands draw independent noise and photon events.
    pub fn band_seed(seed: u64, band: usize) -> u64 {
        if band == 0 {
            seed
        } else {
            seed ^ splitmix64(0x6261_6e64_0000_0000 | band as u64)
        }
    }

    /// A stream for one pulse: mixing the id first keeps neighbouring ids uncorrelated.
    pub fn for_pulse(seed: u64, pulse_id: u64) -> Self {
        SplitMix64(mix(seed ^ splitmix64(pulse_id)))
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

/// A standard normal deviate that depends on (seed, stream, index) alone, so that any one of
/// a sequence is drawn without the others (the navigation errors of a pulse found by its id):
/// Box-Muller on two uniforms hashed from the three.
pub fn normal_at(seed: u64, stream: u64, index: u64) -> f64 {
    let h = splitmix64(seed ^ splitmix64(stream ^ splitmix64(index)));
    let unit = (1u64 << 53) as f64;
    // in (0, 1], so that the logarithm is finite
    let u1 = ((h >> 11) as f64 + 1.0) / unit;
    let u2 = (splitmix64(h) >> 11) as f64 / unit;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Scene generation's generator: xorshift64*.
pub struct Rand(u64);

impl Rand {
    pub fn new(seed: u64) -> Rand {
        Rand(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.uniform()
    }
}

/// Seeds independent generators for independent parts of a scene (splitmix64 of the seed and
/// the stream number), so that a part does not change when another one draws more numbers.
pub fn stream(seed: u64, k: u64) -> Rand {
    Rand::new(splitmix64(seed ^ k.wrapping_mul(0xD1B5_4A32_D192_ED03)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first 2^k samples of every pair are a (0, k, 2)-net: each of the 2^k boxes of
    /// any shape 2^-a × 2^-(k-a) holds one point; and pairs, pulses and seeds differ.
    #[test]
    fn sobol_pairs_stratify_the_square() {
        let k = 6u32;
        let n = 1usize << k;
        for (seed, pulse, pair) in [
            (1u64, 0u64, 0u32),
            (1, 0, 1),
            (7, 123_456, 2),
            (u64::MAX, 9, 5),
        ] {
            let q = Sobol2::new(seed, pulse);
            let pts: Vec<[f64; 2]> = (0..n as u64).map(|i| q.pair(i, pair)).collect();
            assert!(pts.iter().all(|p| p.iter().all(|v| (0.0..1.0).contains(v))));
            for a in 0..=k {
                let (nx, ny) = (1usize << a, 1usize << (k - a));
                let mut seen = vec![false; n];
                for p in &pts {
                    let cell = (p[0] * nx as f64) as usize * ny + (p[1] * ny as f64) as usize;
                    assert!(
                        !seen[cell],
                        "{seed} {pulse} {pair}: two points in a {nx}x{ny} box"
                    );
                    seen[cell] = true;
                }
            }
        }
        let a = Sobol2::new(1, 0).pair(5, 0);
        assert_ne!(a, Sobol2::new(1, 0).pair(5, 1));
        assert_ne!(a, Sobol2::new(1, 1).pair(5, 0));
        assert_ne!(a, Sobol2::new(2, 0).pair(5, 0));
    }

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
