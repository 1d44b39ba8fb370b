use super::*;
use crate::rng::Rand;
use std::path::PathBuf;

/// A fresh folder for one test's files.
fn tmp(name: &str) -> crate::testdata::TempDir {
    let d = crate::testdata::TempDir::new(&format!("scene-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scene")
}

const DOWN: DVec3 = DVec3::new(0.0, 0.0, -1.0);
const UP: DVec3 = DVec3::new(0.0, 0.0, 1.0);

fn plane_scene(dir: &Path) -> Scene {
    let p = write(
        dir,
        "scene.yaml",
        "name: plane\nmaterials:\n  soil: { reflectance: { 532: 0.10, 1064: 0.30 } }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [100, 100]], material: soil }\n",
    );
    Scene::load(&p, 1064.0).unwrap()
}

#[test]
fn plane_hit_from_419_km_keeps_f64_precision() {
    let d = tmp("plane419");
    let s = plane_scene(&d);
    assert_eq!(s.name, "plane");
    assert_eq!(s.surfaces.len(), 1);
    assert_eq!(s.surfaces[0].reflectance, 0.30);
    assert_eq!(s.surfaces[0].back_reflectance, 0.30);
    assert_eq!(s.surfaces[0].transmittance, 0.0);
    assert_eq!(s.surfaces[0].class, SurfaceClass::Ground);
    for (x, y) in [(50.0, 50.0), (0.5, 99.25), (73.123456, 12.5)] {
        let h = s
            .intersect(
                DVec3::new(x, y, 419_000.0),
                DOWN,
                f64::INFINITY,
                FacetId::NONE,
            )
            .unwrap();
        assert!(((h.t - 419_000.0) / 419_000.0).abs() < 1e-9, "t = {}", h.t);
        assert!((h.t - 419_000.0).abs() < 1e-6, "t = {}", h.t);
        assert!(h.position.z.abs() < 1e-6);
        assert_eq!(h.normal, UP);
        assert_eq!(h.surface, 0);
        assert_eq!(h.facet.instance, 0);
    }
    // Slanted ray from orbit: 1 degree off nadir.
    let a = 1f64.to_radians();
    let dir = DVec3::new(a.sin(), 0.0, -a.cos());
    let o = DVec3::new(50.0 - 419_000.0 * a.tan(), 50.0, 419_000.0);
    let h = s.intersect(o, dir, f64::INFINITY, FacetId::NONE).unwrap();
    let expect = 419_000.0 / a.cos();
    assert!(
        ((h.t - expect) / expect).abs() < 1e-9,
        "t = {} expected {}",
        h.t,
        expect
    );
    // Misses: outside the extent, pointing away, and a t_max short of the ground.
    assert!(s
        .intersect(
            DVec3::new(150.0, 50.0, 419_000.0),
            DOWN,
            f64::INFINITY,
            FacetId::NONE
        )
        .is_none());
    assert!(s
        .intersect(
            DVec3::new(50.0, 50.0, 419_000.0),
            UP,
            f64::INFINITY,
            FacetId::NONE
        )
        .is_none());
    assert!(s
        .intersect(DVec3::new(50.0, 50.0, 100.0), DOWN, 99.9, FacetId::NONE)
        .is_none());
    assert!(s
        .intersect(DVec3::new(50.0, 50.0, 100.0), DOWN, 100.1, FacetId::NONE)
        .is_some());
    // Directions with negative zero components (e.g. -DVec3::Z) behave like positive zeros.
    let h = s
        .intersect(
            DVec3::new(50.0, 50.0, 10.0),
            -DVec3::Z,
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    assert!((h.t - 10.0).abs() < 1e-9);
    // From below, the back side.
    let h = s
        .intersect(
            DVec3::new(50.0, 50.0, -5.0),
            UP,
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    assert!((h.t - 5.0).abs() < 1e-6);
    assert_eq!(
        h.normal, UP,
        "the normal keeps the front side, it is not flipped towards the ray"
    );
    let (lo, hi) = s.bounds();
    assert_eq!(
        (lo, hi),
        (DVec3::new(0.0, 0.0, 0.0), DVec3::new(100.0, 100.0, 0.0))
    );
    assert_eq!(s.origin, DVec3::new(50.0, 50.0, 0.0));
    let st = s.stats();
    assert_eq!(
        (
            st.distinct_meshes,
            st.distinct_triangles,
            st.instanced_triangles,
            st.instances
        ),
        (1, 2, 2, 1)
    );
    assert!(st.memory_bytes > 0);
}

/// A vertical triangle in the plane x = 2 facing +x, in a group "blade" with usemtl "green".
const BLADE_OBJ: &str =
    "mtllib missing.mtl\no blade\nv 2 -1 0\nv 2 1 0\nv 2 0 2\nusemtl green\nf 1 2 3\n";

#[test]
fn rotated_scaled_instance_of_obj() {
    let d = tmp("instance");
    write(&d, "blade.obj", BLADE_OBJ);
    write(
        &d,
        "where.csv",
        "# x y z rotation scale\n100, 50, 10, 90, 3\n0 0\n",
    );
    let p = write(
        &d,
        "scene.yaml",
        "name: inst\nmaterials:\n  leaf: { reflectance: 0.4, transmittance: 0.5 }\nobjects:\n  - mesh: { file: blade.obj, materials: { green: leaf }, instances: where.csv }\n",
    );
    let s = Scene::load(&p, 1064.0).unwrap();
    assert_eq!(
        s.surfaces[0].class,
        SurfaceClass::Vegetation,
        "a transmitting mesh defaults to vegetation"
    );
    // Mesh point (2, 0, 1) -> scaled (6, 0, 3) -> rotated 90° (0, 6, 3) -> world (100, 56, 13).
    let h = s
        .intersect(
            DVec3::new(100.0, 80.0, 13.0),
            DVec3::new(0.0, -1.0, 0.0),
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    assert!((h.t - 24.0).abs() < 1e-4, "t = {}", h.t);
    assert!((h.position - DVec3::new(100.0, 56.0, 13.0)).length() < 1e-4);
    assert!(
        (h.normal - DVec3::new(0.0, 1.0, 0.0)).length() < 1e-6,
        "normal {}",
        h.normal
    );
    assert_eq!(
        h.facet,
        FacetId {
            instance: 0,
            triangle: 0
        }
    );
    // The scaled triangle spans world x in [97, 103] at z = 10 (base) up to z = 16 (apex).
    assert!(s
        .intersect(
            DVec3::new(102.9, 80.0, 10.1),
            DVec3::new(0.0, -1.0, 0.0),
            f64::INFINITY,
            FacetId::NONE
        )
        .is_some());
    assert!(s
        .intersect(
            DVec3::new(103.1, 80.0, 10.1),
            DVec3::new(0.0, -1.0, 0.0),
            f64::INFINITY,
            FacetId::NONE
        )
        .is_none());
    assert!(s
        .intersect(
            DVec3::new(100.0, 80.0, 16.1),
            DVec3::new(0.0, -1.0, 0.0),
            f64::INFINITY,
            FacetId::NONE
        )
        .is_none());
    // The second row: identity at the origin, facing +x.
    let h = s
        .intersect(
            DVec3::new(10.0, 0.0, 1.0),
            DVec3::new(-1.0, 0.0, 0.0),
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    assert!((h.t - 8.0).abs() < 1e-4, "t = {}", h.t);
    assert_eq!(h.facet.instance, 1);
    assert!((h.normal - DVec3::X).length() < 1e-6);
    let (lo, hi) = s.bounds();
    assert!((lo - DVec3::new(2.0, -1.0, 0.0)).length() < 1e-4, "{lo}");
    assert!((hi - DVec3::new(103.0, 56.0, 16.0)).length() < 1e-4, "{hi}");
    let st = s.stats();
    assert_eq!(
        (
            st.distinct_meshes,
            st.distinct_triangles,
            st.instanced_triangles,
            st.instances
        ),
        (1, 1, 2, 2)
    );
}

#[test]
fn skip_and_occlusion_with_parallel_triangles_1mm_apart() {
    let d = tmp("skip");
    // Triangle 0 at z = 0.001 (listed first), triangle 1 at z = 0.
    write(
        &d,
        "two.obj",
        "v 0 0 0.001\nv 10 0 0.001\nv 0 10 0.001\nv 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\nf 4 5 6\n",
    );
    let p = write(
        &d,
        "scene.yaml",
        "name: two\nmaterials:\n  m: { reflectance: 0.5 }\nobjects:\n  - mesh: { file: two.obj, material: m, class: building }\n",
    );
    let s = Scene::load(&p, 532.0).unwrap();
    assert_eq!(s.surfaces[0].class, SurfaceClass::Building);
    let top = s
        .intersect(
            DVec3::new(1.0, 1.0, 100.0),
            DOWN,
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    assert_eq!(
        top.facet,
        FacetId {
            instance: 0,
            triangle: 0
        }
    );
    assert!((top.t - 99.999).abs() < 1e-5, "t = {}", top.t);
    let low = s
        .intersect(top.position, DOWN, f64::INFINITY, top.facet)
        .unwrap();
    assert_eq!(
        low.facet,
        FacetId {
            instance: 0,
            triangle: 1
        }
    );
    assert!((low.t - 1e-3).abs() < 1e-6, "t = {}", low.t);
    assert!(low.position.z.abs() < 1e-6);
    assert!(s
        .intersect(low.position, DOWN, f64::INFINITY, low.facet)
        .is_none());
    assert!(s
        .intersect(top.position, UP, f64::INFINITY, top.facet)
        .is_none());
    // Going up from the lower triangle meets the upper one 1 mm away.
    let up = s
        .intersect(low.position, UP, f64::INFINITY, low.facet)
        .unwrap();
    assert_eq!(up.facet.triangle, 0);
    assert!((up.t - 1e-3).abs() < 1e-6);

    let n = FacetId::NONE;
    assert!(s.occluded(
        DVec3::new(1.0, 1.0, 10.0),
        DVec3::new(1.0, 1.0, -10.0),
        n,
        n
    ));
    assert!(!s.occluded(DVec3::new(1.0, 1.0, 10.0), DVec3::new(1.0, 1.0, 5.0), n, n));
    assert!(!s.occluded(
        DVec3::new(20.0, 1.0, 10.0),
        DVec3::new(20.0, 1.0, -10.0),
        n,
        n
    ));
    assert!(!s.occluded(DVec3::new(1.0, 1.0, 10.0), DVec3::new(1.0, 1.0, 10.0), n, n));
    assert!(!s.occluded(top.position, DVec3::new(1.0, 1.0, 10.0), top.facet, n));
    assert!(s.occluded(low.position, DVec3::new(1.0, 1.0, 10.0), low.facet, n));
    assert!(!s.occluded(low.position, top.position, low.facet, top.facet));
    assert!(!s.occluded(top.position, low.position, top.facet, low.facet));
    // Far away, long segments: clipping in f64 first.
    assert!(s.occluded(
        DVec3::new(1.0, 1.0, 419_000.0),
        DVec3::new(1.0, 1.0, -1.0),
        n,
        n
    ));
    assert!(!s.occluded(
        DVec3::new(1.0, 1.0, 419_000.0),
        DVec3::new(1.0, 1.0, 0.01),
        n,
        n
    ));
}

#[test]
fn instance_tables() {
    let p = Path::new("trees.csv");
    let rows = parse_instances(
        p,
        "1 2\n# comment\n\n3,4,5\n6 7 8 90  # inline\n9\t10 , 11 45 2.5\n12 13",
    )
    .unwrap();
    assert_eq!(rows.len(), 5);
    assert_eq!(
        rows[0],
        InstanceRow {
            x: 1.0,
            y: 2.0,
            z: 0.0,
            rotation_deg: 0.0,
            scale: 1.0
        }
    );
    assert_eq!(
        rows[1],
        InstanceRow {
            x: 3.0,
            y: 4.0,
            z: 5.0,
            rotation_deg: 0.0,
            scale: 1.0
        }
    );
    assert_eq!(
        rows[2],
        InstanceRow {
            x: 6.0,
            y: 7.0,
            z: 8.0,
            rotation_deg: 90.0,
            scale: 1.0
        }
    );
    assert_eq!(
        rows[3],
        InstanceRow {
            x: 9.0,
            y: 10.0,
            z: 11.0,
            rotation_deg: 45.0,
            scale: 2.5
        }
    );
    assert_eq!(rows[4].x, 12.0);
    assert_eq!(rows[4].y, 13.0);

    let text = "1 2\n1 2\n1 2\n1 2\n1 2\n1 2\n1 2 3 4 5 6\n";
    let e = parse_instances(p, text).unwrap_err();
    assert_eq!(
        e.to_string(),
        "trees.csv:7: expected 2 to 5 columns (x y [z [rotation_deg [scale]]]), found 6"
    );
    let e = parse_instances(p, "1\n").unwrap_err();
    assert_eq!(
        e.to_string(),
        "trees.csv:1: expected 2 to 5 columns (x y [z [rotation_deg [scale]]]), found 1"
    );
    let e = parse_instances(p, "1 2\n1 abc 3\n").unwrap_err();
    assert!(
        e.to_string().starts_with("trees.csv:2: column 2 (y)"),
        "{}",
        e.to_string()
    );
    let e = parse_instances(p, "1 2 0 0 0\n").unwrap_err();
    assert!(
        e.to_string().starts_with("trees.csv:1: column 5 (scale)"),
        "{}",
        e.to_string()
    );
    assert!(parse_instances(p, "1 2 0 0 -1\n").is_err());
    assert!(parse_instances(p, "1 2 0 0 inf\n").is_err());
    assert!(parse_instances(p, "# nothing\n").is_err());
}

#[test]
fn rami_location_file_loads_as_is() {
    let Some(root) = crate::testdata::rami_dir() else {
        return;
    };
    let p = root.join("CISI1/location.txt");
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(
        !text.ends_with('\n'),
        "the RAMI file ends without a newline"
    );
    let rows = parse_instances(&p, &text).unwrap();
    assert_eq!(
        rows.len(),
        text.lines().filter(|l| !l.trim().is_empty()).count()
    );
    assert_eq!(rows[0].x, -51.711683);
    assert_eq!(rows[0].y, -48.016063);
    assert!(rows
        .iter()
        .all(|r| r.z == 0.0 && r.rotation_deg == 0.0 && r.scale == 1.0));
}

#[test]
fn material_errors_are_located() {
    let d = tmp("materials");
    let scene = |text: &str| write(&d, "scene.yaml", text);
    let obj = "objects:\n  - plane: { z: 0, extent: [[0, 0], [1, 1]], material: leaf }\n";

    let p = scene(&format!(
        "name: t\nmaterials:\n  leaf: {{ reflectance: {{ 532: 0.4 }} }}\n{obj}"
    ));
    let e = Scene::load(&p, 1064.0).err().unwrap();
    let want = format!(
        "{}:3:24: materials.leaf.reflectance: no value for 1064 nm (the table gives 532 nm); add 1064: <value> or give a single number",
        p.display()
    );
    assert_eq!(e.to_string(), want);

    // Block style, float keys, a table for transmittance only.
    let p = scene(&format!(
        "name: t\nmaterials:\n  leaf:\n    reflectance: 0.4\n    transmittance:\n      532.5: 0.3\n{obj}"
    ));
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().starts_with(&format!("{}:6:", p.display())),
        "{}",
        e.to_string()
    );
    assert!(
        e.to_string().contains(
            "materials.leaf.transmittance: no value for 1064 nm (the table gives 532.5 nm)"
        ),
        "{}",
        e.to_string()
    );
    let s = Scene::load(&p, 532.5).unwrap();
    assert_eq!(s.surfaces[0].transmittance, 0.3);
    assert_eq!(
        s.surfaces[0].class,
        SurfaceClass::Ground,
        "planes default to ground even when transmitting"
    );

    let p = scene(&format!(
        "name: t\nmaterials:\n  leaf: {{ reflectance: 1.2 }}\n{obj}"
    ));
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains(":3:")
            && e.to_string().contains("materials.leaf.reflectance")
            && e.to_string().contains("[0, 1]"),
        "{}",
        e.to_string()
    );

    let p = scene(&format!(
        "name: t\nmaterials:\n  leaf: {{ reflectance: 0.6, back_reflectance: 0.2, transmittance: 0.5 }}\n{obj}"
    ));
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains("materials.leaf.reflectance") && e.to_string().contains("> 1"),
        "{}",
        e.to_string()
    );
    let p = scene(&format!(
        "name: t\nmaterials:\n  leaf: {{ reflectance: 0.4, back_reflectance: 0.6, transmittance: 0.5 }}\n{obj}"
    ));
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains("materials.leaf.back_reflectance")
            && e.to_string().contains("back side"),
        "{}",
        e.to_string()
    );
    let p = scene(&format!(
        "name: t\nmaterials:\n  leaf: {{ reflectance: 0.4, back_reflectance: 0.3, transmittance: 0.5 }}\n{obj}"
    ));
    let s = Scene::load(&p, 1064.0).unwrap();
    assert_eq!(s.surfaces[0].back_reflectance, 0.3);

    // Undefined material, unknown key, unknown class.
    let p = scene("name: t\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [1, 1]], material: leaf }\n");
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().starts_with(&format!("{}:5:", p.display())),
        "{}",
        e.to_string()
    );
    assert!(
        e.to_string().contains("objects[0].plane.material")
            && e.to_string().contains("\"leaf\"")
            && e.to_string().contains("soil"),
        "{}",
        e.to_string()
    );
    let p = scene("name: t\nmaterials:\n  soil: { reflectance: 0.2, colour: red }\nobjects: []\n");
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains("materials.soil.colour") && e.to_string().contains("unknown field"),
        "{}",
        e.to_string()
    );
    let p = scene("name: t\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [1, 1]], material: soil, class: tree }\n");
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains(":5:") && e.to_string().contains("objects[0].plane.class"),
        "{}",
        e.to_string()
    );
    let p = scene(
        "name: t\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - cube: { size: 1 }\n",
    );
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains(":5:") && e.to_string().contains("objects[0]"),
        "{}",
        e.to_string()
    );
}

#[test]
fn mesh_errors() {
    let d = tmp("mesh-errors");
    let scene = |objects: &str| {
        write(
            &d,
            "scene.yaml",
            &format!("name: t\nmaterials:\n  leaf: {{ reflectance: 0.4, transmittance: 0.4 }}\n  bark: {{ reflectance: 0.3 }}\nobjects:\n{objects}"),
        )
    };
    let load = |p: &Path| Scene::load(p, 1064.0).err().unwrap().to_string();

    let p = scene("  - mesh: { file: nowhere.obj, material: bark }\n");
    let e = load(&p);
    assert!(
        e.contains("nowhere.obj")
            && e.contains("does not exist")
            && e.contains("objects[0].mesh.file"),
        "{e}"
    );

    write(&d, "blade.obj", BLADE_OBJ);
    let p = scene("  - mesh: { file: blade.obj, material: bark, instances: nowhere.csv }\n");
    let e = load(&p);
    assert!(
        e.contains("nowhere.csv") && e.contains("objects[0].mesh.instances"),
        "{e}"
    );

    let p = scene("  - mesh: { file: blade.obj, materials: { trunk: bark } }\n");
    let e = load(&p);
    assert!(
        e.contains("usemtl \"green\"")
            && e.contains("objects[0].mesh.materials")
            && e.contains(":6:"),
        "{e}"
    );
    // The group name works as well as the usemtl name.
    let p = scene("  - mesh: { file: blade.obj, materials: { blade: bark } }\n");
    let s = Scene::load(&p, 1064.0).unwrap();
    assert_eq!(s.surfaces[0].class, SurfaceClass::Other);
    let p = scene("  - mesh: { file: blade.obj, materials: { green: bark, trunk: bark } }\n");
    let e = load(&p);
    assert!(
        e.contains("objects[0].mesh.materials.trunk") && e.contains("\"trunk\""),
        "{e}"
    );
    let p = scene("  - mesh: { file: blade.obj }\n");
    assert!(load(&p).contains("material"));
    let p = scene("  - mesh: { file: blade.obj, material: bark, materials: { green: bark } }\n");
    assert!(load(&p).contains("either"));

    write(&d, "empty.obj", "v 0 0 0\nv 1 0 0\n");
    let e = load(&scene("  - mesh: { file: empty.obj, material: bark }\n"));
    assert!(
        e.contains("empty.obj") && e.contains("mesh has no triangles"),
        "{e}"
    );
    write(
        &d,
        "flat.obj",
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n",
    );
    let e = load(&scene("  - mesh: { file: flat.obj, material: bark }\n"));
    assert!(e.contains("flat.obj") && e.contains("zero area"), "{e}");
    write(&d, "oob.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n");
    let e = load(&scene("  - mesh: { file: oob.obj, material: bark }\n"));
    assert!(
        e.contains("oob.obj:4:") && e.contains("out of range"),
        "{e}"
    );
    write(&d, "junk.obj", "v 0 0 0\nv 0 0 zero\nf 1 2 3\n");
    let e = load(&scene("  - mesh: { file: junk.obj, material: bark }\n"));
    assert!(
        e.contains("junk.obj:2:") && e.contains("cannot parse OBJ"),
        "{e}"
    );
    write(&d, "junkf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n");
    let e = load(&scene("  - mesh: { file: junkf.obj, material: bark }\n"));
    assert!(
        e.contains("junkf.obj:4:") && e.contains("cannot parse OBJ"),
        "{e}"
    );
    // One degenerate triangle among good ones is dropped silently.
    write(
        &d,
        "mixed.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n",
    );
    let s = Scene::load(
        &scene("  - mesh: { file: mixed.obj, material: leaf }\n"),
        1064.0,
    )
    .unwrap();
    assert_eq!(s.stats().distinct_triangles, 1);
    assert_eq!(s.surfaces[0].class, SurfaceClass::Vegetation);

    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n";
    write(&d, "oob.ply", ply);
    let e = load(&scene("  - mesh: { file: oob.ply, material: bark }\n"));
    assert!(e.contains("oob.ply") && e.contains("out of range"), "{e}");
    write(
        &d,
        "bad.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n0\n",
    );
    let e = load(&scene("  - mesh: { file: bad.ply, material: bark }\n"));
    assert!(e.contains("bad.ply") && e.contains("PLY"), "{e}");
    write(&d, "mesh.stl", "solid");
    let e = load(&scene("  - mesh: { file: mesh.stl, material: bark }\n"));
    assert!(e.contains("mesh.stl") && e.contains("unsupported"), "{e}");
}

/// A unit square at z = 1 as two PLY triangles, in binary with the given byte order, vertices
/// as doubles (big-endian) or floats (little-endian), with an extra property and element.
fn binary_ply(big_endian: bool) -> Vec<u8> {
    let (fmt, vtype, itype) = if big_endian {
        ("binary_big_endian", "double", "ushort")
    } else {
        ("binary_little_endian", "float", "int")
    };
    let mut out = format!(
        "ply\nformat {fmt} 1.0\ncomment test\nelement vertex 4\nproperty {vtype} x\nproperty {vtype} y\nproperty {vtype} z\nproperty uchar red\nelement face 2\nproperty list uchar {itype} vertex_indices\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
    )
    .into_bytes();
    for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
        for v in [x, y, 1.0f64] {
            if big_endian {
                out.extend(v.to_be_bytes());
            } else {
                out.extend((v as f32).to_le_bytes());
            }
        }
        out.push(200);
    }
    for f in [[0u32, 1, 2], [0, 2, 3]] {
        out.push(3);
        for i in f {
            if big_endian {
                out.extend((i as u16).to_be_bytes());
            } else {
                out.extend((i as i32).to_le_bytes());
            }
        }
    }
    if big_endian {
        out.extend(0i32.to_be_bytes());
        out.extend(1i32.to_be_bytes());
    } else {
        out.extend(0i32.to_le_bytes());
        out.extend(1i32.to_le_bytes());
    }
    out
}

#[test]
fn ply_ascii_and_binary() {
    let d = tmp("ply");
    std::fs::write(d.join("le.ply"), binary_ply(false)).unwrap();
    std::fs::write(d.join("be.ply"), binary_ply(true)).unwrap();
    let ascii = fixtures().join("quad_ascii.ply");
    for (file, mapping) in [
        (ascii.display().to_string(), "material: soil".to_string()),
        ("le.ply".into(), "materials: { le: soil }".into()),
        ("be.ply".into(), "material: soil".into()),
    ] {
        let p = write(
            &d,
            "scene.yaml",
            &format!("name: ply\nmaterials:\n  soil: {{ reflectance: 0.2 }}\nobjects:\n  - mesh: {{ file: {file}, {mapping} }}\n"),
        );
        let s = Scene::load(&p, 1064.0).unwrap_or_else(|e| panic!("{file}: {e}"));
        let st = s.stats();
        assert_eq!((st.distinct_triangles, st.instances), (2, 1), "{file}");
        assert_eq!(
            s.bounds(),
            (DVec3::new(0.0, 0.0, 1.0), DVec3::new(1.0, 1.0, 1.0)),
            "{file}"
        );
        for (x, y) in [(0.25, 0.75), (0.75, 0.25), (0.5, 0.5)] {
            let h = s
                .intersect(DVec3::new(x, y, 10.0), DOWN, f64::INFINITY, FacetId::NONE)
                .unwrap();
            assert!((h.t - 9.0).abs() < 1e-6, "{file}: t = {}", h.t);
            assert_eq!(h.normal, UP, "{file}");
        }
        assert_eq!(s.surfaces[0].class, SurfaceClass::Other);
    }
    let p = write(
        &d,
        "scene.yaml",
        "name: ply\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - mesh: { file: le.ply, materials: { foliage: soil } }\n",
    );
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains("\"le\"") && e.to_string().contains("le: <material>"),
        "{}",
        e.to_string()
    );
    // a vertex line the ply crate cannot read: its several-line message told on one line
    let ascii = std::fs::read_to_string(fixtures().join("quad_ascii.ply")).unwrap();
    let broken = ascii.replacen("\n1 0 1 0", "\nzero 0 1 0", 1);
    assert_ne!(broken, ascii, "the test edits a vertex line");
    write(&d, "broken.ply", &broken);
    let p = write(
        &d,
        "broken.yaml",
        "name: ply\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - mesh: { file: broken.ply, material: soil }\n",
    );
    let e = Scene::load(&p, 1064.0).err().unwrap().to_string();
    assert!(
        e.contains("cannot parse PLY") && e.lines().count() == 1,
        "{e}"
    );
    // at the file's line, without the parser's internals
    let line = broken.lines().position(|l| l.starts_with("zero")).unwrap() + 1;
    assert!(e.contains(&format!("broken.ply:{line}: ")), "{e}");
    assert!(!e.contains("ParseError") && !e.contains("Line "), "{e}");
}

/// An OBJ file that starts with a byte-order mark (as Windows editors write) reads as without.
#[test]
fn an_obj_with_a_byte_order_mark_loads() {
    let d = tmp("obj_bom");
    write(
        &d,
        "bom.obj",
        "\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let p = write(
        &d,
        "scene.yaml",
        "name: bom\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - mesh: { file: bom.obj, material: soil }\n",
    );
    let scene = Scene::load(&p, 1064.0).unwrap();
    assert_eq!(scene.stats().distinct_triangles, 1);
}

/// Objects placed by equal instance tables (a tree's foliage and trunk) are traced as one mesh,
/// each triangle keeping its own object's material and class; other tables keep them apart.
#[test]
fn objects_placed_alike_are_one_mesh() {
    let d = tmp("placed_alike");
    // a horizontal leaf at z = 2 and an upright blade (the trunk) in the plane x = 2
    write(
        &d,
        "leaf.obj",
        "v -1 -1 2\nv 1 -1 2\nv 1 1 2\nv -1 1 2\nf 1 2 3\nf 1 3 4\n",
    );
    write(&d, "trunk.obj", BLADE_OBJ);
    write(&d, "trees.csv", "0 0\n10 0\n");
    write(&d, "others.csv", "0 0\n20 0\n");
    let scene = |trunks: &str| {
        let p = write(
            &d,
            "scene.yaml",
            &format!("name: alike\nmaterials:\n  leaf: {{ reflectance: 0.4, transmittance: 0.5 }}\n  bark: {{ reflectance: 0.3 }}\nobjects:\n  - mesh: {{ file: leaf.obj, material: leaf, instances: trees.csv }}\n  - mesh: {{ file: trunk.obj, material: bark, class: building, instances: {trunks} }}\n"),
        );
        Scene::load(&p, 1064.0).unwrap()
    };
    let s = scene("trees.csv");
    let st = s.stats();
    assert_eq!((st.distinct_meshes, st.instances), (2, 4));
    assert_eq!((st.traced_meshes, st.traced_instances), (1, 2));
    assert_eq!(st.instanced_triangles, 2 * 3);
    // each tree's leaf from above, its trunk from the side: the second tree is at x = 10
    for x0 in [0.0, 10.0] {
        let h = s
            .intersect(
                DVec3::new(x0 + 0.5, 0.5, 10.0),
                DOWN,
                f64::INFINITY,
                FacetId::NONE,
            )
            .unwrap();
        let leaf = &s.surfaces[h.surface as usize];
        assert!((h.position.z - 2.0).abs() < 1e-5, "{}", h.position);
        assert_eq!(
            (leaf.name.as_str(), leaf.class),
            ("leaf", SurfaceClass::Vegetation)
        );
        let h = s
            .intersect(
                DVec3::new(x0 + 5.0, 0.0, 0.5),
                -DVec3::X,
                f64::INFINITY,
                FacetId::NONE,
            )
            .unwrap();
        let bark = &s.surfaces[h.surface as usize];
        assert!((h.position.x - (x0 + 2.0)).abs() < 1e-5, "{}", h.position);
        assert_eq!(
            (bark.name.as_str(), bark.class),
            ("bark", SurfaceClass::Building)
        );
    }
    let st = scene("others.csv").stats();
    assert_eq!((st.traced_meshes, st.traced_instances), (2, 4));
}

#[test]
fn heightfield_and_shared_meshes() {
    let d = tmp("heightfield");
    write(&d, "dem.csv", "0, 0, 0\n1, 1, 1\n2, 2, 2\n");
    write(&d, "blade.obj", BLADE_OBJ);
    write(&d, "a.csv", "0 0\n5 5\n");
    let p = write(
        &d,
        "scene.yaml",
        "name: hf\nmaterials:\n  soil: { reflectance: 0.2 }\n  leaf: { reflectance: 0.4, transmittance: 0.5 }\nobjects:\n  - heightfield: { file: dem.csv, cell_m: 2.0, material: soil, origin: [1000, 2000] }\n  - mesh: { file: blade.obj, material: leaf, instances: a.csv }\n  - mesh: { file: ./blade.obj, material: soil, class: other }\n",
    );
    let s = Scene::load(&p, 1064.0).unwrap();
    let st = s.stats();
    assert_eq!(st.distinct_meshes, 2, "blade.obj is loaded once");
    assert_eq!(st.instances, 4);
    assert_eq!(st.distinct_triangles, 8 + 1);
    assert_eq!(st.instanced_triangles, 8 + 3);
    // traced alike: objects without a table are not fused
    assert_eq!((st.traced_meshes, st.traced_instances), (2, 4));
    assert_eq!(
        s.bounds(),
        (DVec3::new(2.0, -1.0, 0.0), DVec3::new(1004.0, 2004.0, 2.0))
    );
    // Row i at y = 2000 + 2i has z = i: the slope is 1/2 along y.
    let h = s
        .intersect(
            DVec3::new(1001.0, 2001.0, 100.0),
            DOWN,
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    assert!((h.position.z - 0.5).abs() < 1e-5, "{}", h.position);
    let n = DVec3::new(0.0, -0.5, 1.0).normalize();
    assert!((h.normal - n).length() < 1e-6, "{}", h.normal);
    assert_eq!(s.surfaces[h.surface as usize].name, "soil");
    assert_eq!(s.surfaces[h.surface as usize].class, SurfaceClass::Ground);
    // Same mesh in two objects with different materials, coincident at the origin: whichever
    // is found first, skipping it finds the other at the same distance.
    let a = s
        .intersect(
            DVec3::new(10.0, 0.0, 1.0),
            -DVec3::X,
            f64::INFINITY,
            FacetId::NONE,
        )
        .unwrap();
    let b = s
        .intersect(
            DVec3::new(10.0, 0.0, 1.0),
            -DVec3::X,
            f64::INFINITY,
            a.facet,
        )
        .unwrap();
    let mut found = [a.facet.instance, b.facet.instance];
    found.sort();
    assert_eq!(found, [1, 3]);
    assert!((a.t - 8.0).abs() < 1e-5 && (b.t - a.t).abs() < 1e-9);
    let by_instance = |h: &Hit| &s.surfaces[h.surface as usize];
    let (leaf, soil) = if a.facet.instance == 1 {
        (by_instance(&a), by_instance(&b))
    } else {
        (by_instance(&b), by_instance(&a))
    };
    assert_eq!(
        (leaf.name.as_str(), leaf.class),
        ("leaf", SurfaceClass::Vegetation)
    );
    assert_eq!(
        (soil.name.as_str(), soil.class),
        ("soil", SurfaceClass::Other)
    );

    write(&d, "ragged.csv", "0 0 0\n# ok\n1 1\n");
    let p = write(
        &d,
        "scene.yaml",
        "name: hf\nmaterials:\n  soil: { reflectance: 0.2 }\nobjects:\n  - heightfield: { file: ragged.csv, cell_m: 1.0, material: soil }\n",
    );
    let e = Scene::load(&p, 1064.0).err().unwrap();
    assert!(
        e.to_string().contains("ragged.csv:3:") && e.to_string().contains("same length"),
        "{}",
        e.to_string()
    );
}

#[test]
fn rami_orchard() {
    let Some(root) = crate::testdata::rami_dir() else {
        return;
    };
    let yaml = fixtures().join("rami_wco_test.yaml");
    let t = std::time::Instant::now();
    let s = Scene::load(&yaml, 1064.0).unwrap();
    let secs = t.elapsed().as_secs_f64();
    let st = s.stats();

    let faces = |p: &Path| -> u64 {
        let bytes = std::fs::read(p).unwrap();
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(2000)]).into_owned();
        let line = head
            .lines()
            .find(|l| l.starts_with("element face"))
            .unwrap();
        line.split_whitespace().nth(2).unwrap().parse().unwrap()
    };
    let (mut trees, mut distinct, mut instanced) = (0u64, 0u64, 0u64);
    for i in 1..=10 {
        let dir = root.join(format!("CISI{i}"));
        let text = std::fs::read_to_string(dir.join("location.txt")).unwrap();
        let n = text.lines().filter(|l| !l.trim().is_empty()).count() as u64;
        let f = faces(&dir.join("foliage.ply")) + faces(&dir.join("trunk.ply"));
        trees += n;
        distinct += f;
        instanced += f * n;
    }
    println!(
        "RAMI WCO: loaded in {secs:.2} s; {} meshes, {} distinct triangles, {} instanced, {} instances, {:.1} MB",
        st.distinct_meshes,
        st.distinct_triangles,
        st.instanced_triangles,
        st.instances,
        st.memory_bytes as f64 / 1e6
    );
    assert_eq!(trees, 1115);
    assert_eq!(st.instances, 2 * 1115);
    assert_eq!(st.distinct_meshes, 20);
    // each tree's foliage and trunk, placed by the same table, are traced as one mesh
    assert_eq!((st.traced_meshes, st.traced_instances), (10, 1115));
    assert_eq!(
        st.distinct_triangles, distinct,
        "no RAMI triangle is degenerate"
    );
    assert_eq!(st.instanced_triangles, instanced);
    assert!((st.memory_bytes as f64) < 2e9);
    let (lo, hi) = s.bounds();
    assert!(
        lo.x > -60.0 && hi.x < 60.0 && lo.y > -60.0 && hi.y < 60.0 && lo.z > -1.0 && hi.z < 20.0,
        "{lo} {hi}"
    );
    let leaf = s.surfaces.iter().find(|x| x.name == "leaf").unwrap();
    assert_eq!(leaf.class, SurfaceClass::Vegetation);

    // A nadir grid from orbit: a good share of rays hit the canopy; none hits below ground.
    let t = std::time::Instant::now();
    let (mut hits, mut n) = (0usize, 0usize);
    let mut x = lo.x;
    while x < hi.x {
        let mut y = lo.y;
        while y < hi.y {
            n += 1;
            if let Some(h) = s.intersect(
                DVec3::new(x, y, 419_000.0),
                DOWN,
                f64::INFINITY,
                FacetId::NONE,
            ) {
                hits += 1;
                assert!(h.position.z > -1e-3 && h.position.z <= hi.z + 1e-3);
                assert!(s.occluded(
                    DVec3::new(x, y, 419_000.0),
                    DVec3::new(x, y, -1.0),
                    FacetId::NONE,
                    FacetId::NONE
                ));
            }
            y += 0.25;
        }
        x += 0.25;
    }
    println!(
        "RAMI WCO: {n} nadir rays ({hits} hits) in {:.2} s on one thread",
        t.elapsed().as_secs_f64()
    );
    assert!(hits > n / 10);

    // Many threads at once, random directions from above the canopy.
    use rayon::prelude::*;
    let t = std::time::Instant::now();
    let rays = 400_000u64;
    let hits: u64 = (0..rays)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rand::new(i ^ 0xABCDEF);
            let o = DVec3::new(rng.range(-54.0, 54.0), rng.range(-52.0, 52.0), 10.0);
            let z = -rng.range(0.2, 1.0);
            let phi = rng.range(0.0, std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            let dir = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            s.intersect(o, dir, f64::INFINITY, FacetId::NONE).is_some() as u64
        })
        .sum();
    let secs = t.elapsed().as_secs_f64();
    println!(
        "RAMI WCO: {rays} random rays ({hits} hits) in {secs:.2} s on {} threads: {:.2} M rays/s",
        rayon::current_num_threads(),
        rays as f64 / secs / 1e6
    );
}

#[test]
fn scene_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<Scene>();
}

/// Closest hit by brute force in f64 over every placed triangle (`per_instance` triangles
/// each instance): (t, instance, triangle, smallest barycentric coordinate).
fn brute_force(
    world: &[[DVec3; 3]],
    per_instance: usize,
    o: DVec3,
    d: DVec3,
) -> Option<(f64, u32, u32, f64)> {
    let mut best: Option<(f64, u32, u32, f64)> = None;
    for (n, &[a, b, cc]) in world.iter().enumerate() {
        let e1 = b - a;
        let e2 = cc - a;
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-14 {
            continue;
        }
        let tv = o - a;
        let u = tv.dot(p) / det;
        let q = tv.cross(e1);
        let v = d.dot(q) / det;
        let tt = e2.dot(q) / det;
        let m = u.min(v).min(1.0 - u - v);
        if m >= 0.0 && tt > 0.0 && best.is_none_or(|bb| tt < bb.0) {
            let (i, k) = (n / per_instance, n % per_instance);
            best = Some((tt, i as u32, k as u32, m));
        }
    }
    best
}

/// 300 random triangles within 4 m, placed 25 times (rotated, scaled 0.5-2) over 30 m × 30 m:
/// the scene, its triangles as written and its instance rows as the loader parsed them.
fn soup_scene(name: &str, rng: &mut Rand) -> (Scene, Vec<[DVec3; 3]>, Vec<InstanceRow>) {
    let d = tmp(name);
    let mut obj = String::from("o soup\n");
    let mut tris = Vec::new();
    for k in 0..300 {
        let c = DVec3::new(
            rng.range(-2.0, 2.0),
            rng.range(-2.0, 2.0),
            rng.range(0.0, 4.0),
        );
        let mut t = [DVec3::ZERO; 3];
        for v in t.iter_mut() {
            *v = c + DVec3::new(
                rng.range(-0.4, 0.4),
                rng.range(-0.4, 0.4),
                rng.range(-0.4, 0.4),
            );
            obj += &format!("v {} {} {}\n", v.x, v.y, v.z);
        }
        obj += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
        tris.push(t);
    }
    write(&d, "soup.obj", &obj);
    let mut table = String::new();
    for _ in 0..25 {
        let r = InstanceRow {
            x: rng.range(0.0, 30.0),
            y: rng.range(0.0, 30.0),
            z: rng.range(0.0, 2.0),
            rotation_deg: rng.range(0.0, 360.0),
            scale: rng.range(0.5, 2.0),
        };
        table += &format!("{} {} {} {} {}\n", r.x, r.y, r.z, r.rotation_deg, r.scale);
    }
    write(&d, "soup.csv", &table);
    let p = write(
        &d,
        "scene.yaml",
        "name: soup\nmaterials:\n  m: { reflectance: 0.5 }\nobjects:\n  - mesh: { file: soup.obj, material: m, instances: soup.csv }\n",
    );
    let s = Scene::load(&p, 1064.0).unwrap();
    // The rows as parsed back, so the comparison sees the same numbers as the loader.
    let rows = parse_instances(&d.join("soup.csv"), &table).unwrap();
    (s, tris, rows)
}

/// The soup's triangles in world coordinates, one instance after another.
fn placed(tris: &[[DVec3; 3]], rows: &[InstanceRow]) -> Vec<[DVec3; 3]> {
    let mut out = Vec::new();
    for r in rows {
        let (s, c) = r.rotation_deg.to_radians().sin_cos();
        let w = |v: DVec3| {
            DVec3::new(r.x, r.y, r.z)
                + DVec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z) * r.scale
        };
        out.extend(tris.iter().map(|t| [w(t[0]), w(t[1]), w(t[2])]));
    }
    out
}

#[test]
fn two_level_tracing_matches_brute_force() {
    let mut rng = Rand::new(12345);
    let (s, tris, rows) = soup_scene("bruteforce", &mut rng);
    let world = placed(&tris, &rows);
    let (mut checked, mut hits) = (0, 0);
    for i in 0..4000 {
        let o = if i % 2 == 0 {
            DVec3::new(
                rng.range(-5.0, 35.0),
                rng.range(-5.0, 35.0),
                rng.range(10.0, 1000.0),
            )
        } else {
            DVec3::new(
                rng.range(-5.0, 35.0),
                rng.range(-5.0, 35.0),
                rng.range(-2.0, 10.0),
            )
        };
        let target = DVec3::new(
            rng.range(0.0, 30.0),
            rng.range(0.0, 30.0),
            rng.range(0.0, 6.0),
        );
        let dir = (target - o).normalize();
        let bf = brute_force(&world, tris.len(), o, dir);
        let got = s.intersect(o, dir, f64::INFINITY, FacetId::NONE);
        match (bf, got) {
            (Some((t, inst, tri, margin)), Some(h)) => {
                hits += 1;
                if margin > 1e-4 {
                    checked += 1;
                    assert!(
                        (h.t - t).abs() < 1e-4 * t.max(1.0),
                        "ray {i}: t {} vs {t}",
                        h.t
                    );
                    // A different facet is fine only when it lies at the same distance.
                    if (h.facet.instance, h.facet.triangle) != (inst, tri) {
                        assert!(
                            (h.t - t).abs() < 1e-5 * t.max(1.0),
                            "ray {i}: facet {:?} vs ({inst}, {tri})",
                            h.facet
                        );
                    }
                    assert!(
                        s.occluded(o, o + dir * (t + 0.01), FacetId::NONE, FacetId::NONE),
                        "ray {i}"
                    );
                    assert!(
                        !s.occluded(
                            o,
                            o + dir * (t - 0.01).max(0.0),
                            FacetId::NONE,
                            FacetId::NONE
                        ),
                        "ray {i}"
                    );
                }
            }
            (Some((_, _, _, margin)), None) => {
                assert!(margin < 1e-4, "ray {i}: missed a clear hit")
            }
            (None, Some(h)) => panic!("ray {i}: hit at t = {} where brute force finds none", h.t),
            (None, None) => {}
        }
    }
    assert!(
        hits > 500 && checked > 400,
        "hits {hits}, checked {checked}"
    );
}

/// An instance table of `n` rows over 30 m × 30 m, raised up to `top` m, turned and scaled
/// 0.5-2 at random.
fn placements(rng: &mut Rand, n: usize, top: f64) -> String {
    (0..n)
        .map(|_| {
            format!(
                "{} {} {} {} {}\n",
                rng.range(0.0, 30.0),
                rng.range(0.0, 30.0),
                rng.range(0.0, top),
                rng.range(0.0, 360.0),
                rng.range(0.5, 2.0)
            )
        })
        .collect()
}

/// Rays that leave a facet of a flat mesh (the ground plane, and a flat square instanced
/// turned, scaled and raised among the soup) and segments that start or end on one get the
/// same answers, to the bit, whether or not the queries leave the flat mesh out.
#[test]
fn leaving_a_flat_mesh_out_changes_no_answer() {
    let mut rng = Rand::new(777);
    let d = tmp("flat_skip");
    let mut obj = String::from("o soup\n");
    for k in 0..300 {
        let c = DVec3::new(
            rng.range(-2.0, 2.0),
            rng.range(-2.0, 2.0),
            rng.range(0.5, 4.0),
        );
        for _ in 0..3 {
            let v = c + DVec3::new(
                rng.range(-0.4, 0.4),
                rng.range(-0.4, 0.4),
                rng.range(-0.4, 0.4),
            );
            obj += &format!("v {} {} {}\n", v.x, v.y, v.z);
        }
        obj += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    write(&d, "soup.obj", &obj);
    write(&d, "soup.csv", &placements(&mut rng, 25, 2.0));
    // a flat 2 m × 2 m square of four triangles at height 1.5, placed 10 times
    write(
        &d,
        "square.obj",
        "o square\nv -1 -1 1.5\nv 1 -1 1.5\nv 1 1 1.5\nv -1 1 1.5\nv 0 0 1.5\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n",
    );
    write(&d, "square.csv", &placements(&mut rng, 10, 3.0));
    let p = write(
        &d,
        "scene.yaml",
        "name: flat\nmaterials:\n  m: { reflectance: 0.5, transmittance: 0.2 }\nobjects:\n  - plane: { z: 0, extent: [[-5, -5], [35, 35]], material: m }\n  - mesh: { file: soup.obj, material: m, instances: soup.csv }\n  - mesh: { file: square.obj, material: m, instances: square.csv }\n",
    );
    let flat = Scene::load(&p, 1064.0).unwrap();
    let mut full = Scene::load(&p, 1064.0).unwrap();
    assert_eq!(full.forget_flat(), 2, "the plane and the square are flat");
    let key = |h: Option<Hit>| {
        h.map(|h| {
            (
                h.t.to_bits(),
                h.facet,
                h.position.to_array().map(f64::to_bits),
            )
        })
    };
    let (mut on_flat, mut blocked) = (0usize, 0usize);
    for i in 0..20_000 {
        let o = DVec3::new(
            rng.range(-5.0, 35.0),
            rng.range(-5.0, 35.0),
            rng.range(5.0, 50.0),
        );
        let target = DVec3::new(rng.range(0.0, 30.0), rng.range(0.0, 30.0), 0.0);
        let Some(h) = full.intersect(o, (target - o).normalize(), f64::INFINITY, FacetId::NONE)
        else {
            continue;
        };
        if h.normal.z.abs() < 0.999_999 {
            continue;
        }
        on_flat += 1;
        // up and down (through a transmitting facet), some nearly grazing
        let z = if i % 3 == 0 {
            rng.range(-1.0, 1.0)
        } else {
            rng.range(-0.02, 0.02)
        };
        let phi = rng.range(0.0, std::f64::consts::TAU);
        let r = (1.0 - z * z).sqrt();
        let dir = DVec3::new(r * phi.cos(), r * phi.sin(), z);
        assert_eq!(
            key(flat.intersect(h.position, dir, f64::INFINITY, h.facet)),
            key(full.intersect(h.position, dir, f64::INFINITY, h.facet)),
            "ray {i} leaving {:?}",
            h.facet
        );
        let far = h.position + dir * rng.range(0.1, 40.0);
        let (a, b) = (
            flat.occluded(h.position, far, h.facet, FacetId::NONE),
            full.occluded(h.position, far, h.facet, FacetId::NONE),
        );
        assert_eq!(a, b, "segment {i} from {:?}", h.facet);
        blocked += a as usize;
        assert_eq!(
            flat.occluded(far, h.position, FacetId::NONE, h.facet),
            full.occluded(far, h.position, FacetId::NONE, h.facet),
            "segment {i} to {:?}",
            h.facet
        );
    }
    assert!(
        on_flat > 10_000 && blocked > 500,
        "{on_flat} rays from flat facets, {blocked} blocked"
    );
}

/// Distance from `p` to the triangle `t` in f64, by another route than the scene's: the
/// foot on the plane if it lies inside, else the nearest of the three edges.
fn distance_to_triangle(p: DVec3, t: &[DVec3; 3]) -> f64 {
    let segment = |a: DVec3, b: DVec3| {
        let ab = b - a;
        let u = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
        (p - (a + ab * u)).length()
    };
    let edges = segment(t[0], t[1])
        .min(segment(t[1], t[2]))
        .min(segment(t[2], t[0]));
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    if n.length_squared() == 0.0 {
        return edges;
    }
    let n = n.normalize();
    let h = (p - t[0]).dot(n);
    let foot = p - n * h;
    let inside = (0..3).all(|k| {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        (b - a).cross(foot - a).dot(n) >= 0.0
    });
    if inside {
        h.abs()
    } else {
        edges
    }
}

/// The nearest facet's distance equals brute force over every placed triangle, for points
/// among, beside and above rotated and scaled instances, and stops at the reach asked.
#[test]
fn nearest_surface_matches_brute_force() {
    let mut rng = Rand::new(777);
    let (s, tris, rows) = soup_scene("nearest", &mut rng);
    let world = placed(&tris, &rows);
    let (mut near, mut capped) = (0, 0);
    for i in 0..3000 {
        let p = DVec3::new(
            rng.range(-5.0, 35.0),
            rng.range(-5.0, 35.0),
            rng.range(-2.0, 10.0),
        );
        let reach = if i % 3 == 0 { 0.3 } else { 50.0 };
        let exact = world
            .iter()
            .map(|t| distance_to_triangle(p, t))
            .fold(f64::INFINITY, f64::min);
        let got = s.nearest_surface(p, reach);
        if exact >= reach {
            assert_eq!(
                got, reach,
                "point {i} at {p}: {got} where none is within {reach}"
            );
            capped += 1;
        } else {
            assert!(
                (got - exact).abs() < 2e-5 * (1.0 + exact),
                "point {i} at {p}: {got} against {exact}"
            );
            near += (exact < 0.3) as usize;
        }
    }
    assert!(near > 100 && capped > 100, "near {near}, capped {capped}");
}

/// In a repeated scene the copy across the period's edge is as near as it looks: a wall
/// 0.1 m inside one edge stands 0.15 m from a point 0.05 m inside the other.
#[test]
fn nearest_surface_sees_the_next_copy() {
    let d = tmp("nearest-repeat");
    write(
        &d,
        "wall.obj",
        "v 4.9 -1 0\nv 4.9 1 0\nv 4.9 0 2\nf 1 2 3\n",
    );
    let p = write(
        &d,
        "scene.yaml",
        "name: walls\nrepeat: true\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[-5, -5], [5, 5]], material: soil }\n  - mesh: { file: wall.obj, material: soil }\n",
    );
    let s = Scene::load(&p, 1064.0).unwrap();
    let at = DVec3::new(-4.95, 0.0, 0.5);
    assert!((s.nearest_surface(at, 1.0) - 0.15).abs() < 1e-5);
    // and the copy two periods on, from the far side
    let far = at + DVec3::new(20.0, 0.0, 0.0);
    assert!((s.nearest_surface(far, 1.0) - 0.15).abs() < 1e-5);
    // over the ground alone, the height
    let open = DVec3::new(0.0, 3.0, 0.7);
    assert!((s.nearest_surface(open, 1.0) - 0.7).abs() < 1e-5);
}

#[test]
fn bundled_scenes_load() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    for name in ["plane.yaml", "sphere.yaml", "rami_wco.yaml"] {
        let p = root.join(name);
        if name == "rami_wco.yaml" && crate::testdata::rami_dir().is_none() {
            continue;
        }
        for wl in [532.0, 1064.0] {
            let s = Scene::load(&p, wl).unwrap_or_else(|e| panic!("{e}"));
            let st = s.stats();
            println!("{name} at {wl} nm: {st:?}, bounds {:?}", s.bounds());
        }
    }
    let p = root.join("sphere.yaml");
    if p.exists() {
        // From the centre every direction meets the wall at about 10 m.
        let s = Scene::load(&p, 1064.0).unwrap();
        let mut rng = Rand::new(7);
        for _ in 0..2000 {
            let z = rng.range(-1.0, 1.0);
            let phi = rng.range(0.0, std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            let dir = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            let h = s
                .intersect(DVec3::ZERO, dir, f64::INFINITY, FacetId::NONE)
                .expect("closed sphere");
            assert!(h.t > 9.9 && h.t <= 10.0 + 1e-6, "t = {}", h.t);
            assert!(
                h.normal.dot(dir).abs() > 0.99,
                "normal {} for direction {dir}",
                h.normal
            );
            // A path bouncing inside never leaves.
            let inward = -dir;
            let out = (DVec3::new(-inward.y, inward.x, 0.0).normalize_or(DVec3::X) * 0.6
                + inward * 0.8)
                .normalize();
            let again = s.intersect(h.position, out, f64::INFINITY, h.facet);
            assert!(again.is_some(), "escaped from {} along {out}", h.position);
        }
    }
}

/// A `group_index` table that leaves out one of the campaign's bands gives that band the
/// formula's value, as a scene without the key does; the band it names keeps its own.
#[test]
fn group_index_table_falls_back_to_the_formula_for_other_bands() {
    let dir = tmp("group_index_fallback");
    let path = write(
        &dir,
        "lake.yaml",
        "name: lake\nmaterials:\n  sand: { reflectance: 0.3 }\nobjects:\n  - water: { z: 0, extent: [[-5, -5], [5, 5]], attenuation_per_m: 0.05, refractive_index: 1.33, group_index: { 532: 1.4 } }\n  - plane: { z: -2, extent: [[-5, -5], [5, 5]], material: sand }\n",
    );
    let scene = Scene::load_bands(&path, &[532.0, 1064.0]).unwrap();
    let water = scene.water.as_ref().expect("a body of water");
    assert_eq!(water.n_group[0], 1.4);
    assert_eq!(water.n_group[1], water_group_index(1.33, 1064.0));
    assert!(water.n_group[1] != 1.4 && water.n_group[1] > 1.33);
}

/// Coordinates beyond any scene (a plane a 10^300 m wide, a grid of 10^300 m cells) are
/// refused at their key with the bound, not met later as a vertex without a place.
#[test]
fn planes_and_grids_beyond_any_scene_are_refused_at_their_key() {
    let dir = tmp("beyond");
    write(&dir, "dem.csv", "0 1\n1 0\n");
    for (object, key) in [
        (
            "plane: { z: 0, extent: [[-1e300, 0], [1, 1]], material: soil }",
            "objects[0].plane.extent",
        ),
        (
            "plane: { z: 1e9, extent: [[0, 0], [1, 1]], material: soil }",
            "objects[0].plane.z",
        ),
        (
            "heightfield: { file: dem.csv, cell_m: 1e300, material: soil }",
            "objects[0].heightfield.cell_m",
        ),
        (
            "heightfield: { file: dem.csv, cell_m: 1e-300, material: soil }",
            "objects[0].heightfield.cell_m",
        ),
        (
            "heightfield: { file: dem.csv, cell_m: 1, origin: [1e12, 0], material: soil }",
            "objects[0].heightfield.origin",
        ),
    ] {
        let p = write(
            &dir,
            "scene.yaml",
            &format!(
                "name: s\nmaterials:\n  soil: {{ reflectance: 0.3 }}\nobjects:\n  - {object}\n"
            ),
        );
        let e = Scene::load(&p, 1064.0).err().expect(object).to_string();
        assert!(
            e.contains("scene.yaml:5:") && e.contains(key) && e.lines().count() == 1,
            "{object}: {e}"
        );
    }
}
