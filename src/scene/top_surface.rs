//! Reference DSM: the highest surface over each cell of a horizontal grid, computed from the
//! scene's triangles themselves rather than by casting rays, so that it is exact (up to f32
//! storage of the geometry) and does not depend on any sampling density.

use super::Scene;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// A horizontal grid. Cell (i, j) spans `x0 + i·cell ..= x0 + (i+1)·cell` and likewise in y;
/// values are stored row-major at index `j·nx + i`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub x0: f64,
    pub y0: f64,
    pub cell: f64,
    pub nx: usize,
    pub ny: usize,
}

impl Grid {
    /// The grid of `cell`-sized cells aligned on multiples of `cell` that covers the xy
    /// extent of the box `lo..hi` (e.g. `Scene::bounds()`).
    pub fn covering(lo: DVec3, hi: DVec3, cell: f64) -> Grid {
        let x0 = (lo.x / cell).floor() * cell;
        let y0 = (lo.y / cell).floor() * cell;
        let n = |lo: f64, hi: f64| (((hi - lo) / cell).ceil().max(1.0)) as usize;
        Grid {
            x0,
            y0,
            cell,
            nx: n(x0, hi.x),
            ny: n(y0, hi.y),
        }
    }

    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Index of the cell holding (x, y). Cells are half-open here ([lo, hi)) so that a point
    /// on a shared edge belongs to exactly one of them.
    pub fn index(&self, x: f64, y: f64) -> Option<usize> {
        let fi = ((x - self.x0) / self.cell).floor();
        let fj = ((y - self.y0) / self.cell).floor();
        if fi >= 0.0 && fj >= 0.0 && fi < self.nx as f64 && fj < self.ny as f64 {
            Some(fj as usize * self.nx + fi as usize)
        } else {
            None
        }
    }

    /// Centre of cell (i, j).
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.x0 + (i as f64 + 0.5) * self.cell,
            self.y0 + (j as f64 + 0.5) * self.cell,
        )
    }

    fn valid(&self) -> bool {
        self.cell > 0.0 && self.cell.is_finite() && self.x0.is_finite() && self.y0.is_finite()
    }
}

/// Triangles per work item: large meshes are split so that one mesh alone still keeps every
/// core busy; their triangles are in BVH leaf order, so a run of them is spatially compact.
const CHUNK: usize = 16_384;

struct Item {
    instance: usize,
    start: usize,
    end: usize,
    /// Whole periods (x, y) the instance is moved by: its copy in a repeated scene.
    shift: (f64, f64),
}

/// The highest z found by one work item over a rectangle of cells (NEG_INFINITY = none).
struct Patch {
    i0: usize,
    j0: usize,
    w: usize,
    h: usize,
    z: Vec<f64>,
}

impl Scene {
    /// The exact highest z of any surface over each cell of `grid` (NaN where there is none).
    ///
    /// Every triangle is clipped to every cell its xy bounding box meets and the maximum is
    /// taken over the clipped polygon's vertices, which is where a plane's maximum over a
    /// convex polygon lies. A cell is therefore credited with a surface that covers any part
    /// of it: a cell half under a roof gets the roof height. Vertical facets count through
    /// their edges. Touching a cell only along its boundary does not count.
    pub fn top_surface_grid(&self, grid: &Grid) -> Vec<f64> {
        let n = grid.len();
        if n == 0 || !grid.valid() {
            return vec![f64::NAN; n];
        }
        let items = self.dsm_items(grid);
        let mut top = vec![f64::NEG_INFINITY; n];
        // Batches bound the memory held by patches waiting to be merged; the merge is a max,
        // which is exact, so the result does not depend on scheduling.
        let batch = 32 * rayon::current_num_threads().max(1);
        for chunk in items.chunks(batch) {
            let patches: Vec<Option<Patch>> = chunk
                .par_iter()
                .map(|it| self.rasterise_top(grid, it))
                .collect();
            for p in patches.into_iter().flatten() {
                for r in 0..p.h {
                    let row = &mut top[(p.j0 + r) * grid.nx + p.i0..][..p.w];
                    for (dst, &z) in row.iter_mut().zip(&p.z[r * p.w..(r + 1) * p.w]) {
                        if z > *dst {
                            *dst = z;
                        }
                    }
                }
            }
        }
        for z in &mut top {
            if *z == f64::NEG_INFINITY {
                *z = f64::NAN;
            }
        }
        top
    }

    /// Work items of the instances whose transformed bounding box meets the grid, for every
    /// copy of a repeated scene that does.
    fn dsm_items(&self, grid: &Grid) -> Vec<Item> {
        let gx1 = grid.x0 + grid.nx as f64 * grid.cell;
        let gy1 = grid.y0 + grid.ny as f64 * grid.cell;
        let (lo, hi) = self.bounds();
        let period = self
            .period()
            .map_or(hi.truncate() - lo.truncate(), |(a, b)| b - a);
        let range = |g0: f64, g1: f64, lo: f64, hi: f64, w: f64| -> (i64, i64) {
            if !self.is_repeated() || w <= 0.0 {
                return (0, 0);
            }
            (
                ((g0 - hi) / w).floor() as i64,
                ((g1 - lo) / w).ceil() as i64,
            )
        };
        let (kx, ky) = (
            range(grid.x0, gx1, lo.x, hi.x, period.x),
            range(grid.y0, gy1, lo.y, hi.y, period.y),
        );
        let mut items = Vec::new();
        for i in kx.0..=kx.1 {
            for j in ky.0..=ky.1 {
                let shift = (i as f64 * period.x.max(0.0), j as f64 * period.y.max(0.0));
                self.dsm_items_of_copy(grid, shift, &mut items);
            }
        }
        items
    }

    fn dsm_items_of_copy(&self, grid: &Grid, shift: (f64, f64), items: &mut Vec<Item>) {
        let gx1 = grid.x0 + grid.nx as f64 * grid.cell;
        let gy1 = grid.y0 + grid.ny as f64 * grid.cell;
        for (k, inst) in self.instances.iter().enumerate() {
            let blas = &self.meshes[inst.mesh as usize];
            if blas.distinct.is_empty() {
                continue;
            }
            let xf = InstanceXf::new(self, inst, -shift.0, -shift.1);
            let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            for c in 0..8 {
                let corner = Vec3::new(
                    if c & 1 == 0 { blas.lo.x } else { blas.hi.x },
                    if c & 2 == 0 { blas.lo.y } else { blas.hi.y },
                    if c & 4 == 0 { blas.lo.z } else { blas.hi.z },
                );
                let w = xf.apply(corner);
                lo = lo.min(w);
                hi = hi.max(w);
            }
            // a little slack for the round-off of the f32 box against f64 triangles
            let pad = 1e-6 * (1.0 + lo.abs().max(hi.abs()).max_element());
            if hi.x + pad < grid.x0 || lo.x - pad > gx1 || hi.y + pad < grid.y0 || lo.y - pad > gy1
            {
                continue;
            }
            let mut start = 0;
            while start < blas.distinct.len() {
                let end = (start + CHUNK).min(blas.distinct.len());
                items.push(Item {
                    instance: k,
                    start,
                    end,
                    shift,
                });
                start = end;
            }
        }
    }

    /// The highest surface of one run of an instance's triangles over the cells it covers:
    /// two passes (the cells reached, then each triangle clipped to each cell), kept together
    /// because the second reuses the first's bounds and transform.
    fn rasterise_top(&self, grid: &Grid, item: &Item) -> Option<Patch> {
        let inst = &self.instances[item.instance];
        let blas = &self.meshes[inst.mesh as usize];
        let tris = || {
            blas.distinct[item.start..item.end]
                .iter()
                .map(|&k| &blas.tris[k as usize])
        };
        // Coordinates relative to the grid's corner keep the clipping in small numbers.
        let xf = InstanceXf::new(self, inst, grid.x0 - item.shift.0, grid.y0 - item.shift.1);
        let inv = 1.0 / grid.cell;
        let (nx, ny) = (grid.nx as f64, grid.ny as f64);

        // Pass 1: the cells this run of triangles can reach.
        let (mut x_lo, mut x_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut y_lo, mut y_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for t in tris() {
            for v in t {
                let p = xf.apply(*v);
                x_lo = x_lo.min(p.x);
                x_hi = x_hi.max(p.x);
                y_lo = y_lo.min(p.y);
                y_hi = y_hi.max(p.y);
            }
        }
        let (fi0, fi1) = cell_span(x_lo * inv, x_hi * inv);
        let (fj0, fj1) = cell_span(y_lo * inv, y_hi * inv);
        if !(fi1 >= 0.0 && fj1 >= 0.0 && fi0 < nx && fj0 < ny) {
            return None;
        }
        let (pi0, pi1) = (fi0.max(0.0), fi1.min(nx - 1.0));
        let (pj0, pj1) = (fj0.max(0.0), fj1.min(ny - 1.0));
        let w = (pi1 - pi0) as usize + 1;
        let h = (pj1 - pj0) as usize + 1;
        let mut z = vec![f64::NEG_INFINITY; w * h];
        let min_cell_area = grid.cell * grid.cell;

        // Pass 2.
        for t in tris() {
            let p = [xf.apply(t[0]), xf.apply(t[1]), xf.apply(t[2])];
            let zmax = p[0].z.max(p[1].z).max(p[2].z);
            let xmin = p[0].x.min(p[1].x).min(p[2].x);
            let xmax = p[0].x.max(p[1].x).max(p[2].x);
            let ymin = p[0].y.min(p[1].y).min(p[2].y);
            let ymax = p[0].y.max(p[1].y).max(p[2].y);
            let (ti0, ti1) = cell_span(xmin * inv, xmax * inv);
            let (tj0, tj1) = cell_span(ymin * inv, ymax * inv);
            if ti1 < pi0 || ti0 > pi1 || tj1 < pj0 || tj0 > pj1 {
                continue;
            }
            // Wholly inside one cell, as most leaves are: the maximum is a vertex. A facet of no
            // extent along x or y may stand on a cell's edge instead, which `clip_max` judges.
            if ti0 == ti1 && tj0 == tj1 && xmin < xmax && ymin < ymax {
                let k = (tj0 - pj0) as usize * w + (ti0 - pi0) as usize;
                if zmax > z[k] {
                    z[k] = zmax;
                }
                continue;
            }
            let (ci0, ci1) = (ti0.max(pi0) as usize, ti1.min(pi1) as usize);
            let (cj0, cj1) = (tj0.max(pj0) as usize, tj1.min(pj1) as usize);
            let e1 = p[1] - p[0];
            let e2 = p[2] - p[0];
            let area_xy = (e1.x * e2.y - e1.y * e2.x).abs();
            // Seen edge-on from above: only its outline can be clipped.
            let flat = area_xy <= 1e-9 * e1.cross(e2).length();
            let min_area = 1e-9 * area_xy.min(min_cell_area);
            let (base_i, base_j) = (pi0 as usize, pj0 as usize);
            for j in cj0..=cj1 {
                for i in ci0..=ci1 {
                    let k = (j - base_j) * w + (i - base_i);
                    if zmax <= z[k] {
                        continue;
                    }
                    let corner = DVec3::new(i as f64 * grid.cell, j as f64 * grid.cell, 0.0);
                    let q = [p[0] - corner, p[1] - corner, p[2] - corner];
                    let m = clip_max(&q, grid.cell, flat, min_area);
                    if m > z[k] {
                        z[k] = m;
                    }
                }
            }
        }
        Some(Patch {
            i0: pi0 as usize,
            j0: pj0 as usize,
            w,
            h,
            z,
        })
    }
}

/// Mesh storage coordinates to world coordinates (minus an xy shift), in f64.
struct InstanceXf {
    t: DVec3,
    cos: f64,
    sin: f64,
    scale: f64,
}

impl InstanceXf {
    fn new(scene: &Scene, inst: &super::Instance, sx: f64, sy: f64) -> InstanceXf {
        InstanceXf {
            t: scene.origin + inst.translation.as_dvec3() - DVec3::new(sx, sy, 0.0),
            cos: inst.cos as f64,
            sin: inst.sin as f64,
            // the inverse of the stored inverse, so the geometry is the one that is traced
            scale: 1.0 / inst.inv_scale as f64,
        }
    }

    #[inline(always)]
    fn apply(&self, v: Vec3) -> DVec3 {
        let (x, y) = (v.x as f64 * self.scale, v.y as f64 * self.scale);
        DVec3::new(
            self.t.x + self.cos * x - self.sin * y,
            self.t.y + self.sin * x + self.cos * y,
            self.t.z + v.z as f64 * self.scale,
        )
    }
}

/// First and last cell index (as f64) of the extent lo..hi given in cell units. The upper end
/// is open, so a facet that stops exactly on a cell edge does not reach the next cell; a
/// facet of zero extent on an edge goes to the cell above it, like a point would (a vertical
/// one then tops no cell, see [`clip_max`]).
#[inline(always)]
fn cell_span(lo: f64, hi: f64) -> (f64, f64) {
    let a = lo.floor();
    (a, (hi.ceil() - 1.0).max(a))
}

/// The highest z of the triangle `q` (coordinates relative to the cell's corner) over the
/// cell [0, size]², or NEG_INFINITY when it does not cover a positive area of it (`min_area`),
/// or, when `flat` (vertical facet), does not pass through its inside: a wall standing on a
/// cell's edge tops the cell its roof covers, not the one beside it, whether or not the wall
/// is stored with facets that reach that cell.
fn clip_max(q: &[DVec3; 3], size: f64, flat: bool, min_area: f64) -> f64 {
    // Each half-plane adds at most one vertex: 3 + 4.
    let mut a = [DVec3::ZERO; 8];
    let mut b = [DVec3::ZERO; 8];
    a[..3].copy_from_slice(q);
    let mut n = 3;
    for (axis, bound, keep_above) in [
        (0, 0.0, true),
        (0, size, false),
        (1, 0.0, true),
        (1, size, false),
    ] {
        n = clip_half(&a[..n], &mut b, axis, bound, keep_above);
        if n == 0 {
            return f64::NEG_INFINITY;
        }
        std::mem::swap(&mut a, &mut b);
    }
    let poly = &a[..n];
    if flat {
        // the clipped outline is a segment seen from above: inside the cell unless all of it
        // lies on the cell's edge, where the mean of its vertices then lies too
        let mean = poly.iter().fold(DVec3::ZERO, |m, v| m + *v) / n as f64;
        let eps = 1e-9 * size;
        if !(mean.x > eps && mean.x < size - eps && mean.y > eps && mean.y < size - eps) {
            return f64::NEG_INFINITY;
        }
    } else {
        let mut twice = 0.0;
        for k in 0..n {
            let (u, v) = (poly[k], poly[(k + 1) % n]);
            twice += u.x * v.y - v.x * u.y;
        }
        if twice.abs() <= min_area {
            return f64::NEG_INFINITY;
        }
    }
    poly.iter().fold(f64::NEG_INFINITY, |m, v| m.max(v.z))
}

/// One Sutherland-Hodgman step: keeps the part of the closed polygon `inp` where
/// `coord[axis] >= bound` (or `<=`); z is interpolated along the edges, which is exact on the
/// triangle's plane.
#[inline(always)]
fn clip_half(
    inp: &[DVec3],
    out: &mut [DVec3; 8],
    axis: usize,
    bound: f64,
    keep_above: bool,
) -> usize {
    let side = |p: DVec3| {
        if keep_above {
            p[axis] - bound
        } else {
            bound - p[axis]
        }
    };
    let mut m = 0;
    for k in 0..inp.len() {
        let (p, r) = (inp[k], inp[(k + 1) % inp.len()]);
        let (dp, dr) = (side(p), side(r));
        if dp >= 0.0 {
            out[m] = p;
            m += 1;
        }
        if (dp >= 0.0) != (dr >= 0.0) && m < out.len() {
            let mut x = p + (r - p) * (dp / (dp - dr));
            x[axis] = bound;
            out[m] = x;
            m += 1;
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    fn tmp(name: &str) -> crate::testdata::TempDir {
        let d = crate::testdata::TempDir::new(&format!("dsm-{name}"));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn scene(name: &str, files: &[(&str, &str)], objects: &str) -> Scene {
        let d = tmp(name);
        for (f, t) in files {
            write(&d, f, t);
        }
        let p = write(
            &d,
            "scene.yaml",
            &format!("name: {name}\nmaterials:\n  m: {{ reflectance: 0.3 }}\nobjects:\n{objects}"),
        );
        Scene::load(&p, 1064.0).unwrap()
    }

    fn grid(x0: f64, y0: f64, cell: f64, nx: usize, ny: usize) -> Grid {
        Grid {
            x0,
            y0,
            cell,
            nx,
            ny,
        }
    }

    #[test]
    fn flat_plane_covers_its_cells_only() {
        let s = scene(
            "plane3",
            &[],
            "  - plane: { z: 3, extent: [[0, 0], [10, 6]], material: m }\n",
        );
        let g = grid(-2.0, -2.0, 2.0, 8, 6);
        let top = s.top_surface_grid(&g);
        for j in 0..g.ny {
            for i in 0..g.nx {
                let (x, y) = g.centre(i, j);
                let inside = (0.0..10.0).contains(&x) && (0.0..6.0).contains(&y);
                let z = top[j * g.nx + i];
                if inside {
                    assert!((z - 3.0).abs() < 1e-6, "cell ({i}, {j}): {z}");
                } else {
                    assert!(z.is_nan(), "cell ({i}, {j}) outside: {z}");
                }
            }
        }
        // an offset grid sees the plane's partial cells too
        let g = grid(-0.5, -0.5, 1.0, 12, 8);
        let top = s.top_surface_grid(&g);
        let covered = top.iter().filter(|z| !z.is_nan()).count();
        assert_eq!(covered, 11 * 7);
    }

    const BOX_OBJ: &str = "v 1.5 1.5 0\nv 4.5 1.5 0\nv 4.5 3.5 0\nv 1.5 3.5 0\n\
        v 1.5 1.5 5\nv 4.5 1.5 5\nv 4.5 3.5 5\nv 1.5 3.5 5\n\
        f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\n\
        f 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n";

    #[test]
    fn box_roof_covers_partial_cells() {
        let s = scene(
            "box",
            &[("box.obj", BOX_OBJ)],
            "  - plane: { z: 0, extent: [[0, 0], [6, 6]], material: m }\n  - mesh: { file: box.obj, material: m, class: building }\n",
        );
        let g = grid(0.0, 0.0, 1.0, 7, 6);
        let top = s.top_surface_grid(&g);
        for j in 0..g.ny {
            for i in 0..g.nx {
                let z = top[j * g.nx + i];
                let expect = if (1..=4).contains(&i) && (1..=3).contains(&j) {
                    5.0
                } else if i < 6 {
                    0.0
                } else {
                    f64::NAN
                };
                if expect.is_nan() {
                    assert!(z.is_nan(), "({i}, {j}): {z}");
                } else {
                    assert!((z - expect).abs() < 1e-5, "({i}, {j}): {z} != {expect}");
                }
            }
        }
    }

    /// Walls on cell edges: the box's roof tops the cells it covers and no more, alone, beside
    /// a ground object, or with the ground in its own mesh (where the walls are clipped
    /// against every cell the mesh reaches).
    #[test]
    fn walls_on_cell_edges_top_no_cell_beside_them() {
        let walls = "v 1 1 0\nv 3 1 0\nv 3 2 0\nv 1 2 0\nv 1 1 5\nv 3 1 5\nv 3 2 5\nv 1 2 5\n\
            f 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n";
        let with_ground =
            format!("{walls}v 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nf 9 10 11\nf 9 11 12\n");
        let g = grid(0.0, 0.0, 1.0, 4, 3);
        let mesh = "  - mesh: { file: walls.obj, material: m, class: building }\n";
        let plane = "  - plane: { z: 0, extent: [[0, 0], [4, 3]], material: m }\n";
        for (obj, objects, ground) in [
            (walls, mesh.to_string(), false),
            (walls, format!("{plane}{mesh}"), true),
            (with_ground.as_str(), mesh.to_string(), true),
        ] {
            let s = scene("walls", &[("walls.obj", obj)], &objects);
            let top = s.top_surface_grid(&g);
            for j in 0..g.ny {
                for i in 0..g.nx {
                    let z = top[j * g.nx + i];
                    if (1..=2).contains(&i) && j == 1 {
                        assert!((z - 5.0).abs() < 1e-5, "({i}, {j}): {z}");
                    } else if ground {
                        assert!(z.abs() < 1e-5, "({i}, {j}): {z}");
                    } else {
                        assert!(z.is_nan(), "({i}, {j}): {z}");
                    }
                }
            }
        }
    }

    #[test]
    fn tilted_plane_gives_highest_corner() {
        // z = 0.5 x + 0.25 y over [0, 4]²
        let obj = "v 0 0 0\nv 4 0 2\nv 4 4 3\nv 0 4 1\nf 1 2 3\nf 1 3 4\n";
        let s = scene(
            "tilt",
            &[("tilt.obj", obj)],
            "  - mesh: { file: tilt.obj, material: m }\n",
        );
        let g = grid(0.5, 0.5, 1.0, 4, 4);
        let top = s.top_surface_grid(&g);
        for j in 0..4 {
            for i in 0..4 {
                let x = (1.5 + i as f64).min(4.0);
                let y = (1.5 + j as f64).min(4.0);
                let expect = 0.5 * x + 0.25 * y;
                let z = top[j * 4 + i];
                assert!((z - expect).abs() < 1e-5, "({i}, {j}): {z} != {expect}");
            }
        }
    }

    #[test]
    fn vertical_facet_counts_through_its_top_edge() {
        // a wall in the plane y = 0.5 whose top edge falls as z = 4 - x
        let obj = "v 0 0.5 0\nv 4 0.5 0\nv 0 0.5 4\nf 1 2 3\n";
        let s = scene(
            "wall",
            &[("wall.obj", obj)],
            "  - mesh: { file: wall.obj, material: m }\n",
        );
        let g = grid(0.0, 0.0, 1.0, 5, 2);
        let top = s.top_surface_grid(&g);
        for (i, z) in top[..4].iter().enumerate() {
            assert!((z - (4.0 - i as f64)).abs() < 1e-5, "{i}: {z}");
        }
        assert!(
            top[4].is_nan() && top[5..].iter().all(|z| z.is_nan()),
            "{top:?}"
        );
    }

    #[test]
    fn rotated_scaled_instance() {
        // z = 1 + 0.5 x over [0, 2] × [0, 1]; scaled 2, rotated 90°, moved to (10, 20, 5):
        // mesh (x, y, z) -> world (10 - 2y, 20 + 2x, 5 + 2z), so world x in [8, 10],
        // y in [20, 24] and z = 7 + 0.5 (y - 20).
        let obj = "v 0 0 1\nv 2 0 2\nv 2 1 2\nv 0 1 1\nf 1 2 3\nf 1 3 4\n";
        let s = scene(
            "inst",
            &[("roof.obj", obj), ("at.csv", "10, 20, 5, 90, 2\n")],
            "  - mesh: { file: roof.obj, material: m, instances: at.csv }\n",
        );
        let g = grid(5.0, 18.0, 1.0, 8, 8);
        let top = s.top_surface_grid(&g);
        for j in 0..8 {
            for i in 0..8 {
                let z = top[j * 8 + i];
                if (3..=4).contains(&i) && (2..=5).contains(&j) {
                    let y_top = 19.0 + j as f64;
                    let expect = 7.0 + 0.5 * (y_top - 20.0);
                    assert!((z - expect).abs() < 1e-4, "({i}, {j}): {z} != {expect}");
                } else {
                    assert!(z.is_nan(), "({i}, {j}): {z}");
                }
            }
        }
        // and at 45°, the corners of the rotated roof reach cells a square grid cuts
        let s = scene(
            "inst45",
            &[("roof.obj", obj), ("at.csv", "0, 0, 0, 45, 1\n")],
            "  - mesh: { file: roof.obj, material: m, instances: at.csv }\n",
        );
        let g = grid(-3.0, -3.0, 0.25, 24, 24);
        let top = s.top_surface_grid(&g);
        let (c, sn) = (45f64.to_radians().cos(), 45f64.to_radians().sin());
        // Cells wholly under the roof: the plane's highest corner. Every cell: no lower than a
        // dense sampling of the roof over it, no higher than the roof's top.
        let mesh_x = |x: f64, y: f64| c * x + sn * y;
        let mesh_y = |x: f64, y: f64| -sn * x + c * y;
        let on_roof = |x: f64, y: f64| {
            let (u, v) = (mesh_x(x, y), mesh_y(x, y));
            (0.0..=2.0).contains(&u) && (0.0..=1.0).contains(&v)
        };
        let mut sampled = vec![f64::NEG_INFINITY; g.len()];
        let n = 400;
        for a in 0..=n {
            for b in 0..=n {
                let (x, y) = (2.0 * a as f64 / n as f64, b as f64 / n as f64);
                if let Some(k) = g.index(c * x - sn * y, sn * x + c * y) {
                    sampled[k] = sampled[k].max(1.0 + 0.5 * x);
                }
            }
        }
        let mut interior = 0;
        for j in 0..g.ny {
            for i in 0..g.nx {
                let k = j * g.nx + i;
                let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)].map(|(a, b)| {
                    (
                        g.x0 + (i as f64 + a) * g.cell,
                        g.y0 + (j as f64 + b) * g.cell,
                    )
                });
                if corners.iter().all(|&(x, y)| on_roof(x, y)) {
                    interior += 1;
                    let expect = corners
                        .iter()
                        .map(|&(x, y)| 1.0 + 0.5 * mesh_x(x, y))
                        .fold(f64::MIN, f64::max);
                    assert!(
                        (top[k] - expect).abs() < 1e-5,
                        "({i}, {j}): {} != {expect}",
                        top[k]
                    );
                }
                if sampled[k].is_finite() {
                    assert!(
                        top[k] >= sampled[k] - 1e-5,
                        "({i}, {j}): {} < {}",
                        top[k],
                        sampled[k]
                    );
                }
                if top[k].is_finite() {
                    assert!(top[k] <= 2.0 + 1e-5, "({i}, {j}): {}", top[k]);
                }
            }
        }
        assert!(interior > 10, "{interior}");
    }

    #[test]
    fn clip_of_a_corner_touch_is_empty() {
        // the triangle x + y <= 0 touches the cell [0, 1]² only at its corner
        let q = [
            DVec3::new(-1.0, -1.0, 0.0),
            DVec3::new(1.0, -1.0, 1.0),
            DVec3::new(-1.0, 1.0, 1.0),
        ];
        assert_eq!(clip_max(&q, 1.0, false, 1e-12), f64::NEG_INFINITY);
        let q = [
            DVec3::new(0.5, 0.5, 1.0),
            DVec3::new(3.0, 0.5, 2.0),
            DVec3::new(0.5, 3.0, 9.0),
        ];
        // z = 1 + 0.4 (x - 0.5) + 3.2 (y - 0.5); highest at (1, 1): 2.8
        assert!((clip_max(&q, 1.0, false, 1e-12) - 2.8).abs() < 1e-12);
    }

    /// The RAMI orchard at 2 m: `cargo test --release --lib dsm -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn rami_top_surface_timing() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/rami_wco.yaml");
        let t = std::time::Instant::now();
        let s = Scene::load(&p, 1064.0).unwrap();
        eprintln!("load: {:.1} s, {:?}", t.elapsed().as_secs_f64(), s.stats());
        let (lo, hi) = s.bounds();
        let g = Grid::covering(lo, hi, 2.0);
        let t = std::time::Instant::now();
        let top = s.top_surface_grid(&g);
        let dt = t.elapsed().as_secs_f64();
        let valid: Vec<f64> = top.iter().copied().filter(|z| !z.is_nan()).collect();
        let max = valid.iter().copied().fold(f64::MIN, f64::max);
        let mean = valid.iter().sum::<f64>() / valid.len() as f64;
        eprintln!(
            "top_surface_grid {}x{} at 2 m: {dt:.2} s on {} threads; {} cells with a surface, mean {mean:.3} m, max {max:.3} m",
            g.nx,
            g.ny,
            rayon::current_num_threads(),
            valid.len()
        );
        assert_eq!(valid.len(), g.len());
    }
}
