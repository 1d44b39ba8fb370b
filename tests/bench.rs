//! `lidarsim bench` on a small scene: the table has its columns and the error falls as rays
//! grow. (Its figures are measured by the code on the machine; nothing here times anything.)

mod common;
use common::*;

#[test]
fn quick_bench_reports_falling_error() {
    let dir = tmp("bench_quick");
    let opts = lidarsim::pipeline::bench::quick_options(&dir);
    let text = lidarsim::pipeline::bench::run(&opts).unwrap();
    println!("{text}");
    assert!(text.contains(
        "| method | rays for rRMSE ≤ 5% | rRMSE | wall s | rays/s | effective paths/ray |"
    ));
    for m in ["forward", "backward", "bdpt"] {
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
    for m in 0..3 {
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
