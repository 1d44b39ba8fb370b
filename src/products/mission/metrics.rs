//! Waveform metrics as GEDI's L2A gives them (ground as the lowest mode, RH0-RH100), found in
//! one stated way, in the style of a GEDI L2A setting group and of gediMetric:
//!
//! 1. y = the record less its noise mean, in photoelectrons (shot noise Poisson), σ_n the sd
//!    of a sample without signal.
//! 2. s = y through the discrete returns' matched filter (a Gaussian of the return's σ: the
//!    pulse's and the detector's in quadrature).
//! 3. The threshold T is the discrete returns' detection level: the level that a gate of
//!    noise alone crosses with the campaign's `false_alarm_rate` (docs/outputs.md); a record
//!    without noise (σ_n = 0) takes [`NOISELESS_FRACTION`] of s's peak instead. The truth (the
//!    noise-free mean waveform of a noisy record) takes the record's T: the same metrics, the
//!    noise's own effect aside.
//! 4. The signal spans the first to the last sample with s > T: its start is the highest
//!    return, its end the lowest. Modes are the local maxima of s above T within it, two of
//!    them distinct only where s dips by more than T below both between them (else the
//!    higher stands); the lowest mode (the last in time) is the ground.
//! 5. RH_p is the height above the ground at which the energy of y over the signal, summed
//!    from its end upwards, first reaches p % (linear within a sample): RH0 is the signal's
//!    end, RH100 its start. y is not clipped at 0: the noise then adds nothing to the energy
//!    on average (clipped, its positive half lifts RH98 by a fifth of a metre in the roof
//!    test of tests/mission.rs).
//! 6. sensitivity = 1 − A_min / E, E the signal's energy, A_min the area of the weakest
//!    return whose filtered summit reaches T (a Gaussian of σ_r: the filter keeps √½ of its
//!    summit, so A_min = T √2 √(2π) σ_r): the canopy cover up to which a ground as bright as the canopy
//!    is still found, GEDI's meaning of beam sensitivity. `quality_flag` needs ≥ 0.9 (GEDI's
//!    over land).

use crate::products::returns::alarm::{alarm_level, matched};

/// The threshold of a record without noise, as a fraction of its smoothed peak.
pub const NOISELESS_FRACTION: f64 = 0.01;
/// The sensitivity below which a shot's quality flag is 0 (GEDI's over land).
pub const MIN_SENSITIVITY: f64 = 0.9;

/// GEDI's `quality_flag`: a ground found, the sensitivity at least [`MIN_SENSITIVITY`], and
/// the mean waveform reaching the detection threshold (`stale` false).
pub fn quality(found: Option<&Metrics>, stale: bool) -> bool {
    found.is_some_and(|m| m.sensitivity >= MIN_SENSITIVITY && !stale)
}

/// A shot's metrics, positions in fractional samples (sample k's centre at k).
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    /// The lowest mode (the ground).
    pub ground: f64,
    /// Signal start and end: the highest and the lowest return.
    pub top: f64,
    pub bottom: f64,
    pub modes: u8,
    /// RH0-RH100 as positions.
    pub rh: [f64; 101],
    pub sensitivity: f64,
}

/// The metrics of `y` (photoelectrons, noise mean removed) with noise sd `sigma_n`, return σ
/// `sigma_r` (bins) and false-alarm rate `alpha`; `None` when no sample exceeds the threshold.
pub fn metrics(y: &[f64], sigma_n: f64, sigma_r: f64, alpha: f64) -> Option<Metrics> {
    let s = matched(y, sigma_r);
    let peak = s.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let t = if sigma_n > 0.0 {
        alarm_level(y.len(), sigma_r, sigma_n * sigma_n, alpha, 0.0)
    } else {
        NOISELESS_FRACTION * peak
    };
    if peak.is_nan() || peak <= t || peak <= 0.0 {
        return None;
    }
    let above = |k: usize| s[k] > t;
    let first = (0..s.len()).find(|&k| above(k))?;
    let last = (0..s.len()).rev().find(|&k| above(k))?;
    // local maxima above T; two are distinct modes only if s dips by more than T below each
    // between them (a noise ripple on one return is not a second), else the higher stands
    let mut modes: Vec<usize> = Vec::new();
    for k in first..=last {
        let left = if k > 0 { s[k - 1] } else { f64::NEG_INFINITY };
        let right = s.get(k + 1).copied().unwrap_or(f64::NEG_INFINITY);
        if !(above(k) && s[k] >= left && s[k] > right) {
            continue;
        }
        match modes.last_mut() {
            None => modes.push(k),
            Some(m) => {
                let dip = s[*m..=k].iter().cloned().fold(f64::INFINITY, f64::min);
                if s[*m] - dip > t && s[k] - dip > t {
                    modes.push(k);
                } else if s[k] > s[*m] {
                    *m = k;
                }
            }
        }
    }
    let ground = refine(&s, *modes.last()?);
    // energy from the signal's end upwards: sample k holds [k - ½, k + ½]
    let e = &y[first..=last];
    let total: f64 = e.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    let mut rh = [0.0; 101];
    let mut cum = 0.0;
    let mut k = e.len();
    for (p, slot) in rh.iter_mut().enumerate() {
        let want = total * p as f64 / 100.0;
        while k > 0 && cum + e[k - 1] < want {
            cum += e[k - 1];
            k -= 1;
        }
        *slot = if p == 0 {
            last as f64
        } else if p == 100 || k == 0 {
            first as f64
        } else {
            // within sample k - 1, filled from its lower edge (k - 1 + ½) upwards
            let f = if e[k - 1] > 0.0 {
                ((want - cum) / e[k - 1]).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (first + k - 1) as f64 + 0.5 - f
        };
    }
    let a_min = t * 2f64.sqrt() * (2.0 * std::f64::consts::PI).sqrt() * sigma_r.max(0.5);
    Some(Metrics {
        ground,
        top: first as f64,
        bottom: last as f64,
        modes: modes.len().min(255) as u8,
        rh,
        sensitivity: (1.0 - a_min / total).clamp(0.0, 1.0),
    })
}

/// The vertex of the parabola through a maximum and its neighbours.
fn refine(s: &[f64], k: usize) -> f64 {
    if k == 0 || k + 1 >= s.len() {
        return k as f64;
    }
    let (a, b, c) = (s[k - 1], s[k], s[k + 1]);
    let d = a - 2.0 * b + c;
    if d < 0.0 {
        k as f64 + 0.5 * (a - c) / d
    } else {
        k as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gaussian(n: usize, at: f64, sigma: f64, area: f64) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let d = (k as f64 - at) / sigma;
                area * (-0.5 * d * d).exp() / (sigma * (2.0 * std::f64::consts::PI).sqrt())
            })
            .collect()
    }

    /// One Gaussian return: the ground is its centre, RH50 is at the centre and RH_p at the
    /// Gaussian's quantile, within a tenth of a sample.
    #[test]
    fn one_return_gives_its_centre_and_quantiles() {
        let y = gaussian(200, 120.3, 4.0, 1000.0);
        let m = metrics(&y, 0.5, 4.0, 1e-3).expect("a return");
        assert_eq!(m.modes, 1);
        assert!((m.ground - 120.3).abs() < 0.05, "ground {}", m.ground);
        assert!((m.rh[50] - 120.3).abs() < 0.1, "rh50 {}", m.rh[50]);
        // RH_p above the ground: the (1 - p) quantile in time, as time runs downwards
        let z84 = 0.994_457_883;
        assert!(
            (m.rh[84] - (120.3 - z84 * 4.0)).abs() < 0.15,
            "rh84 {}",
            m.rh[84]
        );
        assert!(m.rh.windows(2).all(|w| w[1] <= w[0]), "RH rises");
        assert!(m.sensitivity > 0.9 && m.sensitivity < 1.0);
    }

    /// Canopy over ground: two modes, the ground the later one; RH98 near the canopy's top.
    #[test]
    fn canopy_over_ground_takes_the_lower_mode() {
        let canopy = gaussian(300, 100.0, 4.0, 600.0);
        let ground = gaussian(300, 160.0, 4.0, 400.0);
        let y: Vec<f64> = canopy.iter().zip(&ground).map(|(a, b)| a + b).collect();
        let m = metrics(&y, 0.3, 4.0, 1e-3).expect("returns");
        assert_eq!(m.modes, 2);
        assert!((m.ground - 160.0).abs() < 0.05);
        assert!(m.rh[98] < 100.0 && m.rh[98] > 90.0, "rh98 {}", m.rh[98]);
        assert!(m.rh[10] > 150.0);
    }

    /// Noise alone below the threshold: no metrics.
    #[test]
    fn nothing_above_the_threshold_is_no_signal() {
        let y = vec![0.1; 100];
        assert_eq!(metrics(&y, 1.0, 3.0, 1e-3), None);
        assert_eq!(metrics(&[0.0; 50], 0.0, 3.0, 1e-3), None);
    }
}
