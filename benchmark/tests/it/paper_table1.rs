//! Calibration on the paper's Table 1 task scores (15 models) reproduces the frozen weights.

use std::path::PathBuf;

use dh_benchmark::calibrate::{calibrate, CalibrationParams};
use dh_benchmark::TaskId;

/// The paper's "Avg.Score" column, in the fixture's row order.
const PAPER_AVG: [f64; 15] =
    [43.91, 39.28, 45.09, 43.49, 45.09, 45.50, 46.27, 42.31, 49.53, 49.64, 46.61, 54.47, 46.93, 38.31, 43.13];

fn table1() -> (Vec<TaskId>, Vec<Vec<f64>>) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/benchmark/data/paper_table1_task_scores.csv");
    let text = std::fs::read_to_string(&path).expect("fixture");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header[0], "model");
    let tasks = header[1..].iter().map(|t| TaskId::parse(t).unwrap()).collect();
    let rows = lines
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').skip(1).map(|v| v.parse().unwrap()).collect())
        .collect();
    (tasks, rows)
}

#[test]
fn reproduces_frozen_weights_to_three_decimals() {
    let (tasks, rows) = table1();
    assert_eq!(rows.len(), 15);
    let cal = calibrate(&tasks, &rows, &CalibrationParams::default()).unwrap();
    for (t, w) in tasks.iter().zip(&cal.weights) {
        let rounded = (w * 1000.0).round() / 1000.0;
        assert!(
            (rounded - t.frozen_weight()).abs() < 1e-9,
            "{t}: calibrated {w:.5}, frozen {}",
            t.frozen_weight()
        );
    }
    let total: f64 = cal.weights.iter().sum();
    assert!((total - 1.0).abs() < 1e-12);
}

#[test]
fn frozen_weights_give_the_papers_average_column() {
    let (tasks, rows) = table1();
    for (row, avg) in rows.iter().zip(PAPER_AVG) {
        let s: f64 = tasks.iter().zip(row).map(|(t, v)| t.frozen_weight() * v).sum();
        // The printed weights are rounded to 3 decimals, so the sum drifts by a few 0.01.
        assert!((s - avg).abs() < 0.05, "S_open {s:.3} vs paper {avg}");
    }
}
