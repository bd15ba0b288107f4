//! The success-versus-budget figure: for each reward type and budget, the success rate averaged over
//! goals and scenes for each seed, then the mean over seeds (line) and its standard deviation
//! (shaded band). Drawn by the plotting module (`plot`): SVG with every label, PNG without text.

use std::collections::BTreeMap;

use crate::plot::{Axis, Figure, Mark, Point as PlotPoint, Series};

/// One point of a curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Samples spent.
    pub budget: f64,
    /// Mean success over seeds.
    pub mean: f64,
    /// Standard deviation over seeds (0 with one seed).
    pub std: f64,
}

/// One reward type's curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// The reward type (`dense`, `sparse`).
    pub name: String,
    /// Points by increasing budget.
    pub points: Vec<Point>,
}

/// Curves from `(reward type, budget, seed, success)` rows (one per goal × scene × seed × budget).
pub fn curves<'a>(rows: impl IntoIterator<Item = (&'a str, u64, u64, bool)>) -> Vec<Curve> {
    // (type, budget) -> seed -> (successes, total)
    let mut acc: BTreeMap<(String, u64), BTreeMap<u64, (f64, f64)>> = BTreeMap::new();
    for (kind, budget, seed, success) in rows {
        let e = acc
            .entry((kind.to_string(), budget))
            .or_default()
            .entry(seed)
            .or_insert((0.0, 0.0));
        e.0 += if success { 1.0 } else { 0.0 };
        e.1 += 1.0;
    }
    let mut out: BTreeMap<String, Vec<Point>> = BTreeMap::new();
    for ((kind, budget), seeds) in acc {
        let rates: Vec<f64> = seeds.values().map(|(s, n)| s / n).collect();
        let n = rates.len() as f64;
        let mean = rates.iter().sum::<f64>() / n;
        let std = (rates.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        out.entry(kind).or_default().push(Point {
            budget: budget as f64,
            mean,
            std,
        });
    }
    out.into_iter()
        .map(|(name, points)| Curve { name, points })
        .collect()
}

/// The curves as a figure of the plotting module: one line with a ±std band per reward type.
pub fn figure(curves: &[Curve], title: &str) -> Figure {
    Figure {
        title: title.to_string(),
        x: Axis::new("optimisation budget", "samples"),
        y: Axis::new("success rate", "share of goals × scenes").range(0.0, 1.0),
        categories: Vec::new(),
        series: curves
            .iter()
            .map(|c| Series {
                name: c.name.clone(),
                mark: Mark::Line,
                points: c
                    .points
                    .iter()
                    .map(|p| PlotPoint {
                        x: p.budget,
                        y: p.mean,
                        err: p.std,
                    })
                    .collect(),
            })
            .collect(),
    }
}

/// The figure as SVG text (`plot::svg`).
pub fn svg(curves: &[Curve], title: &str) -> String {
    crate::plot::svg(&figure(curves, title))
}

/// The figure as PNG bytes (`plot::png`: no text, see its docs).
pub fn png(curves: &[Curve]) -> Result<Vec<u8>, String> {
    crate::plot::png(&figure(curves, ""))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_average_over_items_then_seeds() {
        let rows = vec![
            ("dense", 50, 1, true),
            ("dense", 50, 1, false),
            ("dense", 50, 2, true),
            ("dense", 50, 2, true),
            ("sparse", 50, 1, false),
        ];
        let c = curves(rows);
        assert_eq!(c[0].name, "dense");
        assert!((c[0].points[0].mean - 0.75).abs() < 1e-12);
        assert!((c[0].points[0].std - 0.25).abs() < 1e-12);
        assert_eq!(c[1].points[0].mean, 0.0);
        let s = svg(&c, "t");
        assert!(s.starts_with("<svg") && s.contains("dense") && s.contains("<polygon"));
        let p = png(&c).unwrap();
        assert_eq!(&p[1..4], b"PNG");
    }
}
