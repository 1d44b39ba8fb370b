//! One pulse of a campaign, set up and simulated: the laser, receiver, range gate, sun,
//! atmosphere and bands the campaign gives it, and the waveform rows (one per band) that its
//! tally makes. The one constructor of a pulse and its radiometry: the pipeline, the bench,
//! the Python package and the tests all go through [`PulseSimulator`].

use super::{edge_sub_bins, sub_bins_per_bin, waveform, Radiometry, Waveform};
use crate::campaign::{Campaign, Instrument, Method};
use crate::plan::Pulse;
use crate::scene::Scene;
use crate::sensor::{pulse_sigma_s, Gate, Laser, Receiver, SunSource};
use crate::transport::atmosphere::Atmosphere;
use crate::transport::bands::Bands;
use crate::transport::{simulate_pulse_in, PulseSetup, Scratch};
use glam::DVec3;

/// What every pulse of a campaign shares: its instrument, sun, atmosphere and bands.
pub struct PulseSimulator<'a> {
    pub campaign: &'a Campaign,
    pub scene: &'a Scene,
    /// The sun over the whole scene, before a pulse sizes it to its gate.
    pub sun: Option<SunSource>,
    /// The first band's atmosphere, which paths are weighted with.
    atmosphere: Option<Atmosphere>,
    /// With several bands, what turns a path's throughput into each band's.
    bands: Option<Bands>,
    /// σ of the pulse's Gaussian time profile, s.
    pub sigma: f64,
    pub radiometry: Radiometry,
}

impl<'a> PulseSimulator<'a> {
    pub fn new(campaign: &'a Campaign, scene: &'a Scene) -> PulseSimulator<'a> {
        let c = campaign;
        let inst = &c.instrument;
        let sun = c
            .sun
            .as_ref()
            .map(|s| SunSource::new(s, inst.bandwidth_nm.unwrap_or(0.0), scene.bounds()));
        // every layer has an optical depth at each wavelength: the campaign's validation says so
        let per_band: Vec<Atmosphere> = c
            .atmosphere
            .as_ref()
            .map(|a| {
                let bands = c.wavelength_nm.all().iter();
                bands.filter_map(|&w| Atmosphere::new(a, w).ok()).collect()
            })
            .unwrap_or_default();
        let bands = c
            .wavelength_nm
            .several()
            .then(|| Bands::new(scene, &per_band));
        PulseSimulator {
            campaign,
            scene,
            sun,
            atmosphere: per_band.into_iter().next(),
            bands,
            sigma: pulse_sigma_s(inst),
            radiometry: Radiometry {
                pulse_energy_j: inst.pulse_energy_j,
                receiver_area_m2: inst.receiver_area_m2,
                fov_half_angle: inst.fov_half_angle_mrad * 1e-3,
                sun: sun.map(|s| (s.band_irradiance, s.cos_zenith)),
            },
        }
    }

    /// Pulse `p`'s setup, traced with `method` (the campaign's, or a pilot's trial).
    pub fn setup(&self, p: &Pulse, method: Method) -> PulseSetup<'_> {
        let (c, scene) = (self.campaign, self.scene);
        let inst = &c.instrument;
        let mut near = scene.bounds_near(p.origin, p.direction);
        if let Some(w) = &scene.water {
            // light is slower in the water column: the gate reaches as far as a path down to
            // the bottom of the box takes, as if the box were deeper by (n_g - 1) × depth
            let n_g = w.n_group.iter().cloned().fold(1.0, f64::max);
            near.0.z -= (n_g - 1.0) * (w.z - near.0.z).max(0.0);
        }
        let gate = Gate::for_pulse(inst, p.origin, p.direction, near);
        let sun = self.sun.map(|s| {
            let s = if scene.is_repeated() {
                let (lo, hi) = viewed_box(inst, p, near);
                s.covering(lo, hi)
            } else {
                s
            };
            s.for_gate(
                c.pulse_energy_j(p.line),
                gate.dt * gate.bins as f64,
                gate.view_area_m2(inst),
            )
        });
        PulseSetup {
            scene,
            laser: Laser {
                energy: c.pulse_energy_j(p.line),
                ..Laser::new(inst, p.origin, p.direction)
            },
            receiver: Receiver::new(
                inst,
                p.origin + p.platform_to_scene(inst.receiver_offset_m.unwrap_or_default()),
                p.direction,
            ),
            gate,
            sub_bins: sub_bins_per_bin(gate.dt, self.sigma),
            edge_sub_bins: edge_sub_bins(gate.dt, self.sigma, gate.bins),
            method,
            heuristic: c.simulation.mis,
            sampler: c.simulation.sampler,
            receiver_depth: c.simulation.receiver_depth,
            sun,
            atmosphere: self.atmosphere.as_ref(),
            bands: self.bands.as_ref(),
            max_order: c.simulation.max_order.cap(),
            seed: c.seed,
            pulse_id: p.id,
        }
    }

    /// Traces pulse `p` with the campaign's method and rays in `scratch`, and returns its
    /// waveform rows: the first band's, then the other bands' in the campaign's order.
    pub fn simulate(&self, p: &Pulse, scratch: &mut Scratch) -> (Waveform, Vec<Waveform>) {
        let c = self.campaign;
        let setup = self.setup(p, c.simulation.method);
        simulate_pulse_in(&setup, c.simulation.rays_per_pulse, scratch);
        let several = c.wavelength_nm.several();
        let radiometry = Radiometry {
            pulse_energy_j: c.pulse_energy_j(p.line),
            ..self.radiometry
        };
        let row = |b: usize, nm: f64| {
            let hv = crate::photon_energy_j(nm);
            let tally = scratch.band(b);
            let (gate, sub_bins) = (&setup.gate, setup.sub_bins);
            let mut w = waveform(p.id, tally, gate, sub_bins, self.sigma, hv, &radiometry);
            w.wavelength_nm = several.then_some(nm);
            w
        };
        let bands = c.wavelength_nm.all();
        let others = bands.iter().enumerate().skip(1);
        (
            row(0, bands[0]),
            others.map(|(b, &nm)| row(b, nm)).collect(),
        )
    }
}

/// In a repeated scene, the box of the landscape a pulse sees: the copy of the scene's box
/// under its beam grown sideways by the wider of its cones at the bottom of the scene (at
/// most ten periods), which the sun's disk must cover for its light sub-paths to reach every
/// point in view.
fn viewed_box(inst: &Instrument, p: &Pulse, (lo, hi): (DVec3, DVec3)) -> (DVec3, DVec3) {
    let half = inst.fov_half_angle_mrad.max(inst.footprint_half_angle_mrad) * 1e-3;
    let down = (p.origin.z - lo.z).max(0.0) / p.direction.z.abs().max(1e-9);
    let grow = (down * half.tan()).min(10.0 * (hi - lo).truncate().max_element());
    let g = DVec3::new(grow, grow, 0.0);
    (lo - g, hi + g)
}
