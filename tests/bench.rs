//! `lidarsim bench` on a small scene: the table has its columns and the error falls as rays
//! grow. (Its figures are measured by the code on the machine; nothing here times anything.)

mod common;
use common::*;

#[test]
fn quick_bench_reports_falling_error() {
    let dir = tmp("bench_quick");
    let opts = lidarsim::bench::quick_options(&dir);
    let text = lidarsim::bench::run(&opts).unwrap();
    println!("{text}");
    assert!(text.contains(
        "| method | rays for rRMSE ≤ 5% | rRMSE | wall s | rays/s | threads busy | effective paths/ray |"
    ));
    assert!(text.contains(
        "| footprint m | forward | backward | bdpt | forward, sobol | backward, sobol | bdpt, sobol |"
    ));
    assert!(text.contains("median R² by rays:"));
    assert!(
        text.lines().any(|l| l.starts_with("| 1 | ")),
        "no Table 2 row"
    );
    assert!(text.contains("| fixed | 0.500 |") && text.contains("| power | "));
    for m in [
        "forward",
        "backward",
        "bdpt",
        "forward, sobol",
        "backward, sobol",
        "bdpt, sobol",
    ] {
        assert!(
            text.lines().any(|l| l.starts_with(&format!("| {m} |"))),
            "no row for {m}"
        );
    }
    // the median rRMSE column of each method, read back from the table
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip_while(|l| !l.starts_with("| rays |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            l.split('|')
                .skip(2)
                .map(|c| c.trim().trim_end_matches('%').parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    assert!(rows.len() >= 2);
    for m in 0..6 {
        let col: Vec<f64> = rows
            .iter()
            .map(|r| r[m])
            .filter(|x| x.is_finite())
            .collect();
        if col.len() >= 2 {
            assert!(
                col.last().unwrap() < col.first().unwrap(),
                "method {m}: rRMSE does not fall: {col:?}"
            );
        }
    }
}

/// The campaign rows: a small photon-counting track through the pipeline, measured, and the
/// orchard rows skipped with a reason when the RAMI scene is not where they look.
#[test]
fn campaign_rows_are_measured_and_missing_data_is_skipped() {
    use lidarsim::bench::campaigns as bc;
    let dir = tmp("bench_campaigns");
    let scene = plane_scene(&dir, 0.3, 60.0);
    // the bench's own MABEL file, shortened to a 40 m track at 2 m steps over a plane
    let campaigns = lidarsim::testdata::repo().join("pipelines/bench");
    let mut short: serde_yaml::Mapping = serde_yaml::from_str(
        "{platform.track: {start: [-20, 0], end: [20, 0]}, platform.along_track_step_m: 2.0, \
         simulation.rays_per_pulse: 50}",
    )
    .unwrap();
    let text = bc::campaign_text(&campaigns, "mabel_532_sun", &short, &scene).unwrap();
    assert!(text.contains("rays_per_pulse: 50"), "{text}");
    // an override through a value that is not a section is an error naming it
    short.insert("seed.x".into(), 1.into());
    let e = bc::campaign_text(&campaigns, "mabel_532_sun", &short, &scene).unwrap_err();
    assert!(
        e.to_string().contains("seed.x: `seed` is not a section"),
        "{e}"
    );
    // in this process, and in one of its own as `lidarsim bench` runs it: the same run, the
    // same figures read from its files
    let exe = std::path::PathBuf::from(env!("CARGO_BIN_EXE_lidarsim"));
    let mut rows = Vec::new();
    for runner in [None, Some(exe.as_path())] {
        let row = bc::run_row(&dir, runner, "mabel_plane", "plane track", &text).unwrap();
        assert_eq!(row.pulses, 20, "{runner:?}");
        assert_eq!(row.rays_per_pulse, 50);
        assert!(row.simulate_s > 0.0 && row.pulses_per_s > 0.0);
        assert!(row.run_pulses_per_s > 0.0 && row.run_pulses_per_s <= row.pulses_per_s);
        // the products stage is a part of the run
        assert!(
            row.products_s > 0.0 && row.products_s < row.run_s,
            "{runner:?}: {} of {}",
            row.products_s,
            row.run_s
        );
        if std::path::Path::new("/proc/self/stat").exists() {
            // CPU time over wall time and threads: a fraction of the cores, never above all
            // of them (a millisecond of slack each way: the manifest rounds both to it)
            let u = row.cpu_utilisation.unwrap();
            assert!(
                (0.0..=1.0 + 0.002 / row.simulate_s).contains(&u),
                "{runner:?}: {u}"
            );
        }
        assert!(row.result.contains("laser") && row.result.contains("photons per shot"));
        if std::path::Path::new("/proc/self/status").exists() {
            assert!(row.peak_mb.unwrap() > 1.0, "{runner:?}");
        }
        rows.push(row);
    }
    assert_eq!(rows[0].result, rows[1].result);
    let row = rows.swap_remove(1);
    // the traversal figures of the same campaign: every query counted, replayed and timed
    let tr = lidarsim::bench::traversal::measure(
        "mabel_plane",
        &dir.join("mabel_plane/campaign.yaml"),
        8,
    )
    .unwrap();
    assert_eq!(tr.pulses, 8);
    assert!(tr.closest > 0 && tr.any_hit > 0, "{tr:?}");
    assert!(tr.inside_per_s > 0.0 && tr.bare_per_s > 0.0, "{tr:?}");
    // the tracing is part of the simulation: each thread traced for at most its wall time
    assert!(tr.tracing_per_s >= tr.inside_per_s, "{tr:?}");
    // the bound: the pulses the bare BVH's rate answers every query of, here 8 pulses'
    // queries in (queries / bare rate) seconds
    let bound = tr.bound_pulses_per_s();
    let seconds = (tr.closest + tr.any_hit) as f64 / tr.bare_per_s;
    assert!((bound * seconds - 8.0).abs() < 1e-9 * 8.0, "{bound} {tr:?}");
    // the replay's time by kind: each kind replayed took some time, and the three are the
    // whole (first segments: the laser's and the aperture's rays, which leave no facet)
    let [first, scattered, visibility] = tr.shares;
    assert!(
        first > 0.0 && visibility > 0.0 && scattered >= 0.0,
        "{tr:?}"
    );
    assert!(
        (first + scattered + visibility - 1.0).abs() < 1e-12,
        "{tr:?}"
    );
    let t = lidarsim::bench::traversal::table(std::slice::from_ref(&tr));
    assert!(t.contains("| mabel_plane | 8 |"), "{t}");
    assert!(t.contains("bound, pulses/s"), "{t}");
    let last = t.lines().last().unwrap_or_default();
    let kinds = format!(
        "{:.0}% / {:.0}% / {:.0}%",
        100.0 * first,
        100.0 * scattered,
        100.0 * visibility
    );
    assert!(last.ends_with(&format!("| {bound:.0} | {kinds} |")), "{t}");
    // the same campaign in three bands against one (the plane reflects alike in all three,
    // so every band receives the same energy from the same paths)
    let bands = bc::bands_row(&dir, "mabel_plane", &text, 1).unwrap();
    assert_eq!((bands.pulses, bands.pairs), (20, 1));
    assert!(bands.one_band_s > 0.0 && bands.three_bands_s > 0.0);
    assert_eq!(bands.energy_j.len(), 3);
    assert!(bands.energy_j[0] > 0.0, "{:?}", bands.energy_j);
    assert!(
        bands.energy_j.iter().all(|&e| e == bands.energy_j[0]),
        "{:?}",
        bands.energy_j
    );
    assert!(bc::bands_table(&[bands]).contains("| mabel_plane | 20 | 1 |"));
    // the same campaign on one thread and on all, for the serial share: its own folder for
    // one thread, a table row
    let sc = bc::scaling(&dir, Some(&exe), &row, &text).unwrap();
    assert!(dir.join("mabel_plane_1thread/run/report.md").is_file());
    assert!(sc.one.0 > 0.0 && sc.one.1 > 0.0 && sc.all.0 > 0.0 && sc.all.1 > 0.0);
    assert!(
        sc.one.1 <= sc.one.0 && sc.all.1 <= sc.all.0,
        "a stage inside its run"
    );
    let t = bc::scaling_table(&[sc]);
    assert!(
        t.contains("| mabel_plane |") && t.contains("serial fraction"),
        "{t}"
    );
    let planned = bc::plan(&dir, &campaigns, &dir.join("no_such_rami.yaml"), false);
    // the forest and town rows generate their scenes: only check the orchard rows here
    let skipped: Vec<String> = planned
        .unwrap()
        .into_iter()
        .filter_map(|p| match p {
            bc::Planned::Skipped { name, why } => Some(format!("{name}: {why}")),
            bc::Planned::Run { .. } => None,
        })
        .collect();
    assert_eq!(skipped.len(), 6, "{skipped:?}");
    assert!(skipped[0].contains("no_such_rami.yaml not found"));
    let share = format!(
        "{:.2} ({:.1} %)",
        row.products_s,
        100.0 * row.products_s / row.run_s
    );
    let table = bc::table(&[row], &[("mabel_532".into(), "absent".into())]);
    assert!(table.contains(
        "| campaign | what | pulses | rays/pulse | run s | simulate s | products s | pulses/s simulate | pulses/s run | CPU | peak memory MiB | result |"
    ));
    assert!(table.contains("| mabel_plane | plane track | 20 | 50 |"));
    assert!(table.contains(&share), "{share} in {table}");
    assert!(table.contains("| mabel_532 | skipped: absent |"));
}
