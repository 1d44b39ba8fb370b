//! Peak detection: the returns' seeds (and, for `Decomposition::PeakDetection`, the returns).

use super::{Component, COLLAPSED_SIGMA};

/// Smoothing width for detection: wide enough that Poisson noise on a broad return does not
/// split it into several maxima, narrow enough not to merge returns 3σ apart.
pub(super) fn smoothing_sigma(hint: f64) -> f64 {
    (0.5 * hint).max(0.7)
}

/// The waveform convolved with a Gaussian of `sigma` bins (±3σ, normalised by the kernel's
/// weight inside the waveform). A bin whose window holds no non-zero value is 0 without being
/// summed: most of a long waveform is empty gate, whose sums would be most of the products
/// stage's time on long waveforms. Every other bin is summed in the same order as the dense
/// sum, so the result is the same to the bit.
pub(super) fn smooth(y: &[f64], sigma: f64) -> Vec<f64> {
    let n = y.len();
    let mut out = vec![0.0; n];
    // Only bins within reach of the first and last non-zero values can have one in their
    // window: the gate's empty ends are not looked at bin by bin.
    let Some(first) = y.iter().position(|&v| v != 0.0) else {
        return out;
    };
    let last = y.iter().rposition(|&v| v != 0.0).unwrap_or(first);
    SMOOTHING.with_borrow_mut(|k| {
        k.set(sigma);
        let Smoothing {
            reach,
            kernel,
            full,
            full_weight,
            nonzero,
            ..
        } = k;
        let (reach, full_weight) = (*reach, *full_weight);
        // nonzero[i]: how many of y[first..first + i] are not zero (none lies outside them)
        nonzero.clear();
        nonzero.push(0u32);
        for &v in &y[first..=last] {
            let seen = *nonzero.last().unwrap_or(&0);
            nonzero.push(seen + u32::from(v != 0.0));
        }
        let count_before = |i: usize| nonzero[i.clamp(first, last + 1) - first];
        let from = first.saturating_sub(reach);
        let to = (last + reach).min(n - 1);
        for (i, o) in out.iter_mut().enumerate().take(to + 1).skip(from) {
            let lo = i.saturating_sub(reach);
            let hi = (i + reach).min(n - 1);
            if count_before(hi + 1) == count_before(lo) {
                continue; // k * ±0 summed from +0 is +0, and +0 / w is +0: what `out` holds
            }
            if hi - lo == 2 * reach {
                let acc = y[lo..=hi]
                    .iter()
                    .zip(full.iter())
                    .fold(0.0, |acc, (&v, &k)| acc + k * v);
                *o = acc / full_weight;
                continue;
            }
            let (mut acc, mut w) = (0.0, 0.0);
            for (j, &v) in y.iter().enumerate().take(hi + 1).skip(lo) {
                let k = kernel[i.abs_diff(j)];
                acc += k * v;
                w += k;
            }
            *o = acc / w;
        }
    });
    out
}

/// [`smooth`]'s kernel for one sigma, kept by each thread with its scratch: a waveform's
/// smoothings share one sigma, whose weights (an exponential each) and buffers, made afresh
/// for each call, were a measurable share of the products stage.
#[derive(Default)]
struct Smoothing {
    /// The bits of the sigma the kernel is for; None before the first.
    sigma: Option<u64>,
    reach: usize,
    /// Weight of a neighbour k bins away, k = 0..=reach.
    kernel: Vec<f64>,
    /// The whole kernel, -reach..=reach, for a window inside the waveform, and its weight,
    /// summed once in the order each such bin's sum would take.
    full: Vec<f64>,
    full_weight: f64,
    /// Scratch: counts of non-zero values.
    nonzero: Vec<u32>,
}

impl Smoothing {
    /// The kernel of `sigma`, made only when it is not the one kept: the same values, so the
    /// same bits.
    fn set(&mut self, sigma: f64) {
        if self.sigma == Some(sigma.to_bits()) {
            return;
        }
        let reach = (3.0 * sigma).ceil() as usize;
        self.kernel.clear();
        self.kernel
            .extend((0..=reach).map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp()));
        // A bin whose window lies wholly inside the waveform sums the whole kernel, in the
        // same order every time: its weight is summed once, and its sum runs over a slice of
        // fixed length without an index to check (half the work of the edge bins' loop, the
        // same sums in the same order, so the same bits).
        self.full.clear();
        let kernel = &self.kernel;
        self.full
            .extend((0..=2 * reach).map(|t| kernel[t.abs_diff(reach)]));
        self.full_weight = self.full.iter().fold(0.0, |w, &k| w + k);
        self.reach = reach;
        self.sigma = Some(sigma.to_bits());
    }
}

thread_local! {
    static SMOOTHING: std::cell::RefCell<Smoothing> = std::cell::RefCell::default();
}

/// Peak detection: local maxima of the lightly smoothed waveform, merged when the dip
/// between two is within Poisson noise, kept when the raw summit exceeds the threshold.
///
/// One pass over the smoothed waveform: maxima found, merged and refined as they come.
pub(super) fn detect_peaks(y: &[f64], threshold: f64, hint: f64) -> Vec<Component> {
    let n = y.len();
    if n == 0 {
        return Vec::new();
    }
    let sk = smoothing_sigma(hint);
    let s = smooth(y, sk);
    // Standard deviation of smoothed Poisson noise per √(count).
    let noise_gain = 1.0 / (2.0 * std::f64::consts::PI.sqrt() * sk).sqrt();
    let mut maxima: Vec<usize> = Vec::new();
    let mut i = 0;
    while i < n {
        // A plateau counts once, at its first bin.
        let mut j = i;
        while j + 1 < n && s[j + 1] == s[i] {
            j += 1;
        }
        let left_lower = i == 0 || s[i - 1] < s[i];
        let right_lower = j + 1 == n || s[j + 1] < s[i];
        if left_lower && right_lower && s[i] > 0.0 {
            maxima.push(i);
        }
        i = j + 1;
    }
    // Merge maxima separated by a dip smaller than the noise, lowest dip first.
    loop {
        let mut worst: Option<(f64, usize)> = None;
        for k in 0..maxima.len().saturating_sub(1) {
            let (p, q) = (maxima[k], maxima[k + 1]);
            let valley = s[p..=q].iter().cloned().fold(f64::INFINITY, f64::min);
            let low = s[p].min(s[q]);
            let tol = 2.0 * noise_gain * low.sqrt();
            let dip = (low - valley) / tol.max(1e-300);
            if dip < 1.0 && worst.is_none_or(|(d, _)| dip < d) {
                worst = Some((dip, k));
            }
        }
        match worst {
            Some((_, k)) => {
                let drop = if s[maxima[k]] < s[maxima[k + 1]] {
                    k
                } else {
                    k + 1
                };
                maxima.remove(drop);
            }
            None => break,
        }
    }
    let mut out = Vec::new();
    for (k, &m) in maxima.iter().enumerate() {
        // The raw summit near the smoothed one carries the parabola.
        let lo = m.saturating_sub(1);
        let hi = (m + 1).min(n - 1);
        let j = (lo..=hi).fold(m, |b, i| if y[i] > y[b] { i } else { b });
        let (delta, peak) = parabola(y, j);
        if peak <= threshold {
            continue;
        }
        // Valleys: the minimum between neighbouring maxima, or where the signal stops
        // falling beyond the outermost ones.
        let left = if k > 0 {
            argmin(&s, maxima[k - 1], m) + 1
        } else {
            let mut l = m;
            while l > 0 && s[l - 1] < s[l] && s[l - 1] > 0.0 {
                l -= 1;
            }
            if l > 0 && s[l - 1] == 0.0 {
                l -= 1;
            }
            l
        };
        let right = if k + 1 < maxima.len() {
            argmin(&s, m, maxima[k + 1])
        } else {
            let mut r = m;
            while r + 1 < n && s[r + 1] < s[r] {
                r += 1;
            }
            r
        };
        let area: f64 = y[left..=right.max(left)].iter().sum();
        let sigma = (area / (peak * (2.0 * std::f64::consts::PI).sqrt()))
            .max(hint)
            .max(COLLAPSED_SIGMA);
        out.push(Component {
            centre_bin: j as f64 + 0.5 + delta,
            sigma_bins: sigma,
            area_photons: area,
            amplitude: peak,
            one_surface: false,
        });
    }
    out
}

fn argmin(s: &[f64], a: usize, b: usize) -> usize {
    (a..=b).fold(a, |m, i| if s[i] < s[m] { i } else { m })
}

/// Vertex of the parabola through ln y of bins j-1, j, j+1 (exact for a sampled Gaussian);
/// the plain parabola when a neighbour is empty. Returns (offset from the bin's middle,
/// summit height).
pub(super) fn parabola(y: &[f64], j: usize) -> (f64, f64) {
    let b = y[j];
    if j == 0 || j + 1 >= y.len() {
        return (0.0, b);
    }
    let (a, c) = (y[j - 1], y[j + 1]);
    if a > 0.0 && b > 0.0 && c > 0.0 {
        let (la, lb, lc) = (a.ln(), b.ln(), c.ln());
        let den = la - 2.0 * lb + lc;
        if den < 0.0 {
            let d = (0.5 * (la - lc) / den).clamp(-0.5, 0.5);
            return (d, (lb - 0.25 * (la - lc) * d).exp());
        }
    }
    let den = a - 2.0 * b + c;
    if den < 0.0 {
        let d = (0.5 * (a - c) / den).clamp(-0.5, 0.5);
        return (d, b - 0.25 * (a - c) * d);
    }
    (0.0, b)
}
