//! What the instrument records of a pulse's mean waveform: the detector's impulse response,
//! shot and electronic noise, the digitiser, and the transmitted-pulse record.
//!
//! The waveform files keep the mean, noise-free photons (the output contract); a record is
//! drawn from them in the products stage, from (seed, pulse id) alone, so it is the same for
//! any thread count or shard split.
//!
//! In bin k of width Δt, with quantum efficiency q, laser photons L_k (convolved with the
//! detector's Gaussian response h when one is set), solar photons S per bin and dark rate D:
//!
//!   mean photoelectrons   μ_k = q (L ⊛ h)_k + q S + D Δt
//!   recorded (noise on)   e_k ~ Poisson(μ_k) + N(0, σ_e²)      (σ_e: electronic noise)
//!   digitised             c_k = min(max(round(offset + gain e_k), 0), saturation)
//!
//! Without noise e_k = μ_k; without a digitiser the record is e_k in photoelectrons.

use super::Waveform;
use crate::campaign::{Digitiser, Instrument};
use crate::rng::SplitMix64;

/// Mixed into the seed so the noise is independent of the photon-counting draws, which use
/// the same (seed, pulse) streams.
const NOISE_STREAM: u64 = 0x6e6f_6973_655f_7278;

#[derive(Clone, Debug)]
pub struct Recorder {
    pub quantum_efficiency: f64,
    pub dark_count_hz: f64,
    /// σ of the detector's impulse response, s; 0 = none.
    pub response_sigma_s: f64,
    /// σ_e, photoelectrons; `None` = the mean waveform is recorded.
    pub electronic_sd: Option<f64>,
    pub digitiser: Option<Digitiser>,
    pub seed: u64,
}

/// One pulse's record.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// Counts with a digitiser, photoelectrons without.
    pub samples: Vec<f32>,
    /// The mean of a sample without laser signal, in the same units: background and dark
    /// photoelectrons, digitised.
    pub background: f64,
}

/// FWHM → σ of a Gaussian.
fn sigma_of_fwhm(fwhm: f64) -> f64 {
    fwhm / (8.0 * std::f64::consts::LN_2).sqrt()
}

impl Recorder {
    pub fn new(inst: &Instrument, seed: u64) -> Recorder {
        Recorder {
            quantum_efficiency: inst.quantum_efficiency.unwrap_or(1.0),
            dark_count_hz: inst.dark_count_hz.unwrap_or(0.0),
            response_sigma_s: sigma_of_fwhm(inst.detector_response_fwhm_ns.unwrap_or(0.0)) * 1e-9,
            electronic_sd: inst.noise.as_ref().map(|n| n.electronic_sd_photons),
            digitiser: inst.digitiser.clone(),
            seed,
        }
    }

    /// True when the record is more than the mean waveform: then the discrete returns are
    /// found in the record, not in the mean photons.
    pub fn changes_returns(&self) -> bool {
        self.electronic_sd.is_some() || self.digitiser.is_some() || self.response_sigma_s > 0.0
    }

    /// σ of the returns' shape in the record, s: the pulse's and the detector's in quadrature.
    pub fn return_sigma_s(&self, pulse_sigma_s: f64) -> f64 {
        pulse_sigma_s.hypot(self.response_sigma_s)
    }

    /// Counts of `pe` photoelectrons (identity without a digitiser).
    pub fn digitise(&self, pe: f64) -> f64 {
        match &self.digitiser {
            Some(d) => (d.offset + d.gain * pe).round().clamp(0.0, d.saturation()),
            None => pe,
        }
    }

    /// Mean photoelectrons per bin from the laser alone (after the detector response), and
    /// from the background (solar and dark).
    pub fn mean_photoelectrons(&self, w: &Waveform) -> (Vec<f64>, f64) {
        let q = self.quantum_efficiency;
        let laser: Vec<f64> = w
            .laser_photons
            .iter()
            .map(|&v| q * v.max(0.0) as f64)
            .collect();
        let laser = convolve_gaussian(&laser, self.response_sigma_s / (w.bin_ns as f64 * 1e-9));
        (laser, self.mean_photoelectrons_background(w))
    }

    pub fn record(&self, w: &Waveform) -> Record {
        let (laser, background) = self.mean_photoelectrons(w);
        let mut rng = SplitMix64::for_pulse(self.seed ^ NOISE_STREAM, w.pulse_id);
        let samples = laser
            .iter()
            .map(|&l| {
                let mu = l + background;
                let pe = match self.electronic_sd {
                    Some(sd) => rng.poisson(mu) as f64 + sd * normal(&mut rng),
                    None => mu,
                };
                self.digitise(pe) as f32
            })
            .collect();
        Record {
            samples,
            background: self.expected_sample(background),
        }
    }

    /// The mean of a recorded sample whose mean photoelectrons are `pe` (the background: solar
    /// and dark), in record units: E[c] over the noise, not c of the mean. With a digitiser the
    /// rounding and the clipping at 0 and at saturation bend the mean: a background near the
    /// offset's bottom, where clipping at 0 lifts the noise's lower half, would otherwise be
    /// under-estimated and its subtraction leave a positive bias in every bin.
    ///
    /// With noise, e = k + σ_e z with k ~ Poisson(pe), z ~ N(0, 1), and c = clip(round(o + g e)),
    /// so E[c | k] = Σ_{m=1}^{sat} P(o + g e ≥ m − ½) = Σ_m Φ((o + g k − m + ½) / (g σ_e)),
    /// summed over k's distribution (a Gaussian of variance pe + σ_e² when pe is large, where
    /// the sum over k would take thousands of terms).
    pub fn expected_sample(&self, pe: f64) -> f64 {
        let Some(d) = &self.digitiser else {
            // Poisson and Gaussian noise have mean 0 about pe: no bias without a digitiser
            return pe;
        };
        let Some(sd) = self.electronic_sd else {
            // without noise the record is the mean waveform, digitised
            return self.digitise(pe);
        };
        let sat = d.saturation();
        // E[clip(round(a + b z))] for z ~ N(0, 1): levels far below a - 9b all count, those
        // far above none
        let mean_of = |a: f64, b: f64| -> f64 {
            if b <= 0.0 {
                return (a.round()).clamp(0.0, sat);
            }
            let lo = (a - 9.0 * b).floor().max(1.0);
            let hi = (a + 9.0 * b).ceil().min(sat);
            let mut e = (lo - 1.0).clamp(0.0, sat);
            let mut m = lo;
            while m <= hi {
                e += super::normal_cdf((a - m + 0.5) / b);
                m += 1.0;
            }
            e
        };
        let pe = pe.max(0.0);
        if pe > 100.0 {
            return mean_of(d.offset + d.gain * pe, d.gain * (pe + sd * sd).sqrt());
        }
        // Poisson weights from k = 0 up, to 12 standard deviations past the mean
        let top = (pe + 12.0 * pe.sqrt() + 20.0).ceil() as u64;
        let mut p = (-pe).exp();
        let mut e = 0.0;
        for k in 0..=top {
            if k > 0 {
                p *= pe / k as f64;
            }
            e += p * mean_of(d.offset + d.gain * k as f64, d.gain * sd);
        }
        e
    }

    /// Variance of each bin of [`Recorder::laser_photoelectrons`] besides the laser's own shot
    /// noise, photoelectrons² (the detector's own units, where that shot noise is Poisson:
    /// variance equal to the mean): electronic noise and the background's shot noise when the
    /// record is noisy, the digitiser's rounding (a uniform error of one count) when there is
    /// one; 0 for the mean waveform.
    pub fn noise_floor_photoelectrons(&self, w: &Waveform) -> f64 {
        let mut pe = 0.0;
        if let Some(sd) = self.electronic_sd {
            pe += sd * sd + self.mean_photoelectrons_background(w);
        }
        if let Some(d) = &self.digitiser {
            pe += 1.0 / (12.0 * d.gain * d.gain);
        }
        pe
    }

    /// Mean background (solar and dark) photoelectrons per bin.
    fn mean_photoelectrons_background(&self, w: &Waveform) -> f64 {
        self.quantum_efficiency * w.solar_photons_per_bin.max(0.0) as f64
            + self.dark_count_hz * w.bin_ns as f64 * 1e-9
    }

    /// The laser photoelectrons in a record, background removed: what the decomposition sees
    /// of a noisy record, in the units whose shot noise is Poisson (divided by q, a signal of
    /// L photons would have the variance L / q, not L). Samples below the background stay
    /// negative.
    pub fn laser_photoelectrons(&self, r: &Record) -> Vec<f32> {
        let (gain, offset) = self
            .digitiser
            .as_ref()
            .map_or((1.0, 0.0), |d| (d.gain, d.offset));
        let bg_pe = (r.background - offset) / gain;
        r.samples
            .iter()
            .map(|&c| ((c as f64 - offset) / gain - bg_pe) as f32)
            .collect()
    }
}

/// The transmitted pulse as the instrument records it: the fraction of the pulse's energy in
/// each bin of width `bin_s`, over ±4σ about the peak (normalised to 1) (one bin for a pulse shorter than a
/// bin's fraction).
pub fn transmitted_pulse(pulse_sigma_s: f64, bin_s: f64) -> Vec<f32> {
    let s = pulse_sigma_s / bin_s;
    if s.is_nan() || s <= 0.05 {
        return vec![1.0];
    }
    let half = (4.0 * s).ceil() as i64;
    let cdf = |x: f64| super::normal_cdf(x / s);
    let w: Vec<f64> = (-half..=half)
        .map(|k| cdf(k as f64 + 0.5) - cdf(k as f64 - 0.5))
        .collect();
    let total: f64 = w.iter().sum();
    w.iter().map(|&x| (x / total) as f32).collect()
}

/// Standard normal variate (Box–Muller).
fn normal(rng: &mut SplitMix64) -> f64 {
    let (u, v) = (rng.uniform_pos(), rng.uniform());
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// `v` convolved with a unit-sum Gaussian of σ `sigma_bins` (bin-integrated, ±4σ);
/// unchanged for σ ≤ 0.
fn convolve_gaussian(v: &[f64], sigma_bins: f64) -> Vec<f64> {
    if sigma_bins.is_nan() || sigma_bins <= 0.0 || v.is_empty() {
        return v.to_vec();
    }
    let reach = (4.0 * sigma_bins).ceil();
    let cdf = |x: f64| super::normal_cdf(x / sigma_bins);
    // taps further than the record is long never land in it (a response of 10^9 ns would ask
    // for a 54 GB kernel); its ±4σ mass is then taken whole from Φ
    let half = if reach < v.len() as f64 {
        reach as usize
    } else {
        v.len()
    };
    let mut kernel: Vec<f64> = (0..=2 * half)
        .map(|j| {
            let d = j as f64 - half as f64;
            cdf(d + 0.5) - cdf(d - 0.5)
        })
        .collect();
    // the tails beyond ±4σ folded back in: the response keeps the energy
    let total: f64 = if half as f64 == reach {
        kernel.iter().sum()
    } else {
        cdf(reach + 0.5) - cdf(-reach - 0.5)
    };
    kernel.iter_mut().for_each(|k| *k /= total);
    let mut out = vec![0.0; v.len()];
    for (i, &x) in v.iter().enumerate().filter(|(_, &x)| x != 0.0) {
        for (j, &k) in kernel.iter().enumerate() {
            if let Some(o) = (i + j).checked_sub(half).and_then(|t| out.get_mut(t)) {
                *o += x * k;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata::most_outside_3se;

    /// A response whose ±4σ is longer than the record is cut to the record's length: the same
    /// values as the whole kernel, whose taps beyond the record land nowhere (to 1e-12, the
    /// kernel's sum then being Φ's difference instead of its taps' sum).
    #[test]
    fn a_response_longer_than_the_record_gives_the_whole_kernels_values() {
        let v: Vec<f64> = (0..12).map(|i| ((i * 7) % 5) as f64).collect();
        let sigma: f64 = 5.0;
        let got = convolve_gaussian(&v, sigma);
        let half = (4.0 * sigma).ceil() as usize;
        let cdf = |x: f64| crate::waveform::normal_cdf(x / sigma);
        let kernel: Vec<f64> = (0..=2 * half)
            .map(|j| cdf(j as f64 - half as f64 + 0.5) - cdf(j as f64 - half as f64 - 0.5))
            .collect();
        let total: f64 = kernel.iter().sum();
        for (t, g) in got.iter().enumerate() {
            let want: f64 = (0..v.len())
                .map(|i| v[i] * kernel[t + half - i] / total)
                .sum();
            assert!(
                (g - want).abs() <= 1e-12 * want.abs().max(1e-300),
                "{t}: {g} against {want}"
            );
        }
    }

    fn recorder() -> Recorder {
        Recorder {
            quantum_efficiency: 1.0,
            dark_count_hz: 0.0,
            response_sigma_s: 0.0,
            electronic_sd: None,
            digitiser: None,
            seed: 7,
        }
    }

    #[test]
    fn digitiser_rounds_offsets_and_saturates_exactly() {
        let mut r = recorder();
        r.digitiser = Some(Digitiser {
            gain: 2.5,
            offset: 10.0,
            bits: 4,
            saturation: None,
        });
        // 10 + 2.5 pe, rounded half away from zero, clipped to 15 (2^4 - 1)
        let expected = [
            (0.0, 10.0),
            (0.19, 10.0),
            (0.21, 11.0),
            (1.0, 13.0),
            (1.9, 15.0),
        ];
        for (pe, c) in expected {
            assert_eq!(r.digitise(pe), c, "{pe} photoelectrons");
        }
        assert_eq!(r.digitise(1e9), 15.0);
        assert_eq!(r.digitise(-100.0), 0.0);
        r.digitiser.as_mut().unwrap().saturation = Some(12.0);
        assert_eq!(r.digitise(1.0), 12.0);
    }

    #[test]
    fn response_keeps_the_energy_and_widens_the_pulse() {
        let mut v = vec![0.0; 101];
        v[50] = 1.0;
        let out = convolve_gaussian(&v, 3.0);
        assert!((out.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        let var: f64 = out
            .iter()
            .enumerate()
            .map(|(i, &x)| x * (i as f64 - 50.0).powi(2))
            .sum();
        // bin-integrated Gaussian: σ² + 1/12, less the tails beyond ±4σ (0.1 % of σ²)
        assert!((var - (9.0 + 1.0 / 12.0)).abs() < 0.02, "{var}");
    }

    /// The mean of 10,000 noisy records of one pulse equals the mean waveform within 3 SE per
    /// bin: no more bins outside 3 SE than chance allows ([`most_outside_3se`]), none
    /// outside 5 SE (a chance of 6e-7 per bin).
    #[test]
    fn mean_of_noisy_records_is_the_mean_waveform() {
        let bins = 200;
        let laser: Vec<f32> = (0..bins)
            .map(|k| 40.0 * (-0.5 * ((k as f32 - 80.0) / 3.0).powi(2)).exp())
            .collect();
        let w = Waveform {
            pulse_id: 0,
            t0_ns: 0.0,
            bin_ns: 1.0,
            laser_photons: laser,
            solar_photons_per_bin: 0.8,
            ..Waveform::default()
        };
        let mut r = recorder();
        r.quantum_efficiency = 0.5;
        r.dark_count_hz = 2e8;
        r.electronic_sd = Some(1.5);
        r.response_sigma_s = 2e-9;
        let (laser, bg) = r.mean_photoelectrons(&w);
        let n = 10_000usize;
        let (mut sum, mut sum2) = (vec![0.0f64; bins], vec![0.0f64; bins]);
        for id in 0..n as u64 {
            let rec = r.record(&Waveform {
                pulse_id: id,
                ..w.clone()
            });
            for (k, &x) in rec.samples.iter().enumerate() {
                sum[k] += x as f64;
                sum2[k] += (x as f64).powi(2);
            }
        }
        let mut outside = 0;
        for k in 0..bins {
            let mean = sum[k] / n as f64;
            let var = (sum2[k] / n as f64 - mean * mean) * n as f64 / (n - 1) as f64;
            let se = (var / n as f64).sqrt();
            let z = (mean - (laser[k] + bg)).abs() / se;
            assert!(
                z < 5.0,
                "bin {k}: mean {mean}, expected {}, se {se}",
                laser[k] + bg
            );
            outside += usize::from(z > 3.0);
        }
        assert!(
            outside <= most_outside_3se(bins),
            "{outside} bins outside 3 SE"
        );
    }

    /// Where no laser light falls, the recorded laser photons vary by the noise floor the
    /// decomposition is told of: electronic noise, the background's shot noise and the
    /// digitiser's rounding, over q². Checked on 10^5 bins against the sample variance,
    /// within 4 of its standard errors (√(2/n) of it, the excess kurtosis of these sums being
    /// small).
    #[test]
    fn the_noise_floor_is_the_variance_of_a_bin_without_signal() {
        let bins = 200;
        let w = Waveform {
            pulse_id: 0,
            bin_ns: 1.0,
            laser_photons: vec![0.0; bins],
            solar_photons_per_bin: 3.0,
            ..Waveform::default()
        };
        let mut r = recorder();
        r.quantum_efficiency = 0.5;
        r.dark_count_hz = 1e9;
        r.electronic_sd = Some(1.5);
        r.digitiser = Some(Digitiser {
            gain: 4.0,
            offset: 100.0,
            bits: 14,
            saturation: None,
        });
        let (mut n, mut sum, mut sum2) = (0.0f64, 0.0f64, 0.0f64);
        for id in 0..500u64 {
            let rec = r.record(&Waveform {
                pulse_id: id,
                ..w.clone()
            });
            // in photons at the detector: photoelectrons over q
            for v in r.laser_photoelectrons(&rec) {
                let v = v as f64 / r.quantum_efficiency;
                n += 1.0;
                sum += v;
                sum2 += v.powi(2);
            }
        }
        let mean = sum / n;
        let var = (sum2 / n - mean * mean) * n / (n - 1.0);
        let floor = r.noise_floor_photoelectrons(&w) / r.quantum_efficiency.powi(2);
        // (1.5² + 0.5 × 3 + 1) / 0.5² + (1 / (12 × 16)) / 0.5²
        let want = (2.25 + 2.5 + 1.0 / 192.0) / 0.25;
        assert!((floor - want).abs() < 1e-12, "{floor} vs {want}");
        let se = var * (2.0 / n).sqrt();
        assert!(
            (var - floor).abs() < 4.0 * se,
            "sample variance {var}, floor {floor}, se {se}"
        );
        assert!(mean.abs() < 4.0 * (var / n).sqrt(), "mean {mean}");
        r.electronic_sd = None;
        r.digitiser = None;
        assert_eq!(r.noise_floor_photoelectrons(&w), 0.0);
    }

    #[test]
    fn records_go_back_to_laser_photons() {
        let w = Waveform {
            pulse_id: 3,
            bin_ns: 1.0,
            laser_photons: vec![0.0, 4.0, 100.0, 4.0, 0.0],
            solar_photons_per_bin: 2.0,
            ..Waveform::default()
        };
        let mut r = recorder();
        r.quantum_efficiency = 0.25;
        r.dark_count_hz = 1e9;
        r.digitiser = Some(Digitiser {
            gain: 4.0,
            offset: 3.0,
            bits: 12,
            saturation: None,
        });
        let rec = r.record(&w);
        // noise off: only the rounding of the counts is lost, at most half a count
        let q = r.quantum_efficiency as f32;
        let photons = r.laser_photoelectrons(&rec).into_iter().map(|v| v / q);
        for (got, want) in photons.zip(&w.laser_photons) {
            assert!(
                (got - want).abs() <= 0.5 / (4.0 * 0.25) + 1e-4,
                "{got} vs {want}"
            );
        }
        assert!((rec.background - (3.0 + 4.0 * (0.25 * 2.0 + 1.0))).abs() < 1e-12);
    }

    /// The background the record's laser photons are taken from is the mean of a sample with
    /// no laser signal, clipping and rounding included: over 200,000 noise-only samples (a
    /// digitiser whose offset sits near 0, where clipping at 0 bends the mean; and one whose
    /// saturation clips the top), their mean is the estimate within 3 SE; with no noise it is
    /// the digitised background exactly.
    #[test]
    fn background_estimate_is_the_mean_of_noise_only_samples() {
        for (offset, gain, bits, sd, solar) in [
            (0.5, 1.0, 12, 2.0, 0.3),
            (1.0, 2.0, 12, 1.5, 2.0),
            (3.0, 4.0, 4, 1.0, 1.5),
            (0.0, 0.7, 10, 3.0, 150.0),
            (0.0, 0.7, 10, 3.0, 400.0),
        ] {
            let mut r = recorder();
            r.quantum_efficiency = 0.5;
            r.electronic_sd = Some(sd);
            r.digitiser = Some(Digitiser {
                gain,
                offset,
                bits,
                saturation: None,
            });
            let bins = 2000;
            let w = Waveform {
                bin_ns: 1.0,
                laser_photons: vec![0.0; bins],
                solar_photons_per_bin: solar,
                ..Waveform::default()
            };
            let (mut sum, mut sum2, mut n) = (0.0f64, 0.0f64, 0.0f64);
            let mut background = 0.0;
            for id in 0..100u64 {
                let rec = r.record(&Waveform {
                    pulse_id: id,
                    ..w.clone()
                });
                background = rec.background;
                for &c in &rec.samples {
                    sum += c as f64;
                    sum2 += (c as f64).powi(2);
                    n += 1.0;
                }
            }
            let mean = sum / n;
            let se = ((sum2 / n - mean * mean) / n).sqrt();
            assert!(
                (mean - background).abs() < 3.0 * se,
                "offset {offset}, gain {gain}, {bits} bits, sd {sd}, solar {solar}: mean {mean} \
                 against the estimate {background} (SE {se})"
            );
        }
        let mut r = recorder();
        r.digitiser = Some(Digitiser {
            gain: 2.0,
            offset: 0.2,
            bits: 8,
            saturation: None,
        });
        assert_eq!(r.expected_sample(1.3), r.digitise(1.3));
    }

    #[test]
    fn transmitted_pulse_sums_to_one() {
        let tx = transmitted_pulse(1.5e-9, 1e-9);
        assert!((tx.iter().map(|&x| x as f64).sum::<f64>() - 1.0).abs() < 1e-5);
        assert_eq!(tx.len() % 2, 1);
        assert_eq!(transmitted_pulse(0.0, 1e-9), vec![1.0]);
    }
}
