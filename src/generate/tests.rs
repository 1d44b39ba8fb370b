use super::*;
use crate::scene::{leaf_area_index, parse_instances, Scene, SurfaceClass};
use glam::DVec3;
use std::time::Instant;

/// A fresh folder per test (and process), so that tests running in parallel do not meet.
fn scratch(name: &str) -> crate::testdata::TempDir {
    let dir = crate::testdata::TempDir::new(&format!("generate-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every file of a folder, by name, with its bytes.
fn contents(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

fn small(kind: SceneKind) -> GenerateOptions {
    match kind {
        SceneKind::Forest => GenerateOptions {
            size_m: Some([30.0, 25.0]),
            trees: Some(60),
            templates: Some(9),
            leaves: Some(400),
            ..Default::default()
        },
        SceneKind::Orchard => GenerateOptions {
            size_m: Some([20.0, 16.0]),
            trees: Some(25),
            leaves: Some(300),
            ..Default::default()
        },
        SceneKind::Flat => GenerateOptions {
            size_m: Some([12.0, 30.0]),
            ..Default::default()
        },
        SceneKind::Town => GenerateOptions {
            size_m: Some([40.0, 50.0]),
            trees: Some(12),
            leaves: Some(300),
            ..Default::default()
        },
    }
}

#[test]
fn same_seed_gives_identical_files_and_another_seed_does_not() {
    for kind in SceneKind::ALL {
        let root = scratch(&format!("determinism-{kind}"));
        let opts = small(kind);
        let (a, b, c) = (root.join("a"), root.join("b"), root.join("c"));
        let sa = generate_with_summary(kind, 7, &a, &opts).unwrap();
        let sb = generate_with_summary(kind, 7, &b, &opts).unwrap();
        generate(kind, 8, &c, &opts).unwrap();
        let (fa, fb, fc) = (contents(&a), contents(&b), contents(&c));
        assert_eq!(
            fa.len(),
            sa.files.len(),
            "{kind}: files listed in the summary"
        );
        assert!(!fa.is_empty());
        for (x, y) in fa.iter().zip(&fb) {
            assert_eq!(x.0, y.0);
            assert!(x.1 == y.1, "{kind}: {} differs between two runs", x.0);
        }
        assert_eq!(fa.len(), fb.len());
        assert_eq!(sa.lai, sb.lai);
        assert_eq!(sa.bytes, fa.iter().map(|f| f.1.len() as u64).sum::<u64>());
        assert_ne!(fa, fc, "{kind}: seeds 7 and 8 wrote the same files");
        if kind != SceneKind::Flat {
            // every template and table differs, not just the header
            for (x, y) in fa.iter().zip(&fc) {
                assert!(x.1 != y.1, "{kind}: {} is the same for two seeds", x.0);
            }
        }
        let _ = std::fs::remove_dir_all(&root);
    }
}

#[test]
fn small_scenes_load_with_their_figures() {
    for kind in SceneKind::ALL {
        let dir = scratch(&format!("small-{kind}"));
        let s = generate_with_summary(kind, 3, &dir, &small(kind)).unwrap();
        let scene = Scene::load(&s.scene, 532.0).unwrap();
        let st = scene.stats();
        let buildings = u64::from(s.buildings > 0);
        assert_eq!(st.instances, s.trees as u64 + 1 + buildings, "{kind}");
        // every tree has one table: nothing here is placed alike
        assert_eq!(st.traced_instances, st.instances, "{kind}");
        assert_eq!(st.instanced_triangles, s.facets, "{kind}");
        assert_eq!(st.distinct_triangles, s.distinct_facets, "{kind}");
        let lai = leaf_area_index(&scene).unwrap();
        assert!(
            (lai - s.lai).abs() < 1e-4 * s.lai.max(1.0),
            "{kind}: {lai} vs {}",
            s.lai
        );
        if kind != SceneKind::Flat {
            let target = GenerateOptions::defaults(kind).lai.unwrap();
            assert!((s.lai - target).abs() < 1e-3 * target, "{kind}: {}", s.lai);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// The forest as shipped: the figures the generator promises, measured on the loaded scene.
#[test]
fn default_forest_is_huge_when_instanced_yet_small_in_memory() {
    let dir = scratch("forest-default");
    let opts = GenerateOptions::default();
    let t0 = Instant::now();
    let s = generate_with_summary(SceneKind::Forest, 1, &dir, &opts).unwrap();
    let t_gen = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let scene = Scene::load(&s.scene, 1064.0).unwrap();
    let t_load = t1.elapsed().as_secs_f64();
    let st = scene.stats();
    let lai = leaf_area_index(&scene).unwrap();
    let biggest = s
        .files
        .iter()
        .map(|f| std::fs::metadata(f).unwrap().len())
        .max()
        .unwrap();
    eprintln!(
        "default forest: generated in {t_gen:.2} s ({} files, {:.1} MB, largest {:.1} MB), loaded in {t_load:.2} s; \
         {} trees, {} templates, {} facets instanced, {} distinct, {:.0} MB; LAI {lai:.4} (summary {:.4})",
        s.files.len(),
        s.bytes as f64 / 1e6,
        biggest as f64 / 1e6,
        s.trees,
        s.templates.len(),
        st.instanced_triangles,
        st.distinct_triangles,
        st.memory_bytes as f64 / 1e6,
        s.lai
    );
    assert_eq!(s.trees, 1029);
    assert_eq!(s.templates.len(), 7);
    assert!(s.templates.iter().all(|t| t.trees > 0));
    assert_eq!(st.instances, 1029 + 1);
    assert_eq!(st.instanced_triangles, s.facets);
    assert!(
        st.instanced_triangles > 100_000_000,
        "{}",
        st.instanced_triangles
    );
    assert!(st.memory_bytes < 1_000_000_000, "{}", st.memory_bytes);
    assert!((3.0..=5.0).contains(&lai), "LAI {lai}");
    assert!((lai - 4.0).abs() < 0.01, "LAI {lai}");
    assert!((lai - s.lai).abs() < 1e-4);
    assert!(biggest < 10_000_000, "a file of {biggest} bytes");

    // classes: leaves and bark are vegetation, the terrain ground
    for surf in &scene.surfaces {
        let want = if surf.name == "soil" {
            SurfaceClass::Ground
        } else {
            SurfaceClass::Vegetation
        };
        assert_eq!(surf.class, want, "{}", surf.name);
    }

    // trunks at least 1.5 m apart, standing on the terrain the scene loads
    let mut rows = Vec::new();
    for t in &s.templates {
        let p = dir.join(format!("{}.csv", t.name));
        let r = parse_instances(&p, &std::fs::read_to_string(&p).unwrap()).unwrap();
        assert_eq!(r.len(), t.trees);
        rows.extend(r);
    }
    for (i, a) in rows.iter().enumerate() {
        assert!((0.0..=100.0).contains(&a.x) && (0.0..=100.0).contains(&a.y));
        assert!((0.8..=1.2).contains(&a.scale));
        for b in &rows[i + 1..] {
            let d2 = (a.x - b.x).powi(2) + (a.y - b.y).powi(2);
            assert!(d2 >= 1.5 * 1.5 - 1e-9, "trunks {} m apart", d2.sqrt());
        }
    }
    let ground_only = dir.join("ground-only.yaml");
    let yaml = std::fs::read_to_string(&s.scene).unwrap();
    let cut = yaml.find("  - mesh:").unwrap();
    std::fs::write(&ground_only, &yaml[..cut]).unwrap();
    let ground = Scene::load(&ground_only, 1064.0).unwrap();
    let (lo, hi) = ground.bounds();
    // a few percent of slope: between 1 and 6 m of relief over 100 m
    assert!(
        (1.0..6.0).contains(&(hi.z - lo.z)),
        "relief {}",
        hi.z - lo.z
    );
    for r in &rows {
        let h = ground
            .intersect(
                DVec3::new(r.x, r.y, 100.0),
                DVec3::NEG_Z,
                1e3,
                crate::scene::FacetId::NONE,
            )
            .expect("terrain under every tree");
        assert!(
            (h.position.z - r.z).abs() < 1e-3,
            "tree at ({}, {}) z {} but ground at {}",
            r.x,
            r.y,
            r.z,
            h.position.z
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn default_orchard_and_flat_load() {
    let dir = scratch("orchard-default");
    let s =
        generate_with_summary(SceneKind::Orchard, 5, &dir, &GenerateOptions::default()).unwrap();
    let scene = Scene::load(&s.scene, 1064.0).unwrap();
    let st = scene.stats();
    assert_eq!(s.trees, 1105);
    assert_eq!(st.instances, 1105 + 1);
    assert_eq!(st.instanced_triangles, s.facets);
    let lai = leaf_area_index(&scene).unwrap();
    assert!((lai - 2.0).abs() < 0.01, "LAI {lai}");
    let (lo, hi) = scene.bounds();
    assert!(lo.z > -0.5 && hi.z < 5.0 && hi.x < 112.0 && hi.y < 108.0);
    eprintln!(
        "default orchard: {} facets instanced, {} distinct, {:.0} MB, {:.1} MB written",
        st.instanced_triangles,
        st.distinct_triangles,
        st.memory_bytes as f64 / 1e6,
        s.bytes as f64 / 1e6
    );
    let _ = std::fs::remove_dir_all(&dir);

    let dir = scratch("flat-default");
    let path = generate(SceneKind::Flat, 0, &dir, &GenerateOptions::default()).unwrap();
    let scene = Scene::load(&path, 1064.0).unwrap();
    assert_eq!(scene.stats().distinct_triangles, 2);
    assert_eq!(scene.stats().instanced_triangles, 2);
    assert_eq!(leaf_area_index(&scene), Some(0.0));
    let (lo, hi) = scene.bounds();
    assert_eq!((lo.x, lo.y, hi.x, hi.y), (0.0, 0.0, 100.0, 100.0));
    assert_eq!(scene.surfaces[0].class, SurfaceClass::Ground);
    assert_eq!(scene.surfaces[0].reflectance, 0.30);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn leaf_angles_follow_their_distributions() {
    // mean leaf inclination of each class (de Wit 1965; Campbell 1990 for the spherical)
    let cases = [
        (LeafAngle::Spherical, 57.30),
        (LeafAngle::Uniform, 45.0),
        (LeafAngle::Planophile, 26.76),
        (LeafAngle::Erectophile, 63.24),
        (LeafAngle::Plagiophile, 45.0),
        (LeafAngle::Extremophile, 45.0),
    ];
    let n = 200_000;
    for (lad, mean_deg) in cases {
        let mut rng = Rand::new(11);
        let mut sum = 0.0;
        let mut sum2 = 0.0;
        for _ in 0..n {
            let t = lad.sample(&mut rng).to_degrees();
            assert!((0.0..=90.0).contains(&t));
            sum += t;
            sum2 += t * t;
        }
        let mean = sum / n as f64;
        let sd = (sum2 / n as f64 - mean * mean).sqrt();
        assert!(
            (mean - mean_deg).abs() < 0.2,
            "{lad:?}: mean {mean:.2}°, expected {mean_deg}°"
        );
        // plagiophile and extremophile share their mean; their spreads tell them apart
        if lad == LeafAngle::Plagiophile {
            assert!(sd < 20.0, "{sd}");
        }
        if lad == LeafAngle::Extremophile {
            assert!(sd > 30.0, "{sd}");
        }
    }
}

#[test]
fn options_are_checked() {
    let dir = scratch("options");
    let slope = GenerateOptions {
        slope: Some(0.02),
        ..Default::default()
    };
    let e = generate(SceneKind::Orchard, 1, &dir, &slope).unwrap_err();
    assert!(
        e.to_string().contains("slope") && e.to_string().contains("orchard"),
        "{e}"
    );
    let crowded = GenerateOptions {
        trees: Some(10_000),
        ..Default::default()
    };
    let e = generate(SceneKind::Orchard, 1, &dir, &crowded).unwrap_err();
    assert!(e.to_string().contains("room for"), "{e}");
    let e = generate(SceneKind::Forest, 1, &dir, &crowded).unwrap_err();
    assert!(e.to_string().contains("cannot place"), "{e}");
    let lai = GenerateOptions {
        lai: Some(-1.0),
        ..Default::default()
    };
    assert!(generate(SceneKind::Forest, 1, &dir, &lai).is_err());
    use clap::ValueEnum;
    assert_eq!(SceneKind::from_str("Forest", true), Ok(SceneKind::Forest));
    assert!(SceneKind::from_str("jungle", true).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
