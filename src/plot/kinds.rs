//! The plot kinds of a run: each is one SQL query over the run's tables giving long-format rows
//! (`series`, `x`, `y`, `err`) and the axes it is drawn on.
//!
//! **Owns:** the queries, the axes with their units, and rows → [`Figure`]. **Does not:** run the query
//! (`RunQuery`, in the stage and the command) or draw (`figure`).

use std::collections::BTreeMap;

use arrow::array::{Array, AsArray};
use arrow::compute::cast;
use arrow::datatypes::DataType;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::figure::{Axis, Figure, Mark, Point, Series};
use crate::query::QueryResult;

/// A plot kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum PlotKind {
    /// Success rate against the optimisation budget, mean ± std over seeds, per environment and reward
    /// type (the `optimisation` table).
    SuccessBudget,
    /// Annotation similarity of each 10 % bin of a search's budget to its final bin, mean ± std per
    /// environment (`evolution_convergence`, the paper's convergence figure).
    Convergence,
    /// Benchmark success with annotation feedback against the number of patterns in the library, mean
    /// ± std over seeds (`benchmark`, sql/benchmark_library_size.sql).
    LibrarySize,
    /// Identification accuracy against the number of patterns that annotated, ± its standard error
    /// over trials (`identification`, the offline half of the library-size ablation).
    IdentificationSize,
    /// The best fitness ν found so far over each label's candidates (`candidates`).
    Fitness,
    /// Learning statistics per environment: executable and activation shares of the candidates
    /// (`candidates`, appendix A).
    LearningStats,
    /// Frames of a trace above its pattern timeline (the paper's first figure; needs a trace).
    AnnotationExamples,
}

impl PlotKind {
    /// Every kind.
    pub const ALL: [PlotKind; 7] = [
        PlotKind::SuccessBudget,
        PlotKind::Convergence,
        PlotKind::LibrarySize,
        PlotKind::IdentificationSize,
        PlotKind::Fitness,
        PlotKind::LearningStats,
        PlotKind::AnnotationExamples,
    ];

    /// The kind's name (`success-budget`), also its file stem.
    pub fn name(self) -> &'static str {
        match self {
            PlotKind::SuccessBudget => "success-budget",
            PlotKind::Convergence => "convergence",
            PlotKind::LibrarySize => "library-size",
            PlotKind::IdentificationSize => "identification-size",
            PlotKind::Fitness => "fitness",
            PlotKind::LearningStats => "learning-stats",
            PlotKind::AnnotationExamples => "annotation-examples",
        }
    }

    /// The table the kind's query reads (for a clear error when the run lacks it).
    pub fn table(self) -> &'static str {
        match self {
            PlotKind::SuccessBudget => "optimisation",
            PlotKind::Convergence => "evolution_convergence",
            PlotKind::LibrarySize => "benchmark",
            PlotKind::IdentificationSize => "identification",
            PlotKind::Fitness | PlotKind::LearningStats => "candidates",
            PlotKind::AnnotationExamples => "annotations",
        }
    }

    /// The query giving `series`, `x`, `y`, `err` rows (`None` for the annotation examples).
    pub fn sql(self) -> Option<String> {
        Some(match self {
            PlotKind::SuccessBudget => "WITH per_seed AS (\
                 SELECT env, reward_type, budget, seed, \
                        avg(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS rate \
                 FROM optimisation GROUP BY env, reward_type, budget, seed) \
                 SELECT env || ' ' || reward_type AS series, CAST(budget AS DOUBLE) AS x, \
                        avg(rate) AS y, coalesce(stddev_pop(rate), 0.0) AS err \
                 FROM per_seed GROUP BY env, reward_type, budget ORDER BY series, x"
                .into(),
            PlotKind::Convergence => "SELECT env AS series, CAST(10 * bin + 5 AS DOUBLE) AS x, \
                 avg(similarity) AS y, coalesce(stddev_pop(similarity), 0.0) AS err \
                 FROM evolution_convergence GROUP BY env, bin ORDER BY series, x"
                .into(),
            PlotKind::LibrarySize => format!(
                "SELECT env || ' ' || agent || ' ' || library AS series, CAST(patterns AS DOUBLE) AS x, \
                 success_mean AS y, success_std AS err FROM ({}) ORDER BY series, x",
                include_str!("../../sql/benchmark_library_size.sql")
                    .lines()
                    .filter(|l| !l.trim_start().starts_with("--"))
                    .collect::<Vec<_>>()
                    .join("\n")
            ),
            PlotKind::IdentificationSize => "WITH t AS (\
                 SELECT env, CASE WHEN chooser_model = '' THEN chooser ELSE chooser || ': ' || chooser_model END AS chooser, \
                        library, patterns, avg(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS p, count(*) AS n \
                 FROM identification GROUP BY env, chooser, chooser_model, library, patterns) \
                 SELECT env || ' ' || chooser || ' ' || library AS series, CAST(patterns AS DOUBLE) AS x, \
                        100.0 * p AS y, 100.0 * sqrt(p * (1.0 - p) / n) AS err \
                 FROM t ORDER BY series, x"
                .into(),
            PlotKind::Fitness => "SELECT label AS series, CAST(step AS DOUBLE) AS x, \
                 max(nu) OVER (PARTITION BY run_stage, label ORDER BY step \
                     ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW) AS y, 0.0 AS err \
                 FROM candidates WHERE step >= 0 AND nu > -1e308 AND nu < 1e308 ORDER BY series, x"
                .into(),
            PlotKind::LearningStats => "SELECT 'executable' AS series, env AS x, \
                     100.0 * avg(CASE WHEN executable THEN 1.0 ELSE 0.0 END) AS y, 0.0 AS err \
                 FROM candidates WHERE step >= 0 GROUP BY env \
                 UNION ALL SELECT 'activation' AS series, env AS x, 100.0 * avg(activation_rate) AS y, \
                     0.0 AS err FROM candidates WHERE step >= 0 GROUP BY env \
                 ORDER BY series, x"
                .into(),
            PlotKind::AnnotationExamples => return None,
        })
    }

    /// The title and axes.
    fn layout(self) -> (&'static str, Axis, Axis, Mark) {
        match self {
            PlotKind::SuccessBudget => (
                "Success rate against the optimisation budget",
                Axis::new("optimisation budget", "samples"),
                Axis::new("success rate", "share of goals × scenes").range(0.0, 1.0),
                Mark::Line,
            ),
            PlotKind::Convergence => (
                "Convergence of the detectors' annotations",
                Axis::new("share of the search budget", "%").range(0.0, 100.0),
                Axis::new("similarity to the final bin", "exp(−d_p), 1 = same").range(0.0, 1.0),
                Mark::Line,
            ),
            PlotKind::LibrarySize => (
                "Benchmark success against library size",
                Axis::new("patterns in the library", "labels"),
                Axis::new("success rate", "%").range(0.0, 100.0),
                Mark::Line,
            ),
            PlotKind::IdentificationSize => (
                "Identification accuracy against library size",
                Axis::new("patterns in the library", "labels"),
                Axis::new("identification accuracy", "%, ± standard error").range(0.0, 100.0),
                Mark::Line,
            ),
            PlotKind::Fitness => (
                "Best fitness over the candidates of each label",
                Axis::new("candidate", "step of the search"),
                Axis::new("best fitness so far", "ν"),
                Mark::Line,
            ),
            PlotKind::LearningStats => (
                "Learning statistics per environment",
                Axis::new("environment", ""),
                Axis::new("share of candidates", "%").range(0.0, 100.0),
                Mark::Bars,
            ),
            PlotKind::AnnotationExamples => (
                "Annotation examples",
                Axis::new("time", "s"),
                Axis::new("label", ""),
                Mark::Bars,
            ),
        }
    }
}

impl std::str::FromStr for PlotKind {
    type Err = String;

    /// A kind by its name (`success-budget`, …).
    fn from_str(s: &str) -> Result<Self, String> {
        PlotKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = PlotKind::ALL.iter().map(|k| k.name()).collect();
                format!(
                    "unknown plot kind {s:?} (expected one of {})",
                    names.join(", ")
                )
            })
    }
}

impl std::fmt::Display for PlotKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An x value: a number, or a category (bar figures).
#[derive(Clone, Debug, PartialEq)]
pub enum X {
    /// A position on a numeric axis.
    Num(f64),
    /// A category name.
    Cat(String),
}

/// One row of a kind's query.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The series it belongs to.
    pub series: String,
    /// Its x.
    pub x: X,
    /// Its value.
    pub y: f64,
    /// Its spread (0: none).
    pub err: f64,
}

/// Reading a query result as rows failed.
#[derive(Debug, thiserror::Error)]
#[error("plot {kind}: {message}")]
pub struct RowsError {
    /// The kind.
    pub kind: PlotKind,
    /// What is wrong.
    pub message: String,
}

/// The rows of a kind's query result.
pub fn rows_of(kind: PlotKind, result: &QueryResult) -> Result<Vec<Row>, RowsError> {
    let err = |message: String| RowsError { kind, message };
    let mut out = Vec::new();
    for b in &result.batches {
        let col = |n: &str| {
            b.column_by_name(n)
                .cloned()
                .ok_or_else(|| err(format!("the query has no column {n}")))
        };
        let f64s = |n: &str| -> Result<arrow::array::Float64Array, RowsError> {
            let c = cast(&col(n)?, &DataType::Float64).map_err(|e| err(e.to_string()))?;
            Ok(c.as_primitive::<arrow::datatypes::Float64Type>().clone())
        };
        let series = cast(&col("series")?, &DataType::Utf8).map_err(|e| err(e.to_string()))?;
        let series = series.as_string::<i32>();
        let x = col("x")?;
        let (y, e) = (f64s("y")?, f64s("err")?);
        let cat = matches!(
            x.data_type(),
            DataType::Utf8 | DataType::LargeUtf8 | DataType::Utf8View
        );
        let xs = if cat {
            cast(&x, &DataType::Utf8).map_err(|e| err(e.to_string()))?
        } else {
            cast(&x, &DataType::Float64).map_err(|e| err(e.to_string()))?
        };
        for i in 0..b.num_rows() {
            if series.is_null(i) || xs.is_null(i) || y.is_null(i) {
                continue;
            }
            out.push(Row {
                series: series.value(i).to_string(),
                x: if cat {
                    X::Cat(xs.as_string::<i32>().value(i).to_string())
                } else {
                    X::Num(xs.as_primitive::<arrow::datatypes::Float64Type>().value(i))
                },
                y: y.value(i),
                err: if e.is_null(i) { 0.0 } else { e.value(i) },
            });
        }
    }
    Ok(out)
}

/// The figure of `kind` from its rows, series in first-seen order.
pub fn figure_of(kind: PlotKind, rows: &[Row], title: Option<&str>) -> Figure {
    let (default_title, x, y, mark) = kind.layout();
    let mut categories: Vec<String> = Vec::new();
    for r in rows {
        if let X::Cat(c) = &r.x
            && !categories.contains(c)
        {
            categories.push(c.clone());
        }
    }
    let mut order: Vec<String> = Vec::new();
    let mut by: BTreeMap<String, Vec<Point>> = BTreeMap::new();
    for r in rows {
        if !by.contains_key(&r.series) {
            order.push(r.series.clone());
        }
        let px = match &r.x {
            X::Num(v) => *v,
            X::Cat(c) => categories.iter().position(|k| k == c).unwrap_or(0) as f64,
        };
        by.entry(r.series.clone()).or_default().push(Point {
            x: px,
            y: r.y,
            err: r.err.max(0.0),
        });
    }
    let series = order
        .into_iter()
        .map(|name| {
            let mut points = by.remove(&name).unwrap_or_default();
            points.sort_by(|a, b| a.x.total_cmp(&b.x));
            Series { name, mark, points }
        })
        .collect();
    Figure {
        title: title.unwrap_or(default_title).to_string(),
        x,
        y,
        categories,
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::svg;

    fn num(series: &str, x: f64, y: f64, err: f64) -> Row {
        Row {
            series: series.into(),
            x: X::Num(x),
            y,
            err,
        }
    }

    fn cat(series: &str, x: &str, y: f64) -> Row {
        Row {
            series: series.into(),
            x: X::Cat(x.into()),
            y,
            err: 0.0,
        }
    }

    /// Counts `needle` in `s`.
    fn count(s: &str, needle: &str) -> usize {
        s.matches(needle).count()
    }

    /// The SVG of `kind` from `rows` has both axes with their titles (label and unit), `series` series
    /// with their names in the legend, and `marks` of the expected element.
    fn check(kind: PlotKind, rows: &[Row], series: usize, mark: &str, marks: usize) -> String {
        let f = figure_of(kind, rows, None);
        let s = svg(&f);
        assert!(s.starts_with("<svg"), "{kind}");
        assert_eq!(count(&s, "<g class=\"axis x\">"), 1, "{kind}");
        assert_eq!(count(&s, "<g class=\"axis y\">"), 1, "{kind}");
        for t in [f.x.title(), f.y.title()] {
            assert!(
                s.contains(&format!(">{}</text>", t.replace('&', "&amp;"))),
                "{kind}: {t}"
            );
        }
        assert!(!f.x.label.is_empty() && !f.y.label.is_empty(), "{kind}");
        assert_eq!(count(&s, "<g class=\"series\""), series, "{kind}");
        for se in &f.series {
            assert!(s.contains(&format!("data-name=\"{}\"", se.name)), "{kind}");
        }
        assert_eq!(count(&s, mark), marks, "{kind}: {mark}\n{s}");
        assert!(count(&s, "class=\"tick\"") >= 3, "{kind}");
        let png = crate::plot::png(&f).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        s
    }

    #[test]
    fn success_budget_draws_a_band_and_a_line_per_env_and_reward_type() {
        let rows = [
            num("pooltool dense", 50.0, 0.2, 0.1),
            num("pooltool dense", 100.0, 0.5, 0.1),
            num("pooltool sparse", 50.0, 0.0, 0.0),
            num("pooltool sparse", 100.0, 0.1, 0.05),
        ];
        let s = check(PlotKind::SuccessBudget, &rows, 2, "<polyline", 2);
        assert_eq!(count(&s, "class=\"band\""), 2);
        assert!(s.contains("optimisation budget (samples)"));
    }

    #[test]
    fn convergence_has_one_curve_per_environment_over_ten_bins() {
        let rows: Vec<Row> = (0..10)
            .flat_map(|b| {
                let x = 10.0 * b as f64 + 5.0;
                [
                    num("pooltool", x, 0.5 + 0.05 * b as f64, 0.1),
                    num("phyre", x, 0.4 + 0.05 * b as f64, 0.0),
                ]
            })
            .collect();
        let s = check(PlotKind::Convergence, &rows, 2, "<polyline", 2);
        assert_eq!(count(&s, "class=\"band\""), 1, "no band without spread");
        assert!(s.contains("share of the search budget (%)"));
    }

    #[test]
    fn library_size_has_a_curve_per_agent_and_library() {
        let rows = [
            num("phyre search pooltool-human", 3.0, 20.0, 5.0),
            num("phyre search pooltool-human", 6.0, 30.0, 5.0),
            num("phyre search pooltool-human", 12.0, 45.0, 2.0),
        ];
        let s = check(PlotKind::LibrarySize, &rows, 1, "<polyline", 1);
        assert!(s.contains("success rate (%)") && s.contains("patterns in the library (labels)"));
    }

    #[test]
    fn identification_size_has_a_curve_per_environment_with_its_error_band() {
        let rows = [
            num("pooltool offline pooltool-human", 1.0, 15.0, 8.0),
            num("pooltool offline pooltool-human", 3.0, 95.0, 4.9),
            num("pooltool offline pooltool-human", 12.0, 100.0, 0.0),
            num("phyre offline phyre-human", 1.0, 100.0, 0.0),
            num("phyre offline phyre-human", 12.0, 95.0, 4.9),
        ];
        let s = check(PlotKind::IdentificationSize, &rows, 2, "<polyline", 2);
        assert_eq!(count(&s, "class=\"band\""), 2);
        assert!(
            s.contains("identification accuracy (%, ± standard error)"),
            "{s}"
        );
    }

    #[test]
    fn fitness_has_a_curve_per_label() {
        let rows = [
            num("fast ball", 0.0, -0.5, 0.0),
            num("fast ball", 1.0, 0.1, 0.0),
            num("fast ball", 2.0, 0.1, 0.0),
            num("ball slowing", 0.0, 0.3, 0.0),
            num("ball slowing", 1.0, 0.4, 0.0),
        ];
        let s = check(PlotKind::Fitness, &rows, 2, "<polyline", 2);
        assert!(s.contains("best fitness so far (ν)"));
        // A negative fitness puts the axis below zero.
        let f = figure_of(PlotKind::Fitness, &rows, Some("mine"));
        assert_eq!(f.title, "mine");
        assert!(s.contains(">-0.6<") || s.contains(">-0.5<"), "{s}");
    }

    #[test]
    fn learning_stats_are_grouped_bars_per_environment() {
        let rows = [
            cat("executable", "iphyre", 80.0),
            cat("executable", "pooltool", 90.0),
            cat("activation", "iphyre", 40.0),
            cat("activation", "pooltool", 55.0),
        ];
        let s = check(PlotKind::LearningStats, &rows, 2, "<rect x=", 4 + 2 + 1);
        assert!(s.contains(">iphyre</text>") && s.contains(">pooltool</text>"));
        assert!(s.contains("share of candidates (%)"));
    }

    #[test]
    fn kinds_parse_by_name_and_every_table_kind_has_a_query() {
        for k in PlotKind::ALL {
            assert_eq!(k.name().parse::<PlotKind>().unwrap(), k);
            assert_eq!(k.sql().is_some(), k != PlotKind::AnnotationExamples, "{k}");
        }
        assert!(
            "nope"
                .parse::<PlotKind>()
                .unwrap_err()
                .contains("success-budget")
        );
    }
}
