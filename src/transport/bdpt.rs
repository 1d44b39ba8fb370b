//! One bidirectional sample: a light and a receiver sub-path, joined in every way, each
//! strategy weighted by [`mis_weight`](super::mis_weight) and tallied by time and order.

use super::bands::{BandVec, ONES};
use super::bsdf::{bsdf, sample_bsdf};
use super::mis::{link, mis_weight};
use super::tally::Accum;
use super::{PulseSetup, Rng, Vertex, VertexKind, ROULETTE_AFTER};
use crate::rng::Sobol2;
use crate::scene::FacetId;
use glam::DVec3;

/// Index of the surface class (ground, vegetation, building, other) of the path's first
/// surface `first`, the one the laser lit, which a return's range points at; `next` is the
/// vertex after it. Light that enters the water there returns from what lies under it (the
/// bottom, an object in the column): its class is that of `next`, and the water surface's
/// own ("other") only for what it reflects.
#[inline]
pub(super) fn class_of(setup: &PulseSetup, first: &Vertex, next: &Vertex) -> usize {
    let surfaces = &setup.scene.surfaces;
    let v = match &setup.scene.water {
        Some(w)
            if next.kind == VertexKind::Surface
                && surfaces
                    .get(first.surface as usize)
                    .is_some_and(|s| s.water.is_some())
                && w.holds(first.p, next.p) =>
        {
            next
        }
        _ => first,
    };
    // a vertex off every surface (none lit) counts as "other", as an unknown class does
    setup
        .scene
        .surfaces
        .get(v.surface as usize)
        .map_or(crate::scene::SurfaceClass::Other.index(), |s| {
            s.class.index()
        })
}

/// Reusable per-thread buffers.
#[derive(Default)]
pub(super) struct Buffers {
    light: Vec<Vertex>,
    cam: Vec<Vertex>,
    scratch: Vec<f64>,
    /// With several bands, each vertex's factor per band (`light_r[i]` of `light[i]`: what
    /// turns its β into each band's).
    light_r: Vec<BandVec>,
    cam_r: Vec<BandVec>,
}

/// Transmittance of the segment from vertex `a` to the point `b`: 1 in vacuum; the sun's
/// vertex stands for the top of the atmosphere up-sun of `b`.
#[inline]
pub(super) fn segment_transmittance(setup: &PulseSetup, a: &Vertex, b: DVec3) -> f64 {
    if let Some(w) = &setup.scene.water {
        // in the water column, its attenuation and no air: the least of the bands', each band
        // taking the rest in its factor (`Bands::segment`)
        if w.holds(a.p, b) {
            return (-w.attenuation_min * (b - a.p).length()).exp();
        }
    }
    match setup.atmosphere {
        None => 1.0,
        Some(atm) if a.kind == VertexKind::Sun => atm.transmittance_to_top(b, -a.n),
        Some(atm) => atm.transmittance(a.p, b),
    }
}

/// The time a straight segment of geometric length `len` from `a` to `b` takes in the first
/// band, as a length in vacuum: n_g × len in the water column (n_g the band's group index),
/// len elsewhere.
#[inline]
pub(super) fn optical_length(setup: &PulseSetup, a: DVec3, b: DVec3, len: f64) -> f64 {
    match &setup.scene.water {
        // the pulse travels at the group velocity; the first band's times are the tally's
        Some(w) if w.holds(a, b) => w.n_group[0] * len,
        _ => len,
    }
}

/// The geometric length of a straight segment from `a` to `b` in the water column: `len` or 0.
#[inline]
pub(super) fn water_length(setup: &PulseSetup, a: DVec3, b: DVec3, len: f64) -> f64 {
    match &setup.scene.water {
        Some(w) if w.holds(a, b) => len,
        _ => 0.0,
    }
}

/// The water's group index in each band (none without water): a band's time over a path is
/// the first band's plus (n_g,b - n_g,0) × its length in water.
#[inline]
pub(super) fn group_indices<'s>(setup: &PulseSetup<'s>) -> &'s [f64] {
    setup.scene.water.as_ref().map_or(&[], |w| &w.n_group)
}

pub(super) fn surface_vertex(hit: &crate::scene::Hit, beta: f64, len: f64, wlen: f64) -> Vertex {
    Vertex {
        kind: VertexKind::Surface,
        p: hit.position,
        n: hit.normal,
        surface: hit.surface,
        facet: hit.facet,
        beta,
        len,
        wlen,
        pdf_fwd: 0.0,
        pdf_rev: 0.0,
        delta: false,
    }
}

/// Russian roulette on the albedo just applied: survive with probability a (at least 0.05)
/// and undo the factor on survival, so the expectation is unchanged.
#[inline]
pub(super) fn survives(surfaces: usize, beta: &mut f64, a: f64, rng: &mut Rng) -> bool {
    if surfaces < ROULETTE_AFTER || a >= 1.0 {
        return true;
    }
    let p = a.max(0.05);
    if rng.uniform() >= p {
        return false;
    }
    *beta /= p;
    true
}

/// A sub-path's random walk: its vertices so far (the end point first) with their band
/// factors, the direction and throughput it leaves the last one with, the most vertices it
/// may hold, and whether it carries light from a source (`light`) or importance from the
/// receiver.
pub(super) struct Walk<'b> {
    pub path: &'b mut Vec<Vertex>,
    /// With several bands, one entry per vertex (the end point's first): each new vertex's
    /// band factors are pushed as it is made.
    pub ratios: &'b mut Vec<BandVec>,
    pub dir: DVec3,
    pub beta: f64,
    pub cap: usize,
    pub light: bool,
}

/// Extends a sub-path ([`Walk`]) up to its cap. On a light sub-path, a segment that crosses
/// the aperture before any facet is the strategy t = 0 and is scored on the way.
///
/// Long because the loop is one bounce: the aperture scored on the way (t = 0), the vertex
/// made, its band factors, the BSDF sampled and the roulette; split, each step would carry
/// the whole walk's state.
pub(super) fn walk(
    setup: &PulseSetup,
    walk: Walk,
    rng: &mut Rng,
    acc: &mut Accum,
    scratch: &mut Vec<f64>,
) {
    let Walk {
        path,
        ratios,
        mut dir,
        mut beta,
        cap,
        light,
    } = walk;
    let scene = setup.scene;
    let recv = &setup.receiver;
    // the band factors of the sub-path so far, the last vertex's scattering included
    let mut run = ONES;
    // a light sub-path that fills its cap samples on once more, for the aperture alone
    // (t = 0), where a specular surface leaves that strategy the only one for the highest order
    let crossing_after_cap = light && setup.crossing_after_cap();
    while path.len() < cap + usize::from(crossing_after_cap) {
        let last = *path.last().expect("a sub-path starts at its end point");
        let surfaces = path.len() - 1;
        let hit = scene.intersect(last.p, dir, f64::INFINITY, last.facet);
        acc.tally.queries += 1;
        if light && surfaces >= 1 {
            if let Some(tq) = recv.hit_distance(last.p, dir) {
                if hit.as_ref().is_none_or(|h| tq < h.t) && recv.accepts(-dir).is_some() {
                    let mut q = Vertex::endpoint(
                        VertexKind::Aperture,
                        last.p + dir * tq,
                        recv.frame.w,
                        0.0,
                    );
                    q.beta = beta * segment_transmittance(setup, &last, q.p);
                    q.len = last.len + optical_length(setup, last.p, q.p, tq);
                    q.wlen = last.wlen + water_length(setup, last.p, q.p, tq);
                    path.push(q);
                    link(setup, path);
                    let w = mis_weight(setup, path, &[], scratch);
                    let sun = path[0].kind == VertexKind::Sun;
                    if let Some(bands) = setup.bands {
                        let mut r = run;
                        bands.segment(&mut r, &last, q.p);
                        if sun {
                            acc.add_solar_bands(q.beta * w, &r);
                        } else {
                            let class = class_of(setup, &path[1], &path[2]);
                            let len = (q.len, q.wlen, group_indices(setup));
                            acc.add_bands(len, q.beta * w, surfaces, class, &r);
                        }
                    } else if sun {
                        acc.add_solar(q.beta * w);
                    } else {
                        let class = class_of(setup, &path[1], &path[2]);
                        acc.add(q.len, q.beta * w, surfaces, class);
                    }
                    path.pop();
                }
            }
        }
        if path.len() >= cap {
            break;
        }
        let Some(hit) = hit else { break };
        beta *= segment_transmittance(setup, &last, hit.position);
        let len = last.len + optical_length(setup, last.p, hit.position, hit.t);
        let wlen = last.wlen + water_length(setup, last.p, hit.position, hit.t);
        path.push(surface_vertex(&hit, beta, len, wlen));
        if setup.both_subpaths() {
            link(setup, path);
        }
        if let Some(bands) = setup.bands {
            bands.segment(&mut run, &last, hit.position);
            ratios.push(run);
        }
        if path.len() >= cap && !crossing_after_cap {
            break;
        }
        let surf = &scene.surfaces[hit.surface as usize];
        let Some((next, a, delta)) = sample_bsdf(surf, hit.normal, -dir, light, rng) else {
            break;
        };
        if let Some(v) = path.last_mut() {
            v.delta = delta;
        }
        if let Some(bands) = setup.bands {
            bands.scatter(&mut run, hit.surface, hit.normal, -dir, next);
        }
        beta *= a;
        if !survives(surfaces + 1, &mut beta, a, rng) {
            break;
        }
        dir = next;
    }
}

/// [`class_of`] the path `light` joined to the receiver sub-path's vertex `y`.
#[inline]
fn first_class(setup: &PulseSetup, light: &[Vertex], y: &Vertex) -> usize {
    class_of(setup, &light[1], light.get(2).unwrap_or(y))
}

/// The geometric length in water of the path that joins `x` (a light sub-path's end) to `y`
/// (a receiver sub-path's).
fn joined_water(setup: &PulseSetup, x: &Vertex, y: &Vertex) -> f64 {
    x.wlen + water_length(setup, x.p, y.p, (y.p - x.p).length()) + y.wlen
}

/// Unweighted estimate f/p of the path light[..s] + cam[..t] (t ≥ 1, s ≥ 1, s + t ≥ 3) and
/// its length, or None when it carries nothing. Visibility is not tested here.
pub(super) fn contribution(
    setup: &PulseSetup,
    light: &[Vertex],
    cam: &[Vertex],
) -> Option<(f64, f64)> {
    let surfaces = &setup.scene.surfaces;
    let (s, t) = (light.len(), cam.len());
    let x = &light[s - 1];
    let y = &cam[t - 1];
    let d = y.p - x.p;
    let r2 = d.length_squared();
    if r2 == 0.0 {
        return None;
    }
    let r = r2.sqrt();
    let w = d / r; // from the light side towards the receiver side
    if s == 1 && x.kind == VertexKind::Sun {
        // irradiance E Δλ from a fixed direction: no distance, no falloff
        let sun = setup.sun?;
        let towards_prev = (cam[t - 2].p - y.p).normalize();
        let f_y = bsdf(&surfaces[y.surface as usize], y.n, -sun.dir, towards_prev)
            * y.n.dot(sun.dir).abs();
        let c = x.beta * sun.band_irradiance * f_y * y.beta * segment_transmittance(setup, x, y.p);
        return (c > 0.0).then_some((c, 0.0));
    }
    let f_x = if s == 1 {
        // the laser: radiant intensity Q_e p_L(ω) per unit solid angle
        setup.laser.energy * setup.laser.pdf(w)
    } else {
        let towards_prev = (light[s - 2].p - x.p).normalize();
        bsdf(&surfaces[x.surface as usize], x.n, towards_prev, w) * x.n.dot(w).abs()
    };
    if f_x == 0.0 {
        return None;
    }
    let f_y = if t == 1 {
        // a point drawn on the aperture (pdf 1/A): W_e cos θ_q A
        setup.receiver.accepts(-w)? * setup.receiver.area
    } else {
        let towards_prev = (cam[t - 2].p - y.p).normalize();
        bsdf(&surfaces[y.surface as usize], y.n, -w, towards_prev) * y.n.dot(w).abs()
    };
    let c = x.beta * f_x * f_y * y.beta / r2 * segment_transmittance(setup, x, y.p);
    (c > 0.0).then_some((c, x.len + optical_length(setup, x.p, y.p, r) + y.len))
}

/// The first dimensions of a ray sample: where the light leaves its source (the laser's
/// direction within its beam, hence the point of the footprint it lights; or the sun's disk),
/// the receiver's aperture point and its direction within the field of view. With
/// `sampler: sobol` they come from the pulse's low-discrepancy sequence ([`Sobol2`], sample
/// index = ray index in the pulse); else from the ray's stream, drawn where they are used,
/// so that independent sampling keeps the draws, and so the files, of versions without the
/// `sampler` key.
pub(super) struct FirstDims(Option<(Sobol2, u64)>);

impl FirstDims {
    pub(super) fn of(sobol: Option<&Sobol2>, index: u64) -> FirstDims {
        FirstDims(sobol.map(|q| (*q, index)))
    }

    fn pair(&self, pair: u32, rng: &mut Rng) -> [f64; 2] {
        match self.0 {
            Some((q, index)) => q.pair(index, pair),
            None => [rng.uniform(), rng.uniform()],
        }
    }

    fn light(&self, rng: &mut Rng) -> [f64; 2] {
        self.pair(0, rng)
    }

    fn aperture(&self, rng: &mut Rng) -> [f64; 2] {
        self.pair(1, rng)
    }

    fn direction(&self, rng: &mut Rng) -> [f64; 2] {
        self.pair(2, rng)
    }
}

/// One sample of the pulse: both sub-paths, then every way of joining them. The order of the
/// random draws (light, receiver, aperture points of t = 1) is part of the output: keep it.
///
/// With a sun whose share f (`sun.share`) is under 1, a sample traces the sun's light with
/// probability f only (one draw before the others); the others are the laser's alone. Every
/// strategy of a sun path then has its density times f, which leaves their MIS weights as
/// they were, and the sun's contributions are divided by f; the laser's light sub-path is
/// chosen in 1 - f q of the samples (q: the sun's selection probability), its density.
pub(super) fn trace_ray(
    setup: &PulseSetup,
    first: &FirstDims,
    rng: &mut Rng,
    acc: &mut Accum,
    b: &mut Buffers,
) {
    let share = setup.sun.map_or(1.0, |s| s.share.min(1.0));
    let sun = setup.sun.filter(|_| share >= 1.0 || rng.uniform() < share);
    let is_sun = light_subpath(setup, first, rng, acc, b, sun.is_some());
    receiver_subpath(setup, first, rng, acc, b, sun.is_some());
    connect_to_lights(setup, acc, b, sun.is_some());
    connect_subpaths(setup, rng, acc, b, is_sun);
}

/// The sun's selection probability and share, and the laser's selection probability
/// (see [`trace_ray`]).
fn selection(setup: &PulseSetup) -> (f64, f64, f64) {
    let (q_sun, share) = setup
        .sun
        .map_or((0.0, 1.0), |s| (s.probability, s.share.min(1.0)));
    (q_sun, share, 1.0 - q_sun * share)
}

/// The light sub-path into `b.light`; true when it starts at the sun.
///
/// It starts at one light, the sun with its selection probability q, else the laser; its
/// contributions are divided by q, which the light end point keeps as its pdf_fwd for the MIS
/// weights. A receiver vertex, by contrast, is connected to every light (s = 1 strategies need
/// no choice), which keeps the laser's variance what it is without the sun. `sun_on`: the
/// sample traces the sun's light (see [`trace_ray`]).
fn light_subpath(
    setup: &PulseSetup,
    first: &FirstDims,
    rng: &mut Rng,
    acc: &mut Accum,
    b: &mut Buffers,
    sun_on: bool,
) -> bool {
    let (s_cap, _) = setup.caps();
    let laser = &setup.laser;
    b.light.clear();
    b.light_r.clear();
    if setup.bands.is_some() {
        b.light_r.push(ONES);
    }
    let (q_sun, share, q_laser) = selection(setup);
    let sun = setup.sun.filter(|_| sun_on && rng.uniform() < q_sun);
    if let Some(sun) = sun {
        let [u, v] = first.light(rng);
        let x0 = sun.sample_origin(u, v);
        b.light
            .push(Vertex::endpoint(VertexKind::Sun, x0, sun.dir, q_sun));
        if s_cap > 1 {
            let beta = sun.band_irradiance * sun.disk_area() / (q_sun * share);
            walk(
                setup,
                Walk {
                    path: &mut b.light,
                    ratios: &mut b.light_r,
                    dir: sun.dir,
                    beta,
                    cap: s_cap,
                    light: true,
                },
                rng,
                acc,
                &mut b.scratch,
            );
        }
    } else {
        b.light.push(Vertex::endpoint(
            VertexKind::Laser,
            laser.position,
            laser.frame.w,
            q_laser,
        ));
        if s_cap > 1 {
            let [u, v] = first.light(rng);
            let (dir, _) = laser.sample(u, v);
            walk(
                setup,
                Walk {
                    path: &mut b.light,
                    ratios: &mut b.light_r,
                    dir,
                    beta: laser.energy / q_laser,
                    cap: s_cap,
                    light: true,
                },
                rng,
                acc,
                &mut b.scratch,
            );
        }
    }
    sun.is_some()
}

/// The receiver sub-path into `b.cam` (empty when the method caps it at its aperture point);
/// in a sample that traces the laser's light alone, only as deep as the laser's joins reach.
fn receiver_subpath(
    setup: &PulseSetup,
    first: &FirstDims,
    rng: &mut Rng,
    acc: &mut Accum,
    b: &mut Buffers,
    sun_on: bool,
) {
    let t_cap = if sun_on {
        setup.receiver_walk_cap()
    } else {
        setup.caps_for(VertexKind::Laser).1
    };
    let recv = &setup.receiver;
    b.cam.clear();
    b.cam_r.clear();
    if t_cap > 1 {
        if setup.bands.is_some() {
            b.cam_r.push(ONES);
        }
        let [u, v] = first.aperture(rng);
        let q0 = recv.sample_point(u, v);
        let [u, v] = first.direction(rng);
        let (dir, w) = recv.sample_direction(u, v);
        b.cam.push(Vertex::endpoint(
            VertexKind::Aperture,
            q0,
            recv.frame.w,
            1.0 / recv.area,
        ));
        walk(
            setup,
            Walk {
                path: &mut b.cam,
                ratios: &mut b.cam_r,
                dir,
                beta: recv.area * w,
                cap: t_cap,
                light: false,
            },
            rng,
            acc,
            &mut b.scratch,
        );
    }
}

/// s = 1: every receiver vertex to the laser, and to the sun when the sample traces its light.
fn connect_to_lights(setup: &PulseSetup, acc: &mut Accum, b: &mut Buffers, sun_on: bool) {
    let (laser, scene) = (&setup.laser, setup.scene);
    let max_order = setup.max_order as usize;
    let (_, laser_t) = setup.caps_for(VertexKind::Laser);
    let (q_sun, share, q_laser) = selection(setup);
    let laser_end = Vertex::endpoint(VertexKind::Laser, laser.position, laser.frame.w, q_laser);
    for t in 2..=b.cam.len().min(max_order + 1) {
        let cam = &b.cam[..t];
        let y = &cam[t - 1];
        let laser_light = [laser_end];
        let joins_laser = t <= laser_t;
        if let Some((c, length)) = joins_laser
            .then(|| contribution(setup, &laser_light, cam))
            .flatten()
        {
            acc.tally.queries += 1;
            if !scene.occluded(laser_end.p, y.p, FacetId::NONE, y.facet) {
                let w = mis_weight(setup, &laser_light, cam, &mut b.scratch);
                if let Some(bands) = setup.bands {
                    let r = bands.connection(setup, &laser_light, cam, (&ONES, &b.cam_r[t - 1]));
                    let len = (
                        length,
                        joined_water(setup, &laser_end, y),
                        group_indices(setup),
                    );
                    acc.add_bands(len, c * w, t - 1, class_of(setup, y, &cam[t - 2]), &r);
                } else {
                    acc.add(length, c * w, t - 1, class_of(setup, y, &cam[t - 2]));
                }
            }
        }
        if let Some(sun) = setup.sun.filter(|_| sun_on) {
            // the sun's point for this connection is the one up-sun of the vertex
            let sun_light = [Vertex::endpoint(
                VertexKind::Sun,
                y.p - sun.dir * (4.0 * sun.radius),
                sun.dir,
                q_sun,
            )];
            if let Some((c, _)) = contribution(setup, &sun_light, cam) {
                acc.tally.queries += 1;
                if !scene.occluded_towards(y.p, -sun.dir, y.facet) {
                    let w = mis_weight(setup, &sun_light, cam, &mut b.scratch);
                    if let Some(bands) = setup.bands {
                        let r = bands.connection(setup, &sun_light, cam, (&ONES, &b.cam_r[t - 1]));
                        acc.add_solar_bands(c * w / share, &r);
                    } else {
                        acc.add_solar(c * w / share);
                    }
                }
            }
        }
    }
}

/// s ≥ 2: the light sub-path's vertices to a point drawn on the aperture (t = 1) and to the
/// receiver sub-path's vertices (t ≥ 2).
fn connect_subpaths(
    setup: &PulseSetup,
    rng: &mut Rng,
    acc: &mut Accum,
    b: &mut Buffers,
    is_sun: bool,
) {
    let light_kind = if is_sun {
        VertexKind::Sun
    } else {
        VertexKind::Laser
    };
    let (_, t_cap) = setup.caps_for(light_kind);
    let (recv, scene) = (&setup.receiver, setup.scene);
    let max_order = setup.max_order as usize;
    let mut q = [Vertex::endpoint(
        VertexKind::Aperture,
        recv.center,
        recv.frame.w,
        1.0 / recv.area,
    )];
    let t_max = if t_cap > 1 { b.cam.len().min(t_cap) } else { 1 };
    for s in 2..=b.light.len() {
        for t in 1..=t_max {
            let order = s + t - 2;
            if order > max_order {
                continue;
            }
            let light = &b.light[..s];
            let cam: &[Vertex] = if t == 1 {
                // the draws are made whether or not the point is needed, so the streams,
                // and the files, do not depend on the test
                let (u1, u2) = (rng.uniform(), rng.uniform());
                if recv.unseen(light[s - 1].p) {
                    continue;
                }
                q[0].p = recv.sample_point(u1, u2);
                &q
            } else {
                &b.cam[..t]
            };
            let Some((c, length)) = contribution(setup, light, cam) else {
                continue;
            };
            let (x, y) = (&light[s - 1], &cam[t - 1]);
            acc.tally.queries += 1;
            if scene.occluded(x.p, y.p, x.facet, y.facet) {
                continue;
            }
            let w = mis_weight(setup, light, cam, &mut b.scratch);
            if let Some(bands) = setup.bands {
                let cr = if t == 1 { &ONES } else { &b.cam_r[t - 1] };
                let r = bands.connection(setup, light, cam, (&b.light_r[s - 1], cr));
                if is_sun {
                    acc.add_solar_bands(c * w, &r);
                } else {
                    let len = (length, joined_water(setup, x, y), group_indices(setup));
                    acc.add_bands(len, c * w, order, first_class(setup, light, y), &r);
                }
            } else if is_sun {
                acc.add_solar(c * w);
            } else {
                acc.add(length, c * w, order, first_class(setup, light, y));
            }
        }
    }
}
