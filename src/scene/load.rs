//! From a scene file to a traceable `Scene`: objects, materials, meshes, instances, top level.

use crate::campaign::yaml::Doc;
use crate::error::{Error, Result};
use glam::{DVec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::BvhBuildParams;
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::bvh::Blas;
use super::config::{
    resolve_materials, HeightfieldSpec, MeshSpec, ObjectSpec, PlaneSpec, ResolvedMaterial,
    SceneFile, WaterSpec,
};
use super::mesh::{self, MeshData, SlotName};
use super::table::{parse_grid, parse_instances, InstanceRow};
use super::{Instance, Scene, Surface, SurfaceClass, WaterBody, MAX_COORDINATE_M};

/// Geometry to load once, shared by every object that names it.
enum Source {
    /// A mesh file, and where the scene names it first (for messages).
    Mesh(PathBuf, String),
    Plane {
        z: f64,
        a: [f64; 2],
        b: [f64; 2],
    },
    Heightfield {
        path: PathBuf,
        cell_m: f64,
        origin: [f64; 2],
        named_at: String,
    },
}

/// Where the scene file names a file, for the messages of errors in that file:
/// `scene.yaml:12: objects[1].mesh.file`.
fn named_at(doc: &Doc, key: &str) -> String {
    match crate::campaign::yaml::locate(&doc.text, key) {
        Some((line, _)) => format!("{}:{line}: {key}", doc.path.display()),
        None => format!("{}: {key}", doc.path.display()),
    }
}

impl Source {
    fn load(&self, scene: &Path) -> Result<MeshData> {
        Ok(match self {
            Source::Mesh(p, named_at) => {
                mesh::load_mesh(p).map_err(|e| e.within(named_at.clone()))?
            }
            Source::Plane { z, a, b } => mesh::plane(scene, *z, *a, *b)?,
            Source::Heightfield {
                path,
                cell_m,
                origin,
                named_at,
            } => {
                let within = |e: Error| e.within(named_at.clone());
                let text = crate::error::read_text(path).map_err(within)?;
                let grid = parse_grid(path, &text).map_err(within)?;
                mesh::heightfield(path, &grid, *cell_m, *origin).map_err(within)?
            }
        })
    }
}

enum Mapping {
    One(String),
    Map(BTreeMap<String, String>),
}

/// One object of the scene file, checked, waiting for its geometry.
struct ObjectPlan {
    key: String,
    source: usize,
    mapping: Mapping,
    class: Option<SurfaceClass>,
    /// Is a mesh (class defaults by transmittance) rather than a plane or heightfield (ground).
    is_mesh: bool,
    /// None: one instance with the identity transform.
    rows: Option<Vec<InstanceRow>>,
    /// The file as the scene names it, for messages.
    file: String,
}

fn existing(doc: &Doc, key: &str, name: &str) -> Result<PathBuf> {
    let p = doc.resolve(name);
    if !p.is_file() {
        let what = if p.exists() {
            "is not a file"
        } else {
            "the file does not exist"
        };
        return Err(doc.error(key, format!("{}: {what}", p.display())));
    }
    Ok(p)
}

fn check_material(
    doc: &Doc,
    key: &str,
    name: &str,
    materials: &BTreeMap<String, ResolvedMaterial>,
) -> Result<()> {
    if materials.contains_key(name) {
        return Ok(());
    }
    let defined: Vec<&str> = materials.keys().map(String::as_str).collect();
    let defined = if defined.is_empty() {
        "none".to_string()
    } else {
        defined.join(", ")
    };
    Err(doc.error(
        key,
        format!("material \"{name}\" is not defined under materials (defined: {defined})"),
    ))
}

/// A horizontal rectangle at `z` over `extent` (a plane's, the water's), finite and not empty.
fn check_rectangle(doc: &Doc, key: &str, what: &str, z: f64, extent: [[f64; 2]; 2]) -> Result<()> {
    let [a, b] = extent;
    let within = |v: &f64| v.is_finite() && v.abs() <= super::MAX_COORDINATE_M;
    if !within(&z) {
        return Err(doc.error(
            &format!("{key}.z"),
            format!(
                "expected a height in metres within ±{} km, found {z}",
                super::MAX_COORDINATE_M / 1e3
            ),
        ));
    }
    if !a.iter().chain(b.iter()).all(within) || a[0] == b[0] || a[1] == b[1] {
        return Err(doc.error(
            &format!("{key}.extent"),
            format!(
                "the {what} must have a non-empty extent [[x0, y0], [x1, y1]] with x0 ≠ x1 and y0 ≠ y1, every coordinate within ±{} km",
                super::MAX_COORDINATE_M / 1e3
            ),
        ));
    }
    Ok(())
}

/// The name of the material of a water surface (no material of a scene file can clash with
/// it: it is not a YAML plain key a user would write).
const WATER_MATERIAL: &str = "(water surface)";

/// The scene's body of water, checked: at most one, a finite non-empty rectangle, a refractive
/// index above 1 and a non-negative attenuation in every band.
fn water_body(doc: &Doc, file: &SceneFile, wavelengths_nm: &[f64]) -> Result<Option<WaterBody>> {
    let mut body = None;
    for (i, obj) in file.objects.iter().enumerate() {
        let ObjectSpec::Water(w) = obj else { continue };
        let key = format!("objects[{i}].water");
        if body.is_some() {
            return Err(doc.error(&key, "a scene holds one body of water at most"));
        }
        if file.repeat {
            // the water column is told by its rectangle, which a repeated landscape would
            // have to repeat too
            return Err(doc.error(
                &key,
                "water in a repeated scene (repeat: true) is not supported: give the water an extent covering the field of view instead",
            ));
        }
        let [a, b] = w.extent;
        check_rectangle(doc, &key, "water", w.z, w.extent)?;
        // the phase index of each band; the first band's steers every path's refraction
        let phase = wavelengths_nm
            .iter()
            .map(|&nm| {
                let at = format!("{key}.refractive_index");
                let n = match &w.refractive_index {
                    Some(s) => s.at(nm).map_err(|why| doc.error(&at, why))?,
                    None => 1.33,
                };
                if !(n.is_finite() && n > 1.0 && n <= 3.0) {
                    return Err(doc.error(
                        &at,
                        format!("expected a refractive index above 1 and at most 3 at {nm} nm, found {n}"),
                    ));
                }
                Ok(n)
            })
            .collect::<Result<Vec<f64>>>()?;
        let n = phase.first().copied().unwrap_or(1.33);
        let n_group = wavelengths_nm
            .iter()
            .zip(&phase)
            .map(|(&nm, &n_band)| {
                let at = format!("{key}.group_index");
                // a band the table leaves out takes the formula's value, as a scene without
                // the key does
                let g = w
                    .group_index
                    .as_ref()
                    .and_then(|s| s.at(nm).ok())
                    .unwrap_or_else(|| super::water_group_index(n_band, nm));
                if !(g.is_finite() && (1.0..=3.0).contains(&g)) {
                    return Err(doc.error(
                        &at,
                        format!("expected a group index of 1 to 3 at {nm} nm, found {g}"),
                    ));
                }
                Ok(g)
            })
            .collect::<Result<Vec<f64>>>()?;
        let attenuation = wavelengths_nm
            .iter()
            .map(|&nm| {
                let at = format!("{key}.attenuation_per_m");
                let c = w
                    .attenuation_per_m
                    .at(nm)
                    .map_err(|why| doc.error(&at, why))?;
                if !(c.is_finite() && c >= 0.0) {
                    return Err(doc.error(
                        &at,
                        format!("expected an attenuation ≥ 0 per metre at {nm} nm, found {c}"),
                    ));
                }
                Ok(c)
            })
            .collect::<Result<Vec<f64>>>()?;
        let mss = match w.wind_speed_m_s {
            None => 0.0,
            Some(u) if u.is_finite() && (0.0..=20.0).contains(&u) => 0.003 + 0.00512 * u,
            Some(u) => {
                return Err(doc.error(
                    &format!("{key}.wind_speed_m_s"),
                    format!(
                        "expected a wind speed of 0 to 20 m/s (Cox and Munk's range), found {u}"
                    ),
                ))
            }
        };
        body = Some(WaterBody {
            mss,
            z: w.z,
            lo: [a[0].min(b[0]), a[1].min(b[1])],
            hi: [a[0].max(b[0]), a[1].max(b[1])],
            n,
            n_bands: phase,
            n_group,
            attenuation_min: attenuation.iter().cloned().fold(f64::INFINITY, f64::min),
            attenuation,
        });
    }
    Ok(body)
}

/// A wavelength at which every material of the scene file has its values: the first of the
/// first table's that every other table also gives, 1064 nm when no value is a table. For a
/// host that loads a scene before it knows the bands it will trace.
pub(crate) fn common_wavelength(path: &Path) -> Result<f64> {
    use crate::campaign::spectral::Spectral;
    let doc = Doc::read(path)?;
    let file: SceneFile = doc.parse()?;
    let tables: Vec<&Vec<(f64, f64)>> = file
        .materials
        .values()
        .flat_map(|m| {
            [
                Some(&m.reflectance),
                m.back_reflectance.as_ref(),
                m.transmittance.as_ref(),
            ]
        })
        .flatten()
        .filter_map(|s| match s {
            Spectral::Table(t) => Some(t),
            Spectral::Single(_) => None,
        })
        .collect();
    let Some(first) = tables.first() else {
        return Ok(1064.0);
    };
    first
        .iter()
        .map(|&(w, _)| w)
        .find(|&w| {
            tables
                .iter()
                .all(|t| Spectral::Table((*t).clone()).at(w).is_ok())
        })
        .ok_or_else(|| {
            Error::file(path, "no wavelength is given by every material's table")
                .advise("name the wavelengths to load the scene at")
        })
}

/// Whether a scene file's materials and water resolve at `wavelengths_nm`, without building
/// the scene: a sweep of bands checks each combination's before any run.
pub(crate) fn check_bands(path: &Path, wavelengths_nm: &[f64]) -> Result<()> {
    let doc = Doc::read(path)?;
    let file: SceneFile = doc.parse()?;
    resolve_materials(&doc, &file, wavelengths_nm)?;
    water_body(&doc, &file, wavelengths_nm)?;
    Ok(())
}

/// Reads a scene file and builds its scene: the objects checked against the file, every
/// distinct mesh loaded once, materials given to each slot, instances placed, the top level
/// built.
///
/// Long because it is the load's sequence in one place (file, materials, water, meshes,
/// instances, tables, BVHs), each step a function of its own.
pub(crate) fn load(path: &Path, wavelengths_nm: &[f64]) -> Result<Scene> {
    let doc = Doc::read(path)?;
    let mut files = vec![path.to_path_buf()];
    let file: SceneFile = doc.parse()?;
    let mut materials = resolve_materials(&doc, &file, wavelengths_nm)?;
    let water = water_body(&doc, &file, wavelengths_nm)?;
    if let Some(w) = &water {
        materials.insert(
            WATER_MATERIAL.to_string(),
            ResolvedMaterial {
                reflectance: 0.0,
                back_reflectance: 0.0,
                transmittance: 0.0,
                bands: vec![[0.0; 3]; wavelengths_nm.len()],
                rpv: None,
                band_rpv: Vec::new(),
                water: Some(super::WaterInterface { n: w.n, mss: w.mss }),
            },
        );
    }
    if file.objects.is_empty() {
        return Err(doc.error("objects", "the scene has no objects"));
    }
    let (sources, plans) = plan_objects(&doc, &file, &materials, &mut files)?;

    let mut units = group_units(&plans);
    let (meshes, read) = build_meshes(&units, &sources, path)?;
    let declared = super::Declared {
        meshes: sources.len(),
        triangles: read.iter().map(|r| r.triangles).sum(),
        instances: plans
            .iter()
            .map(|p| p.rows.as_ref().map_or(1, |r| r.len() as u64))
            .sum(),
    };
    let slots = assign_surfaces(&doc, &plans, &read, &materials)?;
    units.number_slots(&slots);
    let mut placed = place_instances(&plans, &units, &meshes);
    let period = period_of(&doc, &file, &placed)?;
    let wrapped = file.repeat && wrap_into_period(&doc, &mut placed, period)?;
    if placed.len() >= u32::MAX as usize {
        return Err(Error::file(path, "too many instances"));
    }
    // each input is bounded, but a large scale on a far vertex can still carry an instance
    // out of the tracer's reach
    let reach = 10.0 * MAX_COORDINATE_M;
    if let Some(p) = placed.iter().find(|p| {
        !(p.lo.is_finite() && p.hi.is_finite())
            || p.lo.abs().max_element() > reach
            || p.hi.abs().max_element() > reach
    }) {
        return Err(Error::file(
            path,
            format!(
                "an instance of an object reaches {} .. {} m, beyond ±{} km: check its instance table's positions and scales",
                p.lo,
                p.hi,
                reach / 1e3
            ),
        ));
    }
    let top = TopLevel::build(placed, &meshes);

    files.sort();
    files.dedup();
    Ok(Scene {
        repeat: file.repeat,
        period_lo: period.0,
        period_hi: period.1,
        wrapped,
        name: file.name,
        files,
        surfaces: slots.surfaces,
        origin: top.origin,
        meshes,
        instances: top.instances,
        tlas: top.tlas,
        slot_surfaces: units.slot_surfaces,
        world_lo: top.world_lo,
        world_hi: top.world_hi,
        clip_lo: top.clip_lo,
        clip_hi: top.clip_hi,
        instanced_triangles: top.instanced_triangles,
        declared,
        water,
        ray_log: None,
    })
}

/// Checks every object of the scene file against the file and the materials, and lists the
/// geometry to load (each distinct mesh file once) and what each object makes of it.
fn plan_objects(
    doc: &Doc,
    file: &SceneFile,
    materials: &BTreeMap<String, ResolvedMaterial>,
    files: &mut Vec<PathBuf>,
) -> Result<(Vec<Source>, Vec<ObjectPlan>)> {
    let mut objects = Objects {
        doc,
        materials,
        files,
        sources: Vec::new(),
        mesh_sources: HashMap::new(),
    };
    let mut plans: Vec<ObjectPlan> = Vec::new();
    for (i, obj) in file.objects.iter().enumerate() {
        let key = format!("objects[{i}].{}", obj.kind());
        plans.push(match obj {
            ObjectSpec::Plane(p) => objects.plane(key, p)?,
            ObjectSpec::Heightfield(h) => objects.heightfield(key, h)?,
            ObjectSpec::Mesh(m) => objects.mesh(key, m)?,
            ObjectSpec::Water(w) => objects.water(key, w)?,
        });
    }
    Ok((objects.sources, plans))
}

/// What [`plan_objects`] gathers while it checks objects one by one.
struct Objects<'a> {
    doc: &'a Doc,
    materials: &'a BTreeMap<String, ResolvedMaterial>,
    /// Every file the scene reads (for the run's fingerprint).
    files: &'a mut Vec<PathBuf>,
    sources: Vec<Source>,
    /// Source of each distinct mesh file, by canonical path.
    mesh_sources: HashMap<PathBuf, usize>,
}

impl Objects<'_> {
    fn plane(&mut self, key: String, p: &PlaneSpec) -> Result<ObjectPlan> {
        let doc = self.doc;
        check_material(doc, &format!("{key}.material"), &p.material, self.materials)?;
        let [a, b] = p.extent;
        check_rectangle(doc, &key, "plane", p.z, p.extent)?;
        self.sources.push(Source::Plane { z: p.z, a, b });
        Ok(ObjectPlan {
            key,
            source: self.sources.len() - 1,
            mapping: Mapping::One(p.material.clone()),
            class: p.class.map(Into::into),
            is_mesh: false,
            rows: None,
            file: String::new(),
        })
    }

    /// The water's surface: a plane of the water material ([`water_body`] checked the rest).
    fn water(&mut self, key: String, w: &WaterSpec) -> Result<ObjectPlan> {
        let [a, b] = w.extent;
        self.sources.push(Source::Plane { z: w.z, a, b });
        Ok(ObjectPlan {
            key,
            source: self.sources.len() - 1,
            mapping: Mapping::One(WATER_MATERIAL.to_string()),
            class: Some(SurfaceClass::Other),
            is_mesh: false,
            rows: None,
            file: String::new(),
        })
    }

    fn heightfield(&mut self, key: String, h: &HeightfieldSpec) -> Result<ObjectPlan> {
        let doc = self.doc;
        check_material(doc, &format!("{key}.material"), &h.material, self.materials)?;
        // between a micrometre and 10 km: a grid's cells and its extent stay in f32's reach
        if !(h.cell_m.is_finite() && (1e-6..=1e4).contains(&h.cell_m)) {
            return Err(doc.error(
                &format!("{key}.cell_m"),
                format!(
                    "expected a cell size in metres from 10^-6 to 10^4, found {}",
                    h.cell_m
                ),
            ));
        }
        let origin = h.origin.unwrap_or([0.0, 0.0]);
        if !origin
            .iter()
            .all(|v| v.is_finite() && v.abs() <= super::MAX_COORDINATE_M)
        {
            return Err(doc.error(
                &format!("{key}.origin"),
                format!(
                    "expected coordinates in metres within ±{} km",
                    super::MAX_COORDINATE_M / 1e3
                ),
            ));
        }
        let p = existing(doc, &format!("{key}.file"), &h.file)?;
        self.files.push(p.clone());
        self.sources.push(Source::Heightfield {
            path: p,
            cell_m: h.cell_m,
            origin,
            named_at: named_at(doc, &format!("{key}.file")),
        });
        Ok(ObjectPlan {
            key,
            source: self.sources.len() - 1,
            mapping: Mapping::One(h.material.clone()),
            class: h.class.map(Into::into),
            is_mesh: false,
            rows: None,
            file: h.file.clone(),
        })
    }

    fn mesh(&mut self, key: String, m: &MeshSpec) -> Result<ObjectPlan> {
        let doc = self.doc;
        let mapping = match (&m.material, &m.materials) {
            (Some(name), None) => {
                check_material(doc, &format!("{key}.material"), name, self.materials)?;
                Mapping::One(name.clone())
            }
            (None, Some(map)) => {
                if map.is_empty() {
                    return Err(doc.error(&format!("{key}.materials"), "the map is empty"));
                }
                for (group, name) in map {
                    check_material(doc, &format!("{key}.materials.{group}"), name, self.materials)?;
                }
                Mapping::Map(map.clone())
            }
            _ => {
                return Err(doc.error(
                    &key,
                    "give either `material: NAME` (one material for the whole mesh) or `materials: { group_or_usemtl: NAME, ... }`",
                ))
            }
        };
        let p = existing(doc, &format!("{key}.file"), &m.file)?;
        self.files.push(p.clone());
        let canonical = std::fs::canonicalize(&p).unwrap_or(p);
        let sources = &mut self.sources;
        let source = *self
            .mesh_sources
            .entry(canonical.clone())
            .or_insert_with(|| {
                sources.push(Source::Mesh(
                    canonical,
                    named_at(doc, &format!("{key}.file")),
                ));
                sources.len() - 1
            });
        let rows = match &m.instances {
            Some(name) => {
                let p = existing(doc, &format!("{key}.instances"), name)?;
                self.files.push(p.clone());
                let place = named_at(doc, &format!("{key}.instances"));
                let within = |e: Error| e.within(place.clone());
                let text = crate::error::read_text(&p).map_err(within)?;
                Some(parse_instances(&p, &text).map_err(within)?)
            }
            None => None,
        };
        Ok(ObjectPlan {
            key,
            source,
            mapping,
            class: m.class.map(Into::into),
            is_mesh: true,
            rows,
            file: m.file.clone(),
        })
    }
}

/// The surfaces of a scene and the surface of every material slot of every object.
struct Slots {
    surfaces: Vec<Surface>,
    /// Per object, the surface of each of its geometry's slots.
    of_object: Vec<Vec<u32>>,
}

/// Material slots of each object -> surfaces (material, class); one surface per distinct
/// (material, class) pair.
fn assign_surfaces(
    doc: &Doc,
    plans: &[ObjectPlan],
    read: &[Read],
    materials: &BTreeMap<String, ResolvedMaterial>,
) -> Result<Slots> {
    let mut surfaces: Vec<Surface> = Vec::new();
    let mut surface_index: HashMap<(String, SurfaceClass), u32> = HashMap::new();
    let mut of_object: Vec<Vec<u32>> = Vec::with_capacity(plans.len());
    for plan in plans {
        let slot_names = &read[plan.source].slot_names;
        let names: Vec<&str> = match &plan.mapping {
            Mapping::One(name) => vec![name.as_str(); slot_names.len()],
            Mapping::Map(map) => map_slots(doc, plan, slot_names, map)?,
        };
        let transmits = names.iter().any(|n| materials[*n].transmittance > 0.0);
        let class = plan.class.unwrap_or(if !plan.is_mesh {
            SurfaceClass::Ground
        } else if transmits {
            SurfaceClass::Vegetation
        } else {
            SurfaceClass::Other
        });
        let mut slot_surfaces = Vec::with_capacity(names.len());
        for name in names {
            let id = *surface_index
                .entry((name.to_string(), class))
                .or_insert_with(|| {
                    let m = &materials[name];
                    surfaces.push(Surface {
                        name: name.to_string(),
                        reflectance: m.reflectance,
                        back_reflectance: m.back_reflectance,
                        transmittance: m.transmittance,
                        bands: m.bands.clone(),
                        rpv: m.rpv,
                        band_rpv: m.band_rpv.clone(),
                        water: m.water,
                        class,
                    });
                    (surfaces.len() - 1) as u32
                });
            slot_surfaces.push(id);
        }
        of_object.push(slot_surfaces);
    }
    Ok(Slots {
        surfaces,
        of_object,
    })
}

/// Objects placed by equal instance tables traced as one mesh: a tree's foliage and trunk,
/// each instanced at the same positions, then cost one instance per tree, not two overlapping
/// ones that a ray through the crown enters both of. Objects in the scene's own frame (no
/// table) stay apart: fused, a large scene's ground and buildings would be held twice while
/// their one mesh is built, and a generated town traced no faster for it.
struct Units {
    /// Per unit: its objects, in file order.
    objects: Vec<Vec<usize>>,
    /// Per unit: the index of its mesh in `parts`.
    mesh: Vec<u32>,
    /// Per mesh: the geometries (sources) fused into it, in order.
    parts: Vec<Vec<usize>>,
    /// Per unit: its first slot in `slot_surfaces`, where its objects' slots follow each
    /// other as the parts of its mesh do.
    base: Vec<u32>,
    slot_surfaces: Vec<u32>,
}

fn group_units(plans: &[ObjectPlan]) -> Units {
    let mut objects: Vec<Vec<usize>> = Vec::new();
    for (i, plan) in plans.iter().enumerate() {
        let alike = |u: &&mut Vec<usize>| plan.rows.is_some() && plans[u[0]].rows == plan.rows;
        match objects.iter_mut().find(alike) {
            Some(u) => u.push(i),
            None => objects.push(vec![i]),
        }
    }
    let (mut parts, mut mesh): (Vec<Vec<usize>>, Vec<u32>) = (Vec::new(), Vec::new());
    for u in &objects {
        let sources: Vec<usize> = u.iter().map(|&i| plans[i].source).collect();
        // units of the same geometries (other materials or tables) share their mesh
        let k = parts.iter().position(|p| *p == sources).unwrap_or_else(|| {
            parts.push(sources);
            parts.len() - 1
        });
        mesh.push(k as u32);
    }
    Units {
        objects,
        mesh,
        parts,
        base: Vec::new(),
        slot_surfaces: Vec::new(),
    }
}

impl Units {
    fn number_slots(&mut self, slots: &Slots) {
        for u in &self.objects {
            self.base.push(self.slot_surfaces.len() as u32);
            for &i in u {
                self.slot_surfaces.extend_from_slice(&slots.of_object[i]);
            }
        }
    }
}

/// What reading a source told of it, besides its triangles (which its mesh keeps).
#[derive(Clone, Default)]
struct Read {
    slot_names: Vec<SlotName>,
    triangles: u64,
}

/// Each distinct mesh read and its BVH built, in parallel (each mesh's parts read where it is
/// built, so that no more geometry than the threads build at once is held), and what was read
/// of every source. The first error in file order wins.
fn build_meshes(units: &Units, sources: &[Source], scene: &Path) -> Result<(Vec<Blas>, Vec<Read>)> {
    type Built = std::result::Result<(Blas, Vec<Read>), (usize, Error)>;
    let built: Vec<Built> = units
        .parts
        .par_iter()
        .map(|p| {
            let mut data = Vec::with_capacity(p.len());
            let mut failed: Option<(usize, Error)> = None;
            for &s in p {
                match sources[s].load(scene) {
                    Ok(d) => data.push(d),
                    Err(e) if failed.as_ref().is_none_or(|(f, _)| s < *f) => failed = Some((s, e)),
                    Err(_) => {}
                }
            }
            if let Some(f) = failed {
                return Err(f);
            }
            let names = data
                .iter()
                .map(|d| Read {
                    slot_names: d.slot_names.clone(),
                    triangles: d.tris.len() as u64,
                })
                .collect();
            let blas = if data.len() == 1 {
                Blas::build(&data[0])
            } else {
                Blas::build(&mesh::fuse(data))
            };
            Ok((blas, names))
        })
        .collect();
    let mut meshes = Vec::with_capacity(built.len());
    let mut read = vec![Read::default(); sources.len()];
    let mut failed: Option<(usize, Error)> = None;
    for (p, b) in units.parts.iter().zip(built) {
        match b {
            Ok((blas, names)) => {
                for (&s, r) in p.iter().zip(names) {
                    read[s] = r;
                }
                meshes.push(blas);
            }
            Err((s, e)) if failed.as_ref().is_none_or(|(f, _)| s < *f) => failed = Some((s, e)),
            Err(_) => {}
        }
    }
    match failed {
        Some((_, e)) => Err(e),
        None => Ok((meshes, read)),
    }
}

/// One instance placed in the world, in f64.
#[derive(Clone, Copy)]
struct PlacedInstance {
    translation: DVec3,
    cos: f64,
    sin: f64,
    scale: f64,
    lo: DVec3,
    hi: DVec3,
    mesh: u32,
    surfaces: u32,
    /// A plane's or heightfield's: the ground, whose extent is a repeated scene's period by
    /// default.
    ground: bool,
}

/// Most copies of one instance that wrapping it into a repeated scene's period may add: a
/// period far smaller than its geometry is more likely a mistake than a landscape.
const MAX_WRAPS: i64 = 1024;

/// A repeated scene's period (x-y rectangle): the `period` key, else the ground's extent,
/// else all geometry's.
fn period_of(
    doc: &Doc,
    file: &SceneFile,
    placed: &[PlacedInstance],
) -> Result<(glam::DVec2, glam::DVec2)> {
    if let Some([a, b]) = file.period {
        let ok = a.iter().chain(&b).all(|v| v.is_finite()) && b[0] > a[0] && b[1] > a[1];
        if !ok {
            return Err(doc.error(
                "period",
                format!(
                    "expected [[x0, y0], [x1, y1]] with x1 > x0 and y1 > y0, found {a:?}, {b:?}"
                ),
            ));
        }
        if a.iter().chain(&b).any(|v| v.abs() > MAX_COORDINATE_M) {
            return Err(doc.error(
                "period",
                format!(
                    "coordinates in metres within {} km (the scene's own), found {a:?}, {b:?}",
                    MAX_COORDINATE_M / 1e3
                ),
            ));
        }
        if !file.repeat {
            return Err(doc.error(
                "period",
                "a period belongs to a repeated scene: add repeat: true, or remove period",
            ));
        }
        return Ok((glam::DVec2::from(a), glam::DVec2::from(b)));
    }
    let extent = |ground_only: bool| {
        placed.iter().filter(|p| p.ground || !ground_only).fold(
            None,
            |acc: Option<(DVec3, DVec3)>, p| {
                Some(acc.map_or((p.lo, p.hi), |(lo, hi)| (lo.min(p.lo), hi.max(p.hi))))
            },
        )
    };
    let (lo, hi) = extent(true)
        .or_else(|| extent(false))
        .unwrap_or((DVec3::ZERO, DVec3::ZERO));
    Ok((lo.truncate(), hi.truncate()))
}

/// Copies of the instances that overhang a repeated scene's period, moved by whole periods
/// so that each copy overlaps it: the scene's own geometry then holds every piece of every
/// period's geometry that lies in its period, and a query of one period's column finds what
/// any copy puts there. A flat period side (zero width) does not repeat.
fn wrap_into_period(
    doc: &Doc,
    placed: &mut Vec<PlacedInstance>,
    (lo, hi): (glam::DVec2, glam::DVec2),
) -> Result<bool> {
    let w = hi - lo;
    let mut added = Vec::new();
    for p in placed.iter() {
        // the whole periods k for which p moved by k overlaps [lo, hi) with area
        // in f64 until the count is known to be small: a period of 1e-300 m makes counts no
        // integer holds
        let range = |plo: f64, phi: f64, lo: f64, hi: f64, w: f64| -> (f64, f64) {
            if w <= 0.0 {
                return (0.0, 0.0);
            }
            (
                ((lo - phi) / w).floor() + 1.0,
                ((hi - plo) / w).ceil() - 1.0,
            )
        };
        let (x0, x1) = range(p.lo.x, p.hi.x, lo.x, hi.x, w.x);
        let (y0, y1) = range(p.lo.y, p.hi.y, lo.y, hi.y, w.y);
        let copies = (x1 - x0 + 1.0).max(0.0) * (y1 - y0 + 1.0).max(0.0);
        if copies.is_nan() || copies > MAX_WRAPS as f64 {
            return Err(doc.error(
                "period",
                format!(
                    "an object reaching {:.1} .. {:.1} m spans more than {MAX_WRAPS} periods of {:.3} x {:.3} m: give a larger period",
                    p.lo.truncate(),
                    p.hi.truncate(),
                    w.x,
                    w.y
                ),
            ));
        }
        let (x0, x1, y0, y1) = (x0 as i64, x1 as i64, y0 as i64, y1 as i64);
        for kx in x0..=x1 {
            for ky in y0..=y1 {
                if kx == 0 && ky == 0 {
                    continue;
                }
                let shift = DVec3::new(kx as f64 * w.x, ky as f64 * w.y, 0.0);
                added.push(PlacedInstance {
                    translation: p.translation + shift,
                    lo: p.lo + shift,
                    hi: p.hi + shift,
                    ..*p
                });
            }
        }
    }
    let wrapped = !added.is_empty();
    placed.extend(added);
    Ok(wrapped)
}

/// World transforms and bounds of every instance of every object, in f64.
fn place_instances(plans: &[ObjectPlan], units: &Units, meshes: &[Blas]) -> Vec<PlacedInstance> {
    let identity = [InstanceRow {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        rotation_deg: 0.0,
        scale: 1.0,
    }];
    let mut placed: Vec<PlacedInstance> = Vec::new();
    for ((objects, &mesh), &base) in units.objects.iter().zip(&units.mesh).zip(&units.base) {
        let blas = &meshes[mesh as usize];
        let rows: &[InstanceRow] = plans[objects[0]].rows.as_deref().unwrap_or(&identity);
        for r in rows {
            let (sin, cos) = r.rotation_deg.to_radians().sin_cos();
            let rot = |v: DVec3| DVec3::new(cos * v.x - sin * v.y, sin * v.x + cos * v.y, v.z);
            let translation = DVec3::new(r.x, r.y, r.z) + rot(blas.offset) * r.scale;
            let mut lo = DVec3::splat(f64::INFINITY);
            let mut hi = DVec3::splat(f64::NEG_INFINITY);
            for c in 0..8 {
                let corner = DVec3::new(
                    if c & 1 == 0 { blas.lo.x } else { blas.hi.x } as f64,
                    if c & 2 == 0 { blas.lo.y } else { blas.hi.y } as f64,
                    if c & 4 == 0 { blas.lo.z } else { blas.hi.z } as f64,
                );
                let w = translation + rot(corner) * r.scale;
                lo = lo.min(w);
                hi = hi.max(w);
            }
            placed.push(PlacedInstance {
                translation,
                cos,
                sin,
                scale: r.scale,
                lo,
                hi,
                mesh,
                surfaces: base,
                ground: !plans[objects[0]].is_mesh,
            });
        }
    }
    placed
}

/// The scene's top level: its frame (origin, bounds, clip box) and the instance BVH.
struct TopLevel {
    origin: DVec3,
    world_lo: DVec3,
    world_hi: DVec3,
    clip_lo: DVec3,
    clip_hi: DVec3,
    instances: Vec<Instance>,
    tlas: obvhs::cwbvh::CwBvh,
    instanced_triangles: u64,
}

impl TopLevel {
    fn build(placed: Vec<PlacedInstance>, meshes: &[Blas]) -> TopLevel {
        let mut world_lo = DVec3::splat(f64::INFINITY);
        let mut world_hi = DVec3::splat(f64::NEG_INFINITY);
        for p in &placed {
            world_lo = world_lo.min(p.lo);
            world_hi = world_hi.max(p.hi);
        }
        let origin = (world_lo + world_hi) * 0.5;
        let extent = (world_hi - world_lo).max_element();
        // The clip box must contain every instance box after rounding to f32 and leave room for
        // rays that graze a flat scene (a single plane has zero height).
        let pad = 1e-3 + 1e-6 * extent;
        let clip_lo = world_lo - DVec3::splat(pad);
        let clip_hi = world_hi + DVec3::splat(pad);

        let instance_pad =
            |v: DVec3| (v.abs().max_element() * 4.0 * f32::EPSILON as f64 + 1e-6) as f32;
        let mut instances: Vec<Instance> = Vec::with_capacity(placed.len());
        let mut boxes: Vec<Aabb> = Vec::with_capacity(placed.len());
        let mut instanced_triangles = 0u64;
        for (id, p) in placed.iter().enumerate() {
            let lo = p.lo - origin;
            let hi = p.hi - origin;
            let pad = instance_pad(lo).max(instance_pad(hi));
            boxes.push(Aabb::new(
                Vec3A::from(lo.as_vec3() - pad),
                Vec3A::from(hi.as_vec3() + pad),
            ));
            instances.push(Instance {
                translation: Vec3A::from((p.translation - origin).as_vec3()),
                cos: p.cos as f32,
                sin: p.sin as f32,
                inv_scale: (1.0 / p.scale) as f32,
                mesh: p.mesh,
                surfaces: p.surfaces,
                id: id as u32,
            });
            instanced_triangles += meshes[p.mesh as usize].distinct.len() as u64;
        }
        drop(placed);
        let mut tlas = build_cwbvh(
            &boxes,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        super::bvh::shrink(&mut tlas);
        let instances: Vec<Instance> = tlas
            .primitive_indices
            .iter()
            .map(|&i| instances[i as usize])
            .collect();
        TopLevel {
            origin,
            world_lo,
            world_hi,
            clip_lo,
            clip_hi,
            instances,
            tlas,
            instanced_triangles,
        }
    }
}

/// Materials of a mesh's slots from a `materials:` map: a slot's usemtl name first, then its
/// group (or, for PLY, file stem). Every slot must be mapped and every key must name a slot,
/// so that typos do not pass silently.
fn map_slots<'a>(
    doc: &Doc,
    plan: &ObjectPlan,
    slot_names: &[SlotName],
    map: &'a BTreeMap<String, String>,
) -> Result<Vec<&'a str>> {
    let key = format!("{}.materials", plan.key);
    let mut used: Vec<&str> = Vec::new();
    let mut names = Vec::with_capacity(slot_names.len());
    let file = &plan.file;
    let known = || {
        let mut k: Vec<String> = Vec::new();
        for s in slot_names {
            if let Some(u) = &s.usemtl {
                if !k.contains(u) {
                    k.push(u.clone());
                }
            }
            if !k.contains(&s.group) {
                k.push(s.group.clone());
            }
        }
        k.join(", ")
    };
    for s in slot_names {
        let hit = s
            .usemtl
            .as_ref()
            .and_then(|u| map.get_key_value(u))
            .or_else(|| map.get_key_value(&s.group));
        match hit {
            Some((k, v)) => {
                used.push(k.as_str());
                names.push(v.as_str());
            }
            None => {
                let what = match &s.usemtl {
                    Some(u) => format!("usemtl \"{u}\" (group \"{}\")", s.group),
                    None => format!("\"{}\"", s.group),
                };
                let suggest = s.usemtl.as_ref().unwrap_or(&s.group);
                return Err(doc.error(
                    &key,
                    format!("{what} in {file} has no material here; add `{suggest}: <material>` (names in the file: {})", known()),
                ));
            }
        }
    }
    for k in map.keys() {
        if !used.contains(&k.as_str())
            && !slot_names
                .iter()
                .any(|s| &s.group == k || s.usemtl.as_ref() == Some(k))
        {
            return Err(doc.error(
                &format!("{key}.{k}"),
                format!(
                    "\"{k}\" is not a group or usemtl name of {file} (names there: {})",
                    known()
                ),
            ));
        }
    }
    Ok(names)
}
