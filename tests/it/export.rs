//! `annotrace export` and the `export` stage: traces back to JSON; tables to CSV, Markdown, LaTeX.

use annotrace::trace::Env;

use crate::common::{TestRun, example, repo};

#[test]
fn export_to_stdout_and_unknown_trace() {
    let t = TestRun::new();
    t.run(&[
        "import",
        "--env",
        "iphyre",
        example(Env::Iphyre).to_str().unwrap(),
        "--run",
        "r",
    ])
    .ok();
    let r = t.run(&["export", "--run", "r", "--trace", "iphyre_support"]);
    r.ok();
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["environment"], "iphyre");
    assert_eq!(v["timesteps"].as_array().unwrap().len(), 16);
    t.run(&["export", "--run", "r", "--trace", "nope"])
        .code(2)
        .stderr_has("no trace \"nope\"")
        .stderr_has("1 trace(s)");
}

/// The quickstart's export stages write CSV, Markdown and booktabs LaTeX with the same numbers.
#[test]
fn export_stages_write_csv_markdown_and_latex() {
    let t = TestRun::new();
    let pipeline = repo().join("pipelines/quickstart.toml");
    t.run(&[
        "run",
        pipeline.to_str().unwrap(),
        "--run-dir",
        "q",
        "--quiet",
    ])
    .ok();
    let csv = std::fs::read_to_string(t.path("q/exports/trace_summary.csv")).unwrap();
    let md = std::fs::read_to_string(t.path("q/exports/trace_summary.md")).unwrap();
    let tex = std::fs::read_to_string(t.path("q/exports/trace_summary.tex")).unwrap();
    assert!(
        csv.starts_with("env,traces,steps,frame_rows,events,mean_duration_s,success_rate\n"),
        "{csv}"
    );
    // The quickstart also draws the evolution's figures and writes the web report of every trace.
    for f in [
        "fitness",
        "convergence",
        "learning-stats",
        "annotation-examples",
    ] {
        for ext in ["svg", "png"] {
            let p = t.path(&format!("q/exports/{f}.{ext}"));
            assert!(p.is_file(), "{}", p.display());
        }
    }
    let index = std::fs::read_to_string(t.path("q/exports/report/data/index.js")).unwrap();
    assert_eq!(
        index.matches("\"trace_id\":").count(),
        273,
        "3 imported + 270 simulated traces"
    );
    t.run(&["verify", "--run", "q"]).ok();
    // The PHYRE row: the imported example plus the 30 simulated episodes, the same numbers in every format.
    let phyre: Vec<&str> = csv
        .lines()
        .find(|l| l.starts_with("phyre,"))
        .unwrap_or_else(|| panic!("{csv}"))
        .split(',')
        .collect();
    assert_eq!(phyre[1], "31", "{csv}");
    assert!(md.contains("| env | traces | steps |"), "{md}");
    assert!(
        md.contains(&format!(
            "| phyre | {} | {} | {} | {} |",
            phyre[1], phyre[2], phyre[3], phyre[4]
        )),
        "{md}"
    );
    assert!(
        tex.contains("\\toprule") && tex.contains("\\midrule") && tex.contains("\\bottomrule"),
        "{tex}"
    );
    assert!(tex.contains("frame\\_rows"), "{tex}");
    assert!(
        tex.contains(&format!(
            "phyre & {} & {} & {} & {} & ",
            phyre[1], phyre[2], phyre[3], phyre[4]
        )),
        "{tex}"
    );
    assert!(
        tex.starts_with("% requires \\usepackage{booktabs}\n% Traces per environment"),
        "{tex}"
    );
}
