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

/// Traces read back together (`store::read_traces`) out of files of many traces and several row
/// groups, where a trace's rows may straddle two groups, equal the same traces read one by one out
/// of files of one trace each: the same 30 shots simulated with 15 and with 1 scene per file.
#[test]
fn traces_read_together_from_shared_row_groups_equal_traces_read_alone() {
    use annotrace::store::{RunDir, read_trace, read_traces, trace_ids};
    let t = TestRun::new();
    for (run, per) in [("many", "15"), ("one", "1")] {
        t.run(&[
            "simulate",
            "--env",
            "pooltool",
            "--scenes",
            "30",
            "--seed",
            "9",
            "--dt",
            "0.01",
            "--scenes-per-shard",
            per,
            "--run",
            run,
            "-q",
        ])
        .ok();
    }
    let (many, one) = (RunDir::new(t.path("many")), RunDir::new(t.path("one")));
    // Two files of about 75,000 frame rows: two row groups each.
    for f in std::fs::read_dir(t.path("many/frames/env=pooltool")).unwrap() {
        use parquet::file::reader::FileReader;
        let file = std::fs::File::open(f.unwrap().path()).unwrap();
        let reader = parquet::file::reader::SerializedFileReader::new(file).unwrap();
        assert!(reader.metadata().num_row_groups() >= 2);
    }
    let mut ids: Vec<String> = trace_ids(&many)
        .unwrap()
        .into_iter()
        .map(|(_, id)| id)
        .collect();
    assert_eq!(ids.len(), 30);
    ids.reverse();
    let together = read_traces(&many, &ids).unwrap();
    for (id, trace) in ids.iter().zip(&together) {
        let alone = read_trace(&one, id).unwrap();
        assert!(*trace == alone, "{id} differs");
        assert!(
            read_trace(&many, id).unwrap() == alone,
            "{id} alone differs"
        );
    }
}
