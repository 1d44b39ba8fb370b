//! The solver under the fit: Levenberg-Marquardt on a window's Poisson deviance, with Fisher
//! scoring for the curvature and a dense Cholesky solve for the step.

use super::fit::{pdf, Params, Window};

impl Window<'_> {
    /// Levenberg-Marquardt on the Poisson deviance: gradient Σ (1 - y/m) ∂m/∂θ and the
    /// Fisher information Σ ∂m/∂θ ∂m/∂θᵀ / m as the curvature. Returns the parameters
    /// and the deviance, or None if nothing finite came out.
    /// At most `iterations` steps: the third value says whether the fit stopped at that
    /// limit rather than converged.
    pub(super) fn fit(
        &self,
        params: Vec<Params>,
        floor: f64,
        iterations: usize,
    ) -> Option<(Vec<Params>, f64, bool)> {
        BUFFERS.with_borrow_mut(|b| self.fit_in(params, floor, iterations, b))
    }

    /// [`Window::fit`] in a thread's buffers.
    fn fit_in(
        &self,
        mut params: Vec<Params>,
        floor: f64,
        iterations: usize,
        b: &mut Buffers,
    ) -> Option<(Vec<Params>, f64, bool)> {
        let np = 3 * params.len();
        let Buffers {
            edges,
            model: m,
            jac,
            h,
            g,
            trial,
        } = b;
        // the bin integrals of the current parameters, from the model that was made with them
        self.model_keeping(&params, edges, m);
        let mut dev = self.deviance(m);
        if !dev.is_finite() {
            return None;
        }
        let mut lambda = 1e-3;
        // each is written whole before it is read
        jac.resize(self.y.len() * np, 0.0);
        h.resize(np * np, 0.0);
        g.resize(np, 0.0);
        trial.aug.resize(np * np, 0.0);
        trial.step.resize(np, 0.0);
        let (jac, h, g) = (
            &mut jac[..self.y.len() * np],
            &mut h[..np * np],
            &mut g[..np],
        );
        let mut capped = true;
        for _ in 0..iterations {
            self.jacobian(&params, edges, jac);
            self.scoring(jac, m, h, g);
            let dmax = (0..np).map(|a| h[a * np + a]).fold(0.0, f64::max);
            if !(dmax.is_finite() && dmax > 0.0) {
                return None;
            }
            // None: the next step is too small to mean anything, or no step goes downhill
            // (a minimum within float precision)
            let Some(td) = self.damped_step(&params, h, g, (dev, dmax, floor), &mut lambda, trial)
            else {
                capped = false;
                break;
            };
            let gain = dev - td;
            std::mem::swap(&mut params, &mut trial.params);
            std::mem::swap(m, &mut trial.model);
            std::mem::swap(edges, &mut trial.edges);
            dev = td;
            // A deviance gain of 1e-6 is a likelihood ratio of 1 + 5e-7. A model that cannot
            // fit (a canopy return is no Gaussian, and at 10^6 photons every bin says so)
            // keeps a deviance far above the bins' count and crawls along a valley, gaining
            // ~0.02 % an iteration for a hundred iterations: once a step removes less than
            // 0.1 % of that excess, further steps change nothing the fit can mean.
            let excess = dev - self.y.len() as f64;
            if gain < 1e-6 || gain < 1e-3 * excess {
                capped = false;
                break;
            }
        }
        Some((params, dev, capped))
    }

    /// ∂m_i/∂(centre, sigma, area) of every component over the bins it reaches (row-major,
    /// one row per bin): the model integrates each Gaussian over a bin, so the derivatives
    /// are differences of the normal pdf and cdf at the bin's edges. `masses` holds each
    /// component's bin integrals (differences of Φ), as the model at `params` computed them
    /// (see `Window::model_keeping`).
    fn jacobian(&self, params: &[Params], masses: &[f64], jac: &mut [f64]) {
        let np = 3 * params.len();
        let mut at = 0;
        for (c, p) in params.iter().enumerate() {
            let (a, b) = self.reach(p);
            // zero where the component does not reach, written below where it does (zeroing
            // the whole matrix first would be a measurable share of the fit's instructions)
            let (before, reached) = jac.split_at_mut(a * np);
            let after = &mut reached[(b - a) * np..];
            for row in before
                .chunks_exact_mut(np)
                .chain(after.chunks_exact_mut(np))
            {
                row[3 * c..3 * c + 3].fill(0.0);
            }
            let s = p[1];
            let mass = &masses[at..at + b - a];
            at += b - a;
            // φ from edge to edge, z rising by h = 1/σ: φ(z + h) = φ(z) e^(-z h) e^(-h²/2),
            // and e^(-z h) itself falls by e^(-h²) an edge, so three exponentials serve the
            // whole component instead of one per edge (the Jacobian's main cost after Φ);
            // the product's relative error grows by an ulp or two an edge. No division per
            // bin either: three of them a bin would be a measurable share of the products
            // stage, throughput-bound where everything else pipelines.
            let h = 1.0 / s;
            let area_h = p[2] * h;
            let mut zl = (self.offset + a as f64 - p[0]) * h;
            let mut pl = pdf(zl);
            let (half, full) = ((-0.5 * h * h).exp(), (-h * h).exp());
            let mut fall = (-zl * h).exp();
            let stepped = fall.is_finite();
            for (i, &mi) in (a..b).zip(mass) {
                let zh = (self.offset + (i + 1) as f64 - p[0]) * h;
                let ph = if stepped { pl * fall * half } else { pdf(zh) };
                fall *= full;
                let row = &mut jac[i * np + 3 * c..i * np + 3 * c + 3];
                row[0] = area_h * (pl - ph);
                row[1] = area_h * (pl * zl - ph * zh);
                row[2] = mi;
                zl = zh;
                pl = ph;
            }
        }
    }

    /// Fisher scoring: the Poisson deviance's half-gradient `g` = Σ (1 - y/m) J and its
    /// expected curvature `h` = Σ J Jᵀ / m (full symmetric matrix).
    fn scoring(&self, jac: &[f64], m: &[f64], h: &mut [f64], g: &mut [f64]) {
        // one and two components, most fits, with their sizes known to the compiler: its
        // loops unrolled and unchecked (the general loop's index checks are a measurable
        // share of the fit's time); the same sums in the same order, so the same bits
        match g.len() {
            3 => scoring_sized(3, &self.y, jac, m, h, g),
            6 => scoring_sized(6, &self.y, jac, m, h, g),
            np => scoring_sparse(np, &self.y, jac, m, h, g),
        }
    }

    /// The first damped step that does not raise the deviance `dev`, raising the damping
    /// `lambda` until one does (at most 12 tries) and lowering it after; None when none does,
    /// or when a step is too small to mean anything: then the fit has converged, and the
    /// step is not worth the model it would cost to try (most fits end with such a step,
    /// which float noise in the deviance could otherwise reject several times over).
    /// `dmax` is the largest diagonal of `h`, `floor` the least sigma. The step taken, its
    /// model and bin integrals are left in `trial`, and its deviance returned.
    fn damped_step(
        &self,
        params: &[Params],
        h: &[f64],
        g: &[f64],
        (dev, dmax, floor): (f64, f64, f64),
        lambda: &mut f64,
        trial: &mut Trial,
    ) -> Option<f64> {
        let np = g.len();
        for _ in 0..12 {
            let (aug, step) = (&mut trial.aug[..np * np], &mut trial.step[..np]);
            aug.copy_from_slice(h);
            for a in 0..np {
                aug[a * np + a] += *lambda * h[a * np + a].max(1e-12 * dmax);
            }
            for (s, v) in step.iter_mut().zip(g) {
                *s = -v;
            }
            if !cholesky_solve(aug, step, np) {
                *lambda *= 10.0;
                continue;
            }
            // Far below any statistical or geometric meaning: 1e-4 bin is 0.015 mm at 1 ns.
            let small = params.iter().enumerate().all(|(c, p)| {
                step[3 * c].abs() < 1e-4
                    && step[3 * c + 1].abs() < 1e-4 * p[1]
                    && step[3 * c + 2].abs() < 1e-5 * p[2].max(1.0)
            });
            if small {
                return None;
            }
            trial.params.clear();
            trial.params.extend(params.iter().enumerate().map(|(c, p)| {
                [
                    p[0] + step[3 * c],
                    (p[1] + step[3 * c + 1]).max(floor),
                    (p[2] + step[3 * c + 2]).max(1e-9),
                ]
            }));
            self.model_keeping(&trial.params, &mut trial.edges, &mut trial.model);
            let deviance = self.deviance(&trial.model);
            if deviance.is_finite() && deviance <= dev {
                *lambda = (*lambda / 3.0).max(1e-12);
                return Some(deviance);
            }
            *lambda *= 4.0;
        }
        None
    }
}

/// A thread's buffers for [`Window::fit`], kept from fit to fit: their ten vectors, allocated
/// for each fit, would be a measurable share of the products stage.
#[derive(Default)]
struct Buffers {
    /// Each component's bin integrals at the current parameters.
    edges: Vec<f64>,
    /// The model at the current parameters.
    model: Vec<f64>,
    jac: Vec<f64>,
    h: Vec<f64>,
    g: Vec<f64>,
    trial: Trial,
}

thread_local! {
    static BUFFERS: std::cell::RefCell<Buffers> = std::cell::RefCell::default();
}

/// A trial step of the solver: its parameters, model and bin integrals, and the buffers its
/// damped system is solved in.
#[derive(Default)]
struct Trial {
    params: Vec<Params>,
    model: Vec<f64>,
    edges: Vec<f64>,
    aug: Vec<f64>,
    step: Vec<f64>,
}

/// [`Window::scoring`] for `np` parameters, inlined into each call so that a constant `np`
/// sizes its loops.
#[inline(always)]
fn scoring_sized(np: usize, y: &[f64], jac: &[f64], m: &[f64], h: &mut [f64], g: &mut [f64]) {
    let (h, g) = (&mut h[..np * np], &mut g[..np]);
    h.fill(0.0);
    g.fill(0.0);
    for ((row, &yi), &mi) in jac.chunks_exact(np).zip(y).zip(m) {
        if row.iter().all(|&v| v == 0.0) {
            continue;
        }
        let w = 1.0 / mi;
        let r = 1.0 - yi * w;
        for a in 0..np {
            g[a] += r * row[a];
            let wa = w * row[a];
            if wa == 0.0 {
                continue;
            }
            let ha = &mut h[a * np..(a + 1) * np];
            for (hb, &jb) in ha[a..].iter_mut().zip(&row[a..]) {
                *hb += wa * jb;
            }
        }
    }
    for a in 0..np {
        for b in 0..a {
            h[a * np + b] = h[b * np + a];
        }
    }
}

/// Components [`scoring_sparse`] keeps apart at a bin; a fit of more is scored whole.
const SPARSE_COMPONENTS: usize = 16;

/// [`scoring_sized`] for three components or more, each bin's sums over the components that
/// reach it only: a bin far from a component has its three derivatives zero, and adding
/// their zero products would leave a fit of six components summing 171 products a bin to
/// find the few that are not (on a forest survey this solver is a large share of the
/// products stage). The products skipped are zeros, so the sums are the same to the bit.
fn scoring_sparse(np: usize, y: &[f64], jac: &[f64], m: &[f64], h: &mut [f64], g: &mut [f64]) {
    let nc = np / 3;
    if nc > SPARSE_COMPONENTS || !np.is_multiple_of(3) {
        return scoring_sized(np, y, jac, m, h, g);
    }
    let (h, g) = (&mut h[..np * np], &mut g[..np]);
    h.fill(0.0);
    g.fill(0.0);
    let mut active = [0usize; SPARSE_COMPONENTS];
    for ((row, &yi), &mi) in jac.chunks_exact(np).zip(y).zip(m) {
        let mut na = 0;
        for c in 0..nc {
            if row[3 * c..3 * c + 3].iter().any(|&v| v != 0.0) {
                active[na] = c;
                na += 1;
            }
        }
        if na == 0 {
            continue;
        }
        let w = 1.0 / mi;
        let r = 1.0 - yi * w;
        for (ia, &ca) in active[..na].iter().enumerate() {
            for a in 3 * ca..3 * ca + 3 {
                g[a] += r * row[a];
                let wa = w * row[a];
                if wa == 0.0 {
                    continue;
                }
                let ha = &mut h[a * np..(a + 1) * np];
                for b in a..3 * ca + 3 {
                    ha[b] += wa * row[b];
                }
                for &cb in &active[ia + 1..na] {
                    for b in 3 * cb..3 * cb + 3 {
                        ha[b] += wa * row[b];
                    }
                }
            }
        }
    }
    for a in 0..np {
        for b in 0..a {
            h[a * np + b] = h[b * np + a];
        }
    }
}

/// Solves A x = b in place for a symmetric positive definite A (row-major n×n).
fn cholesky_solve(a: &mut [f64], b: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i * n + k] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sparse sums skip only zero products: for components reaching a few bins each (a
    /// Jacobian zero elsewhere, as a component's is far from its centre) they are the dense
    /// sums to the bit, for every component count up to and past the sparse limit.
    #[test]
    fn sparse_scoring_is_the_dense_sums() {
        let mut rng = crate::rng::SplitMix64::new(5);
        let nb = 120;
        for nc in [3, 4, 7, SPARSE_COMPONENTS, SPARSE_COMPONENTS + 1] {
            let np = 3 * nc;
            let mut jac = vec![0.0; nb * np];
            for c in 0..nc {
                let centre = rng.uniform() * nb as f64;
                let reach = 1.0 + 20.0 * rng.uniform();
                for i in 0..nb {
                    if (i as f64 - centre).abs() < reach {
                        for a in 3 * c..3 * c + 3 {
                            jac[i * np + a] = rng.uniform() - 0.5;
                        }
                    }
                }
            }
            let m: Vec<f64> = (0..nb).map(|_| 0.1 + 50.0 * rng.uniform()).collect();
            let y: Vec<f64> = (0..nb).map(|_| (60.0 * rng.uniform()).floor()).collect();
            let (mut h, mut g) = (vec![7.0; np * np], vec![7.0; np]);
            scoring_sized(np, &y, &jac, &m, &mut h, &mut g);
            let (mut hs, mut gs) = (vec![-3.0; np * np], vec![-3.0; np]);
            scoring_sparse(np, &y, &jac, &m, &mut hs, &mut gs);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&hs), bits(&h), "{nc} components: curvature");
            assert_eq!(bits(&gs), bits(&g), "{nc} components: gradient");
        }
    }
}
