//! What the scene holds under a footprint, for the L2A truth datasets: the ground the laser
//! lights (weighted by its irradiance) and the highest scene point within the footprint's
//! edge, found by rays of the beam itself on a grid across the footprint.

use crate::plan::Pulse;
use crate::scene::{FacetId, Scene, SurfaceClass};
use crate::sensor::Frame;
use glam::DVec3;

/// Rays across the footprint's diameter (the grid is this square, cut to the disc).
const ACROSS: usize = 33;
/// Surfaces a ray passes through before it is taken to have no ground.
const MAX_LAYERS: usize = 256;

/// Heights (local z) under one footprint; `None` where no ray met any.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    pub ground: Option<f64>,
    pub canopy_top: Option<f64>,
}

/// The truth under `pulse`'s footprint: a Gaussian beam of σ `sigma_tan` in tan-space, cut at
/// `edge_tan`. The ground is the irradiance-weighted mean height of the first ground surface
/// each ray meets (through leaves and anything else); the canopy top the highest first hit.
pub fn under_footprint(scene: &Scene, pulse: &Pulse, edge_tan: f64, sigma_tan: f64) -> Truth {
    let frame = Frame::from_axis(pulse.direction);
    let (mut top, mut wsum, mut zsum) = (f64::NEG_INFINITY, 0.0, 0.0);
    let step = 2.0 * edge_tan / (ACROSS - 1) as f64;
    for i in 0..ACROSS {
        for j in 0..ACROSS {
            let (a, b) = (-edge_tan + i as f64 * step, -edge_tan + j as f64 * step);
            let r2 = a * a + b * b;
            if r2 > edge_tan * edge_tan * (1.0 + 1e-12) {
                continue;
            }
            let dir = (frame.w + frame.u * a + frame.v * b).normalize();
            let Some(first) = scene.intersect(pulse.origin, dir, f64::INFINITY, FacetId::NONE)
            else {
                continue;
            };
            top = top.max(first.position.z);
            if let Some(g) = ground_along(scene, first, dir) {
                let w = if sigma_tan > 0.0 {
                    (-0.5 * r2 / (sigma_tan * sigma_tan)).exp()
                } else {
                    1.0
                };
                wsum += w;
                zsum += w * g.z;
            }
        }
    }
    Truth {
        ground: (wsum > 0.0).then(|| zsum / wsum),
        canopy_top: top.is_finite().then_some(top),
    }
}

/// The first ground surface along the ray from its first hit on.
fn ground_along(scene: &Scene, mut hit: crate::scene::Hit, dir: DVec3) -> Option<DVec3> {
    for _ in 0..MAX_LAYERS {
        let class = scene.surfaces.get(hit.surface as usize)?.class;
        if class == SurfaceClass::Ground {
            return Some(hit.position);
        }
        hit = scene.intersect(hit.position, dir, f64::INFINITY, hit.facet)?;
    }
    None
}
