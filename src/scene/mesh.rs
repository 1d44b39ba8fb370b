//! Triangle meshes in mesh-local coordinates: OBJ, PLY, planes and heightfields.

use crate::error::{Error, Result};
use glam::{DVec3, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};
use std::collections::HashMap;
use std::io::{BufReader, Cursor, Read};
use std::path::Path;

use super::table::HeightGrid;

/// Where a triangle's material comes from: its OBJ group (or PLY file stem) and usemtl name.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) struct SlotName {
    pub group: String,
    pub usemtl: Option<String>,
}

/// Triangles of one mesh, f32, relative to `offset` (mesh-local), before any acceleration.
pub(crate) struct MeshData {
    pub tris: Vec<[Vec3; 3]>,
    /// Per triangle: index into `slot_names`.
    pub slots: Vec<u32>,
    pub slot_names: Vec<SlotName>,
    /// Mesh-local position of the stored coordinates' origin (the centre of the mesh's box),
    /// so that f32 keeps its precision for meshes far from their own origin.
    pub offset: DVec3,
}

/// Collects f64 vertices and indexed triangles, then checks and converts them.
#[derive(Default)]
pub(crate) struct Builder {
    pub verts: Vec<DVec3>,
    pub tris: Vec<[u32; 3]>,
    pub slots: Vec<u32>,
    pub slot_names: Vec<SlotName>,
}

/// What is wrong with a vertex's coordinates, if anything: a mesh's vertices are finite
/// metres within ±[`super::MAX_COORDINATE_M`] of its origin.
fn bad_vertex(v: DVec3) -> Option<String> {
    if !v.is_finite() {
        return Some(format!("has a non-finite coordinate {v}"));
    }
    (v.abs().max_element() > super::MAX_COORDINATE_M).then(|| {
        format!(
            "at {v} lies beyond ±{} km of the mesh's origin: coordinates are metres",
            super::MAX_COORDINATE_M / 1e3
        )
    })
}

impl Builder {
    /// Checks the mesh and converts it to f32 relative to the centre of its box. Zero-area
    /// triangles are dropped (they can never be hit); an empty or all-degenerate mesh is an error.
    pub fn finish(self, path: &Path) -> Result<MeshData> {
        if self.tris.is_empty() {
            return Err(Error::file(path, "mesh has no triangles"));
        }
        let n = self.verts.len();
        if let Some(t) = self
            .tris
            .iter()
            .find(|t| t.iter().any(|&i| i as usize >= n))
        {
            let bad = t.iter().find(|&&i| i as usize >= n).copied().unwrap_or(0);
            return Err(Error::file(
                path,
                format!("a face refers to vertex {bad}, but the mesh has {n} vertices (index out of range)"),
            ));
        }
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for t in &self.tris {
            for &i in t {
                let v = self.verts[i as usize];
                if let Some(what) = bad_vertex(v) {
                    return Err(Error::file(path, format!("vertex {i} {what}")));
                }
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        let offset = (lo + hi) * 0.5;
        let local: Vec<Vec3> = self.verts.iter().map(|&v| (v - offset).as_vec3()).collect();
        let mut tris = Vec::with_capacity(self.tris.len());
        let mut slots = Vec::with_capacity(self.tris.len());
        for (t, &slot) in self.tris.iter().zip(&self.slots) {
            let p = [
                local[t[0] as usize],
                local[t[1] as usize],
                local[t[2] as usize],
            ];
            // Judged on the f32 vertices the tracer will see, in f64 so the test is exact enough.
            let (a, b, c) = (p[0].as_dvec3(), p[1].as_dvec3(), p[2].as_dvec3());
            if (b - a).cross(c - a).length_squared() > 0.0 {
                tris.push(p);
                slots.push(slot);
            }
        }
        if tris.is_empty() {
            return Err(Error::file(
                path,
                format!(
                    "mesh is degenerate: all of its {} triangles have zero area",
                    self.tris.len()
                ),
            ));
        }
        Ok(MeshData {
            tris,
            slots,
            slot_names: self.slot_names,
            offset,
        })
    }
}

/// Several meshes as one, in the frame of their joint box's centre (as [`Builder::finish`]
/// frames one mesh); each part's slots numbered after the previous parts' slots. Each part is
/// dropped once copied.
pub(crate) fn fuse(parts: Vec<MeshData>) -> MeshData {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for p in &parts {
        for v in p.tris.iter().flatten() {
            let w = v.as_dvec3() + p.offset;
            lo = lo.min(w);
            hi = hi.max(w);
        }
    }
    let offset = (lo + hi) * 0.5;
    let n = parts.iter().map(|p| p.tris.len()).sum();
    let mut fused = MeshData {
        tris: Vec::with_capacity(n),
        slots: Vec::with_capacity(n),
        slot_names: Vec::new(),
        offset,
    };
    for p in parts {
        let shift = p.offset - offset;
        let first = fused.slot_names.len() as u32;
        fused.tris.extend(
            p.tris
                .iter()
                .map(|t| t.map(|v| (v.as_dvec3() + shift).as_vec3())),
        );
        fused.slots.extend(p.slots.iter().map(|s| s + first));
        fused.slot_names.extend(p.slot_names);
    }
    fused
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Loads an OBJ or PLY file by its extension.
pub(crate) fn load_mesh(path: &Path) -> Result<MeshData> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "obj" => load_obj(path),
        "ply" => load_ply(path),
        _ => Err(Error::file(
            path,
            "unsupported mesh format: expected a .obj or .ply file",
        )),
    }
}

const NAMES_MTL: &str = "__lidarsim_usemtl_names__";

/// OBJ through tobj. Materials are only needed by name: the names come from the usemtl lines
/// themselves, handed to tobj as a synthetic material library, so a missing or broken .mtl
/// file does not matter.
///
/// Long because each kind of bad input (no faces, indices out of range, non-finite
/// vertices, degenerate triangles) gets its own located message.
/// The first line (1-based) of an OBJ text whose face names a vertex index beyond the
/// vertices given so far (or 0, or a relative index reaching before the first).
fn obj_line_out_of_range(text: &str) -> Option<usize> {
    let mut vertices = 0i64;
    for (k, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => vertices += 1,
            Some("f") | Some("l") => {
                let bad = words.any(|w| {
                    let i: i64 = w
                        .split('/')
                        .next()
                        .and_then(|s| s.parse().ok())
                        .unwrap_or(0);
                    i == 0 || i > vertices || -i > vertices
                });
                if bad {
                    return Some(k + 1);
                }
            }
            _ => {}
        }
    }
    None
}

/// The first line (1-based) of an OBJ text whose vertex, normal, texture coordinate or face
/// does not hold the numbers its keyword needs.
fn obj_line_unparsable(text: &str) -> Option<usize> {
    text.lines().enumerate().find_map(|(k, line)| {
        let mut words = line.split_whitespace();
        let ok = match words.next() {
            Some("v") | Some("vn") => {
                let n: Vec<&str> = words.collect();
                n.len() >= 3 && n.iter().all(|w| w.parse::<f32>().is_ok())
            }
            Some("vt") => words.all(|w| w.parse::<f32>().is_ok()),
            Some("f") => {
                let n: Vec<&str> = words.collect();
                n.len() >= 3
                    && n.iter().all(|w| {
                        w.split('/')
                            .all(|p| p.is_empty() || p.parse::<i64>().is_ok())
                    })
            }
            _ => true,
        };
        (!ok).then_some(k + 1)
    })
}

pub(crate) fn load_obj(path: &Path) -> Result<MeshData> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, "cannot read file", e))?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|_| Error::file(path, "cannot parse OBJ: the file is not UTF-8 text"))?;
    // a byte-order mark (Windows editors write one) would hide the first line's keyword
    let bom = text.len() - text.trim_start_matches('\u{feff}').len();
    let (text, bytes) = (&text[bom..], &bytes[bom..]);
    let mut names: Vec<String> = Vec::new();
    let mut index: HashMap<String, usize> = HashMap::new();
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let keyword = words.next();
        if keyword == Some("v") {
            // found here, a vertex is named by its line; tobj's index is its own, not the file's
            let numbers: Vec<f64> = words
                .clone()
                .take_while(|w| !w.starts_with('#'))
                .filter_map(|w| w.parse().ok())
                .collect();
            // four numbers are x y z w, the point (x, y, z) / w; six or seven carry a colour
            let vertex = match numbers[..] {
                [x, y, z, w] if w.is_finite() => Some(DVec3::new(x, y, z) / w),
                [x, y, z, w] => Some(DVec3::new(x, y, z) * w),
                [x, y, z, ..] => Some(DVec3::new(x, y, z)),
                _ => None,
            };
            if let Some(what) = vertex.and_then(bad_vertex) {
                return Err(Error::line(path, n + 1, format!("the vertex {what}")));
            }
        }
        if keyword == Some("f") {
            // tobj drops a face of fewer than three vertices without a word: a facet lost
            let vertices = words.take_while(|w| !w.starts_with('#')).count();
            if vertices < 3 {
                return Err(Error::line(
                    path,
                    n + 1,
                    format!(
                        "a face of {vertices} vertices: a face needs at least 3 (fix or remove the line)"
                    ),
                ));
            }
        }
        if keyword == Some("usemtl") {
            // Same extraction as tobj, so the names match its lookup.
            let name = line.split_once(' ').unwrap_or_default().1.trim().to_owned();
            if !name.is_empty() && !index.contains_key(&name) {
                index.insert(name.clone(), names.len());
                names.push(name);
            }
        }
    }
    let materials: Vec<tobj::Material> = names
        .iter()
        .map(|n| tobj::Material {
            name: n.clone(),
            ..Default::default()
        })
        .collect();
    let header = format!("mtllib {NAMES_MTL}\n");
    let mut reader = BufReader::new(Cursor::new(header.into_bytes()).chain(Cursor::new(bytes)));
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, |p| {
        if p == Path::new(NAMES_MTL) {
            // tobj's map type depends on its features: build it by collecting.
            Ok((
                materials.clone(),
                index.iter().map(|(k, v)| (k.clone(), *v)).collect(),
            ))
        } else {
            Ok((Vec::new(), std::iter::empty().collect()))
        }
    })
    .map_err(|e| {
        // tobj says what, not where: the line is found again here
        let (what, line) = match e {
            tobj::LoadError::FaceVertexOutOfBounds => (
                "a face refers to a vertex that does not exist (index out of range)".to_string(),
                obj_line_out_of_range(text),
            ),
            e => (format!("cannot parse OBJ: {e}"), obj_line_unparsable(text)),
        };
        match line {
            Some(n) => Error::line(path, n, what),
            None => Error::file(path, what),
        }
    })?;

    let file_stem = stem(path);
    let mut b = Builder::default();
    let mut slot_index: HashMap<SlotName, u32> = HashMap::new();
    for m in &models {
        if m.mesh.indices.is_empty() {
            continue;
        }
        let group = if m.name.is_empty() || m.name == "unnamed_object" {
            file_stem.clone()
        } else {
            m.name.clone()
        };
        let usemtl = m.mesh.material_id.and_then(|i| names.get(i).cloned());
        let key = SlotName { group, usemtl };
        let slot = *slot_index.entry(key.clone()).or_insert_with(|| {
            b.slot_names.push(key);
            (b.slot_names.len() - 1) as u32
        });
        let base = b.verts.len() as u32;
        let nv = m.mesh.positions.len() / 3;
        b.verts.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| DVec3::new(p[0], p[1], p[2])),
        );
        for t in m.mesh.indices.chunks_exact(3) {
            if t.iter().any(|&i| i as usize >= nv) {
                let what = "a face refers to a vertex that does not exist (index out of range)";
                return Err(match obj_line_out_of_range(text) {
                    Some(n) => Error::line(path, n, what),
                    None => Error::file(path, what),
                });
            }
            b.tris.push([base + t[0], base + t[1], base + t[2]]);
            b.slots.push(slot);
        }
    }
    b.finish(path)
}

#[derive(Default)]
struct PlyVertex {
    p: [f64; 3],
    set: u8,
}

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

impl PlyVertex {
    #[inline]
    fn put(&mut self, key: &str, v: f64) -> PropertyAccessResult {
        let i = match key {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return PropertyAccessResult::Ignored,
        };
        self.p[i] = v;
        self.set |= 1 << i;
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        match scalar(&property) {
            Some(v) => self.put(key, v),
            None => PropertyAccessResult::Ignored,
        }
    }
    fn set_float(&mut self, key: &str, v: f32) -> PropertyAccessResult {
        self.put(key, v as f64)
    }
    fn set_double(&mut self, key: &str, v: f64) -> PropertyAccessResult {
        self.put(key, v)
    }
}

#[derive(Default)]
struct PlyFace {
    /// Indices as i64 so that negative values from signed lists can be reported.
    idx: Vec<i64>,
}

impl PlyFace {
    fn put<T: Copy + Into<i64>>(&mut self, key: &str, v: Vec<T>) -> PropertyAccessResult {
        if key == "vertex_indices" || key == "vertex_index" {
            self.idx = v.into_iter().map(Into::into).collect();
            PropertyAccessResult::Set
        } else {
            PropertyAccessResult::Ignored
        }
    }
}

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        match property {
            Property::ListChar(v) => self.put(key, v),
            Property::ListUChar(v) => self.put(key, v),
            Property::ListShort(v) => self.put(key, v),
            Property::ListUShort(v) => self.put(key, v),
            Property::ListInt(v) => self.put(key, v),
            Property::ListUInt(v) => self.put(key, v),
            _ if key == "vertex_indices" || key == "vertex_index" => {
                PropertyAccessResult::UnsupportedType
            }
            _ => PropertyAccessResult::Ignored,
        }
    }
}

/// An element we do not use (edges, materials...): read and dropped.
struct PlySkip;

impl PropertyAccess for PlySkip {
    fn new() -> Self {
        PlySkip
    }
}

/// PLY (ASCII, binary little- or big-endian): vertex x y z (any numeric type), faces as
/// `vertex_indices`/`vertex_index` lists of any integer type, polygons triangulated as fans.
/// One material slot named after the file stem.
///
/// Long for the same reason as [`load_obj`]: a located message per kind of bad input.
pub(crate) fn load_ply(path: &Path) -> Result<MeshData> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, "cannot read file", e))?;
    let mut reader = Reader::new(BufReader::with_capacity(1 << 20, f));
    // the ply crate's messages run over several lines (the line, the text, the cause, its
    // parser's debug dump): one, with the file's line as the location where it gives one
    let bad = |e: &dyn std::fmt::Display| {
        let text = e.to_string();
        let one: Vec<&str> = text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with("Error: ParseError"))
            .collect();
        let mut message = one.join("; ");
        let line = message
            .strip_prefix("Line ")
            .and_then(|r| r.split_once(": "))
            .and_then(|(n, rest)| Some((n.parse::<usize>().ok()?, rest.to_string())));
        if let Some((n, rest)) = line {
            message = rest;
            return Error::line(path, n, format!("cannot parse PLY: {message}"));
        }
        Error::file(path, format!("cannot parse PLY: {message}"))
    };
    let vparser = Parser::<PlyVertex>::new();
    let fparser = Parser::<PlyFace>::new();
    let sparser = Parser::<PlySkip>::new();
    let header = vparser.read_header(&mut reader).map_err(|e| bad(&e))?;
    let mut verts: Vec<PlyVertex> = Vec::new();
    let mut faces: Vec<PlyFace> = Vec::new();
    let (mut have_v, mut have_f) = (false, false);
    for (name, def) in &header.elements {
        match name.as_str() {
            "vertex" => {
                for c in ["x", "y", "z"] {
                    if !def.properties.contains_key(c) {
                        return Err(Error::file(
                            path,
                            format!("cannot parse PLY: element vertex has no property {c}"),
                        ));
                    }
                }
                verts = vparser
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
                have_v = true;
            }
            "face" => {
                if !def.properties.contains_key("vertex_indices")
                    && !def.properties.contains_key("vertex_index")
                {
                    return Err(Error::file(
                        path,
                        "cannot parse PLY: element face has no list property vertex_indices (or vertex_index)",
                    ));
                }
                faces = fparser
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
                have_f = true;
            }
            _ => {
                sparser
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
            }
        }
    }
    if !have_v {
        return Err(Error::file(path, "cannot parse PLY: no vertex element"));
    }
    if !have_f {
        return Err(Error::file(
            path,
            "mesh has no triangles (the PLY file has no face element)",
        ));
    }
    // an ASCII file's vertex is named by its line when the vertices come first, as they
    // mostly do (the builder names it by its index otherwise)
    let vertices_first = header.elements.keys().next().map(String::as_str) == Some("vertex");
    if header.encoding == ply_rs_bw::ply::Encoding::Ascii && vertices_first {
        let bad = verts
            .iter()
            .enumerate()
            .find_map(|(i, v)| bad_vertex(DVec3::from_array(v.p)).map(|what| (i, what)));
        if let (Some((i, what)), Some(lines)) = (bad, ply_header_lines(path)) {
            return Err(Error::line(
                path,
                lines + i + 1,
                format!("the vertex {what}"),
            ));
        }
    }
    let n = verts.len() as i64;
    let mut b = Builder {
        verts: verts.iter().map(|v| DVec3::from_array(v.p)).collect(),
        slot_names: vec![SlotName {
            group: stem(path),
            usemtl: None,
        }],
        ..Default::default()
    };
    drop(verts);
    b.tris.reserve(faces.len());
    for (k, f) in faces.iter().enumerate() {
        if let Some(&i) = f.idx.iter().find(|&&i| i < 0 || i >= n) {
            return Err(Error::file(
                path,
                format!("face {k} refers to vertex {i}, but the file has {n} vertices (index out of range)"),
            ));
        }
        for j in 2..f.idx.len() {
            b.tris
                .push([f.idx[0] as u32, f.idx[j - 1] as u32, f.idx[j] as u32]);
            b.slots.push(0);
        }
    }
    b.finish(path)
}

/// The lines of a PLY file's header, `end_header` included; None if it cannot be read again.
fn ply_header_lines(path: &Path) -> Option<usize> {
    use std::io::BufRead;
    let f = std::fs::File::open(path).ok()?;
    let mut lines = 0;
    for line in BufReader::new(f).split(b'\n') {
        lines += 1;
        if line.ok()?.trim_ascii() == b"end_header" {
            return Some(lines);
        }
    }
    None
}

/// A horizontal rectangle at height z, front side up.
pub(crate) fn plane(path_for_errors: &Path, z: f64, a: [f64; 2], b: [f64; 2]) -> Result<MeshData> {
    let (x0, x1) = (a[0].min(b[0]), a[0].max(b[0]));
    let (y0, y1) = (a[1].min(b[1]), a[1].max(b[1]));
    let mut m = Builder {
        verts: vec![
            DVec3::new(x0, y0, z),
            DVec3::new(x1, y0, z),
            DVec3::new(x1, y1, z),
            DVec3::new(x0, y1, z),
        ],
        tris: vec![[0, 1, 2], [0, 2, 3]],
        slots: vec![0, 0],
        slot_names: vec![SlotName {
            group: "plane".into(),
            usemtl: None,
        }],
    };
    m.verts.shrink_to_fit();
    m.finish(path_for_errors)
}

/// Two triangles per grid cell, front side up; row i at y0 + i·cell, column j at x0 + j·cell.
pub(crate) fn heightfield(
    path: &Path,
    grid: &HeightGrid,
    cell_m: f64,
    origin: [f64; 2],
) -> Result<MeshData> {
    let (rows, cols) = (grid.rows, grid.cols);
    if (rows * cols) as u64 >= u32::MAX as u64 {
        return Err(Error::file(path, "the heightfield is too large"));
    }
    let mut b = Builder {
        slot_names: vec![SlotName {
            group: stem(path),
            usemtl: None,
        }],
        ..Default::default()
    };
    b.verts.reserve(rows * cols);
    for i in 0..rows {
        for j in 0..cols {
            b.verts.push(DVec3::new(
                origin[0] + j as f64 * cell_m,
                origin[1] + i as f64 * cell_m,
                grid.z[i * cols + j],
            ));
        }
    }
    b.tris.reserve(2 * (rows - 1) * (cols - 1));
    for i in 0..rows - 1 {
        for j in 0..cols - 1 {
            let v00 = (i * cols + j) as u32;
            let v10 = v00 + 1;
            let v01 = v00 + cols as u32;
            let v11 = v01 + 1;
            b.tris.push([v00, v10, v11]);
            b.tris.push([v00, v11, v01]);
        }
    }
    b.slots = vec![0; b.tris.len()];
    b.finish(path)
}
