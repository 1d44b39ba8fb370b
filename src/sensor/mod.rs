//! The LiDAR sensor: laser source (paper Eq. 5-8, Appendix B) and receiver (Eq. 9).
//!
//! Both are mono-static and co-aligned: they share the pulse's position and axis.

pub mod overlap;

use crate::campaign::Instrument;
use glam::DVec3;
use std::f64::consts::PI;

/// An orthonormal frame (u, v, w) with w along a given axis.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub u: DVec3,
    pub v: DVec3,
    pub w: DVec3,
}

impl Frame {
    /// Frisvad-style construction (Duff et al. 2017), branchless and stable for any unit `w`.
    pub fn from_axis(w: DVec3) -> Frame {
        let sign = 1.0f64.copysign(w.z);
        let a = -1.0 / (sign + w.z);
        let b = w.x * w.y * a;
        let u = DVec3::new(1.0 + sign * w.x * w.x * a, sign * b, -sign * w.x);
        let v = DVec3::new(b, sign + w.y * w.y * a, -w.y);
        Frame { u, v, w }
    }

    pub fn to_world(&self, x: f64, y: f64, z: f64) -> DVec3 {
        self.u * x + self.v * y + self.w * z
    }
}

/// Where the footprint the receiver sees is cut, in sigmas of the beam's Gaussian (tan-space):
/// at the beam's edge, sqrt(-2 ln η), or at the field of view's where that is narrower (a
/// receiver offset, which shifts the field of view by milliradians at most, is left out).
pub fn footprint_edge_sigmas(inst: &Instrument) -> f64 {
    let tan_fp = (inst.footprint_half_angle_mrad * 1e-3).tan();
    let tan_fov = (inst.fov_half_angle_mrad * 1e-3).tan();
    (-2.0 * inst.edge_energy_fraction.ln()).sqrt() * (tan_fov / tan_fp).min(1.0)
}

/// Point laser with a Gaussian footprint in tan-space truncated at the edge fraction η.
#[derive(Clone, Copy, Debug)]
pub struct Laser {
    pub position: DVec3,
    pub frame: Frame,
    /// Pulse energy Q_e, J.
    pub energy: f64,
    /// tan θ_fp.
    pub tan_fp: f64,
    /// σ = tan θ_fp / sqrt(-2 ln η).
    pub sigma: f64,
    pub eta: f64,
}

impl Laser {
    pub fn new(inst: &Instrument, position: DVec3, axis: DVec3) -> Laser {
        let tan_fp = (inst.footprint_half_angle_mrad * 1e-3).tan();
        let eta = inst.edge_energy_fraction;
        Laser {
            position,
            frame: Frame::from_axis(axis.normalize()),
            energy: inst.pulse_energy_j,
            tan_fp,
            sigma: tan_fp / (-2.0 * eta.ln()).sqrt(),
            eta,
        }
    }

    /// Samples an emission direction by inverting Eq. B.4: tan²θ = -2σ² ln(1 - U1 (1 - η)).
    /// Returns the direction and its solid-angle pdf (Eq. 6).
    pub fn sample(&self, u1: f64, u2: f64) -> (DVec3, f64) {
        let tan2 = -2.0 * self.sigma * self.sigma * (1.0 - u1 * (1.0 - self.eta)).ln();
        let tan = tan2.max(0.0).sqrt().min(self.tan_fp);
        let phi = 2.0 * PI * u2;
        let d = self
            .frame
            .to_world(tan * phi.cos(), tan * phi.sin(), 1.0)
            .normalize();
        (d, self.pdf_tan2(tan * tan))
    }

    /// Solid-angle pdf of emitting along the unit direction `d` (0 outside the footprint cone).
    pub fn pdf(&self, d: DVec3) -> f64 {
        let cos = d.dot(self.frame.w);
        if cos <= 0.0 {
            return 0.0;
        }
        let x = d.dot(self.frame.u) / cos;
        let y = d.dot(self.frame.v) / cos;
        let tan2 = x * x + y * y;
        if tan2 > self.tan_fp * self.tan_fp {
            return 0.0;
        }
        self.pdf_tan2(tan2)
    }

    /// Eq. 6 written with cos³θ = (1 + tan²θ)^-3/2.
    fn pdf_tan2(&self, tan2: f64) -> f64 {
        let s2 = self.sigma * self.sigma;
        let cos3 = (1.0 + tan2).powf(-1.5);
        (-tan2 / (2.0 * s2)).exp() / (2.0 * PI * s2 * cos3 * (1.0 - self.eta))
    }
}

/// Disk aperture of area A_tel, normal along the axis, accepting rays within θ_fov of it.
#[derive(Clone, Copy, Debug)]
pub struct Receiver {
    pub center: DVec3,
    pub frame: Frame,
    pub radius: f64,
    pub area: f64,
    pub tan_fov: f64,
    pub cos_fov: f64,
}

impl Receiver {
    pub fn new(inst: &Instrument, center: DVec3, axis: DVec3) -> Receiver {
        let fov = inst.fov_half_angle_mrad * 1e-3;
        Receiver {
            center,
            frame: Frame::from_axis(axis.normalize()),
            radius: (inst.receiver_area_m2 / PI).sqrt(),
            area: inst.receiver_area_m2,
            tan_fov: fov.tan(),
            cos_fov: fov.cos(),
        }
    }

    /// Uniform point on the aperture disk (pdf 1 / A_tel).
    pub fn sample_point(&self, u1: f64, u2: f64) -> DVec3 {
        let r = self.radius * u1.sqrt();
        let phi = 2.0 * PI * u2;
        self.center + self.frame.u * (r * phi.cos()) + self.frame.v * (r * phi.sin())
    }

    /// Samples a direction through an aperture point by picking a point uniformly on the
    /// sub-sensor disk of radius tan θ_fov at F = 1 behind it (Eq. 9). Returns the direction
    /// and W_e cos θ / p(ω) = A_sub cos⁴θ (the aperture pdf is left to the caller).
    pub fn sample_direction(&self, u1: f64, u2: f64) -> (DVec3, f64) {
        let r = self.tan_fov * u1.sqrt();
        let phi = 2.0 * PI * u2;
        let d = self.frame.to_world(r * phi.cos(), r * phi.sin(), 1.0);
        let cos = 1.0 / d.length();
        let a_sub = PI * self.tan_fov * self.tan_fov;
        (d * cos, a_sub * cos.powi(4))
    }

    /// Solid-angle pdf of [`Receiver::sample_direction`]: 1 / (A_sub cos³θ) within the field
    /// of view, 0 outside.
    pub fn pdf_dir(&self, d: DVec3) -> f64 {
        match self.accepts(d) {
            Some(cos) => 1.0 / (PI * self.tan_fov * self.tan_fov * cos * cos * cos),
            None => 0.0,
        }
    }

    /// Distance along the unit direction `d` from `o` to the aperture disk, when the ray
    /// crosses it from the scene's side.
    pub fn hit_distance(&self, o: DVec3, d: DVec3) -> Option<f64> {
        let w = self.frame.w;
        let denom = d.dot(w);
        if denom >= 0.0 {
            return None;
        }
        let t = (self.center - o).dot(w) / denom;
        if t.is_nan() || t <= 0.0 {
            return None;
        }
        let p = o + d * t - self.center;
        (p.length_squared() <= self.radius * self.radius).then_some(t)
    }

    /// True when no point of the aperture sees `x` within the field of view, so that every
    /// connection of `x` to a point drawn on the aperture carries nothing. Conservative: it
    /// says so only where [`Receiver::accepts`] would refuse the direction from every point
    /// of the disk by a margin well above its round-off; elsewhere it leaves the decision
    /// to the exact test. Most vertices of an airborne survey's paths past the first lie far
    /// outside the narrow field of view, and the test spares them the aperture point's
    /// sine and cosine and the connection's arithmetic.
    ///
    /// From a disk point q = c + ρ (ρ across the axis, |ρ| ≤ R), x - q has the axial part
    /// h = (x - c)·w of x - c and an across part at least p - R, p the across distance of x
    /// from the axis: the direction is outside the field of view when p - R > h tan θ_fov,
    /// and for h ≤ 0 (x beside or behind the aperture's plane) whenever p > R.
    #[inline]
    pub fn unseen(&self, x: DVec3) -> bool {
        let v = x - self.center;
        let h = v.dot(self.frame.w);
        let p = (v - self.frame.w * h).length();
        let slack = 1e-9 * (v.length() + self.radius);
        p - self.radius > h.max(0.0) * self.tan_fov * (1.0 + 1e-6) + slack
    }

    /// Cosine between the axis and the unit direction `d` leaving the aperture towards the
    /// scene, or None when `d` is outside the field of view (W_e = 0).
    pub fn accepts(&self, d: DVec3) -> Option<f64> {
        let cos = d.dot(self.frame.w);
        (cos >= self.cos_fov && cos > 0.0).then_some(cos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inst() -> Instrument {
        serde_yaml::from_str(
            "pulse_energy_j: 1\npulse_fwhm_ns: 1\nfootprint_half_angle_mrad: 50\nfov_half_angle_mrad: 80\nreceiver_area_m2: 0.1",
        )
        .unwrap()
    }

    #[test]
    fn frame_is_orthonormal() {
        for w in [
            DVec3::Z,
            -DVec3::Z,
            DVec3::new(0.3, -0.5, 0.2).normalize(),
            DVec3::new(0.0, 0.0, -1.0),
        ] {
            let f = Frame::from_axis(w);
            assert!(
                f.u.dot(f.v).abs() < 1e-12
                    && f.u.dot(f.w).abs() < 1e-12
                    && f.v.dot(f.w).abs() < 1e-12
            );
            assert!((f.u.cross(f.v) - f.w).length() < 1e-12);
        }
    }

    /// `unseen` never refuses a point some aperture point sees within the field of view
    /// (narrow and wide fields, points near the cone's edge, beside and behind the disk),
    /// and it refuses every point past 1.01 of the edge's across distance (rim points of the
    /// disk, where the bound is tight, decide the first).
    #[test]
    fn unseen_is_conservative_and_tight() {
        let mut rng = crate::rng::Rng::new(3, 0, 0);
        for (fov_mrad, area, axis) in [
            (0.375, 0.01, -DVec3::Z),
            (80.0, 0.1, DVec3::new(0.3, -0.2, -1.0).normalize()),
            (1400.0, 1.0, DVec3::X),
        ] {
            let mut i = inst();
            i.fov_half_angle_mrad = fov_mrad;
            i.receiver_area_m2 = area;
            let r = Receiver::new(&i, DVec3::new(10.0, -4.0, 250.0), axis);
            let (mut refused, mut outside) = (0usize, 0usize);
            for _ in 0..20_000 {
                // a point at range h along the axis, across it by s times the cone's edge
                let h = if rng.uniform() < 0.1 {
                    -50.0 * rng.uniform()
                } else {
                    1e-3 + 300.0 * rng.uniform()
                };
                let s = 3.0 * rng.uniform();
                let phi = 2.0 * PI * rng.uniform();
                let across = (h.max(0.0) * r.tan_fov + r.radius) * s;
                let x = r.center
                    + r.frame.w * h
                    + r.frame.u * (across * phi.cos())
                    + r.frame.v * (across * phi.sin());
                let seen_from = |q: DVec3| r.accepts((x - q).normalize()).is_some();
                let rim = (0..64).any(|k| {
                    let a = 2.0 * PI * k as f64 / 64.0;
                    let q = r.center
                        + r.frame.u * (r.radius * a.cos())
                        + r.frame.v * (r.radius * a.sin());
                    seen_from(q)
                });
                let seen =
                    rim || (0..16).any(|_| seen_from(r.sample_point(rng.uniform(), rng.uniform())));
                if r.unseen(x) {
                    refused += 1;
                    assert!(
                        !seen,
                        "fov {fov_mrad} mrad: a seen point was refused: {x:?}"
                    );
                }
                if s > 1.01 {
                    outside += 1;
                }
            }
            assert!(
                refused >= outside && outside > 5_000,
                "fov {fov_mrad} mrad: {refused} refused of {outside} outside"
            );
        }
    }

    /// By power the sun's share is that of the energy sent into the receiver's view: a view
    /// of a few metres in a large scene makes it small, one wider than the sampling disk is
    /// cut to the disk, and the bounds hold at either end.
    #[test]
    fn power_selection_counts_the_view_not_the_disk() {
        let spec = crate::campaign::Sun {
            zenith_deg: 60.0,
            azimuth_deg: 0.0,
            irradiance_w_m2_um: 1000.0,
            selection: Some(crate::campaign::SunSelection::Power),
            selection_probability: None,
            share: None,
        };
        // a 1 nm band: E Δλ = 1 W m⁻²; a disk of radius 50 m (7854 m²)
        let a = 50.0 / 3f64.sqrt();
        let bounds = (DVec3::splat(-a), DVec3::splat(a));
        let sun = SunSource::new(&spec, 1.0, bounds);
        assert!((sun.disk_area() - PI * 2500.0).abs() < 1e-6);
        let (gate, q_e) = (1e-6, 1e-5);
        // 100 m² seen at cos 60° = 0.5: 50 W over 1 µs = 5e-5 J against 1e-5 J
        let q = sun.for_gate(q_e, gate, 100.0).probability;
        assert!((q - 5e-5 / 6e-5).abs() < 1e-12, "{q}");
        // a view wider than the disk: the disk's 7854 W, as the whole sunlit scene
        let q = sun.for_gate(1e-2, gate, 1e6).probability;
        let e = sun.disk_area() * gate;
        assert!((q - e / (e + 1e-2)).abs() < 1e-12, "{q}");
        // within 0.02-0.98 whatever the energies, and untouched with a fixed selection
        assert_eq!(sun.for_gate(1.0, gate, 1.0).probability, 0.02);
        assert_eq!(sun.for_gate(1e-12, gate, 1e6).probability, 0.98);
        let fixed = crate::campaign::Sun {
            selection: None,
            selection_probability: Some(0.3),
            share: None,
            ..spec
        };
        let sun = SunSource::new(&fixed, 1.0, bounds);
        assert_eq!(sun.for_gate(q_e, gate, 100.0).probability, 0.3);
    }

    #[test]
    fn laser_pdf_integrates_to_one_and_matches_sampling() {
        let laser = Laser::new(&inst(), DVec3::ZERO, -DVec3::Z);
        // ∫ p dω over the cone, by quadrature in θ.
        let n = 20000;
        let th_max = laser.tan_fp.atan();
        let mut sum = 0.0;
        for i in 0..n {
            let th = (i as f64 + 0.5) / n as f64 * th_max;
            let d = laser.frame.to_world(th.sin(), 0.0, th.cos());
            sum += laser.pdf(d) * th.sin() * 2.0 * PI * th_max / n as f64;
        }
        assert!((sum - 1.0).abs() < 1e-6, "{sum}");
        let (d, p) = laser.sample(0.37, 0.81);
        assert!((laser.pdf(d) - p).abs() < 1e-9 * p);
        assert_eq!(
            laser.pdf(
                laser
                    .frame
                    .to_world(laser.tan_fp * 1.01, 0.0, 1.0)
                    .normalize()
            ),
            0.0
        );
    }
}

/// The receiver's range gate: bin ξ covers [t0 + ξ Δt, t0 + (ξ+1) Δt) after emission (Eq. 18).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gate {
    /// Start of bin 0 after emission, s.
    pub t0: f64,
    /// Bin width Δt, s.
    pub dt: f64,
    pub bins: usize,
}

impl Gate {
    /// The gate a campaign asks for, or one that covers every range at which the beam's cone
    /// (the wider of footprint and field of view) meets the scene's bounding box, with room
    /// for the pulse's tails. The nearest range falls in the middle of a bin, so that a flat
    /// target at the top of the scene returns into one bin rather than straddling two.
    pub fn for_pulse(
        inst: &Instrument,
        origin: DVec3,
        direction: DVec3,
        bounds: (DVec3, DVec3),
    ) -> Gate {
        let dt = inst.bin_ns * 1e-9;
        if let Some(g) = &inst.range_gate {
            return Gate {
                t0: g.start_ns * 1e-9,
                dt,
                bins: g.bins as usize,
            };
        }
        let (lo, hi) = bounds;
        let (r_min, r_max) = cone_range(origin, direction.normalize(), lo, hi, inst);
        let sigma = gate_sigma_s(inst);
        let margin = (4.0 * sigma / dt).ceil() + 2.0;
        // an offset telescope makes a path up to |offset| shorter or longer than 2R
        let offset = inst.receiver_offset_length();
        let t0 = (2.0 * r_min - offset) / crate::C - (margin + 0.5) * dt;
        let bins = (((2.0 * r_max + offset) / crate::C - t0) / dt).ceil() + margin;
        Gate {
            t0,
            dt,
            bins: bins.max(1.0) as usize,
        }
    }

    pub fn end(&self) -> f64 {
        self.t0 + self.dt * self.bins as f64
    }

    /// Cross-section of the field of view at the gate's middle range, m²: the part of the
    /// scene the receiver sees, for choosing the light by power.
    pub fn view_area_m2(&self, inst: &Instrument) -> f64 {
        let range = (crate::C * 0.25 * (self.t0 + self.end())).max(0.0);
        let radius = range * (inst.fov_half_angle_mrad * 1e-3).tan();
        PI * radius * radius
    }
}

/// Range interval [r_min, r_max] over which the beam's cone can meet the box: the axis is
/// clipped against the box grown by the cone's radius at the box's far side (so a cone that
/// only grazes the box still gets its ranges). Every range of the box when the sensor is
/// inside it or the axis misses the grown box.
fn cone_range(origin: DVec3, dir: DVec3, lo: DVec3, hi: DVec3, inst: &Instrument) -> (f64, f64) {
    let nearest = origin.clamp(lo, hi);
    let mut far: f64 = 0.0;
    for i in 0..8 {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        far = far.max((corner - origin).length());
    }
    let whole = ((nearest - origin).length(), far);
    if nearest == origin {
        return whole;
    }
    let half = inst.footprint_half_angle_mrad.max(inst.fov_half_angle_mrad) * 1e-3;
    let grow = DVec3::splat(far * half.tan() + 1e-6 * far + 1e-3);
    let (glo, ghi) = (lo - grow, hi + grow);
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for k in 0..3 {
        if dir[k] == 0.0 {
            if origin[k] < glo[k] || origin[k] > ghi[k] {
                return whole;
            }
        } else {
            let a = (glo[k] - origin[k]) / dir[k];
            let b = (ghi[k] - origin[k]) / dir[k];
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    if t0 > t1 {
        return whole;
    }
    // ranges along off-axis rays of the cone reach a little further than along the axis
    let stretch = 1.0 / half.cos();
    (t0.max(whole.0), (t1 * stretch).min(far))
}

/// Standard deviation of the pulse's Gaussian time profile, s.
pub fn pulse_sigma_s(inst: &Instrument) -> f64 {
    inst.pulse_fwhm_ns * 1e-9 / (8.0 * std::f64::consts::LN_2).sqrt()
}

/// The spread a default range gate leaves room for on either side of the scene's ranges, s:
/// the pulse's, widened by the detector's response where the record has one (waveform and
/// discrete-return instruments: its kernel spreads the photons further, and a gate sized for
/// the pulse alone lost that spill from the record, 40 % of a 2 ns pulse's photons under a
/// 10 ns response).
pub fn gate_sigma_s(inst: &Instrument) -> f64 {
    // photon counting records events, not a convolved record: the response is not applied
    let fwhm_ns = match inst.kind {
        crate::campaign::InstrumentKind::PhotonCounting => 0.0,
        _ => inst.detector_response_fwhm_ns.unwrap_or(0.0),
    };
    let response = fwhm_ns * 1e-9 / (8.0 * std::f64::consts::LN_2).sqrt();
    pulse_sigma_s(inst).hypot(response)
}

/// The sun: a directional source of irradiance E Δλ over the receiver's band, sampled from a
/// disk perpendicular to its direction that covers the scene's bounding sphere (paper 2.4).
#[derive(Clone, Copy, Debug)]
pub struct SunSource {
    /// Direction the sunlight travels (unit, pointing down into the scene).
    pub dir: DVec3,
    pub frame: Frame,
    /// Irradiance on a surface facing the sun, over the receiver band, W m⁻².
    pub band_irradiance: f64,
    /// Centre and radius of the scene's bounding sphere.
    pub center: DVec3,
    pub radius: f64,
    /// Cosine of the sun's zenith angle, for BRFs.
    pub cos_zenith: f64,
    /// Probability that a sample's light sub-path starts at the sun.
    pub probability: f64,
    /// Pick `probability` per pulse by power (see [`SunSource::for_gate`]).
    pub by_power: bool,
    /// Share of bdpt's samples that trace the sun's light (`sun.share`).
    pub share: f64,
}

impl SunSource {
    pub fn new(sun: &crate::campaign::Sun, bandwidth_nm: f64, bounds: (DVec3, DVec3)) -> SunSource {
        let (t, p) = (sun.zenith_deg.to_radians(), sun.azimuth_deg.to_radians());
        let towards_sun = DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
        let dir = -towards_sun;
        let center = (bounds.0 + bounds.1) * 0.5;
        SunSource {
            dir,
            frame: Frame::from_axis(dir),
            band_irradiance: sun.irradiance_w_m2_um * bandwidth_nm * 1e-3,
            center,
            radius: ((bounds.1 - bounds.0).length() * 0.5).max(1e-3),
            cos_zenith: t.cos(),
            probability: sun.selection_probability.unwrap_or(0.5),
            // `auto` is resolved before any pulse is traced; the method's pilot takes it as fixed
            by_power: sun.selection() == crate::campaign::SunSelection::Power,
            share: sun.share_fraction(),
        }
    }

    /// Least and most probability selection by power gives either light: a light never
    /// chosen would leave its signal to the connections alone (s = 1), and one chosen 1 in
    /// 10^4 would make its sub-path strategies pure noise.
    pub const POWER_SELECTION_BOUNDS: (f64, f64) = (0.02, 0.98);

    /// The sun for one pulse. By power, the sun is chosen with probability
    /// E_sun / (E_sun + Q_e): the lights' shares of the energy sent, while the receiver
    /// listens, into the part of the scene it sees, whose light is what both lights' sub-paths
    /// must find. E_sun = E Δλ cos θ_s · A · T, with A the ground area of the field of view at
    /// the gate's middle range (`view_area_m2`, at most the sampling disk's πR² / cos θ_s) and
    /// T the gate's length; Q_e the pulse energy, which all falls in the view. Both lights
    /// scattered by the same surface then return in that ratio (closed forms 1 and 4): a sun
    /// sub-path started over the whole disk where the receiver sees a few metres of it
    /// (MABEL's 4 m over the 100 m orchard) finds the view about 1 time in 1000, and its
    /// connections are almost all shadowed.
    pub fn for_gate(&self, pulse_energy_j: f64, gate_s: f64, view_area_m2: f64) -> SunSource {
        let mut s = *self;
        if self.by_power {
            let lit = (self.cos_zenith * view_area_m2).min(self.disk_area());
            let e_sun = self.band_irradiance * lit * gate_s.max(0.0);
            let q = e_sun / (e_sun + pulse_energy_j);
            let (lo, hi) = Self::POWER_SELECTION_BOUNDS;
            s.probability = if q.is_finite() { q.clamp(lo, hi) } else { 0.5 };
        }
        s
    }

    /// The sun with its disk over the bounding sphere of the box `lo..hi` instead: in a
    /// repeated scene, the part of the landscape a pulse sees.
    pub fn covering(&self, lo: DVec3, hi: DVec3) -> SunSource {
        SunSource {
            center: (lo + hi) * 0.5,
            radius: ((hi - lo).length() * 0.5).max(1e-3),
            ..*self
        }
    }

    /// True when sunlight through the disk reaches `p`: `p` lies within the disk's radius of
    /// its axis. Every point of a scene that is not repeated does.
    pub fn covers(&self, p: DVec3) -> bool {
        let d = p - self.center;
        let across = (d - self.dir * d.dot(self.dir)).length_squared();
        across <= self.radius * self.radius * (1.0 + 1e-9)
    }

    /// Uniform point on the disk (pdf 1 / πR²), outside the bounding sphere, up-sun.
    pub fn sample_origin(&self, u1: f64, u2: f64) -> DVec3 {
        let r = self.radius * u1.sqrt();
        let phi = 2.0 * PI * u2;
        self.center - self.dir * (2.0 * self.radius)
            + self.frame.u * (r * phi.cos())
            + self.frame.v * (r * phi.sin())
    }

    pub fn disk_area(&self) -> f64 {
        PI * self.radius * self.radius
    }
}
