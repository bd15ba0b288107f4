//! `annotrace survey` and `annotrace import-survey`: the survey page generated for a small billiards run
//! with two conditions (offline summaries of all 12 patterns and of one), opened in headless Chromium
//! with the harness of the report test (`super::report`): the page's test hook (`#test=1&p=ID`)
//! restarts the first animation and decodes it with the browser's own decoder, rates every item and
//! reads the CSV the download button saves; that CSV goes through `import-survey` and
//! `sql/survey_ratings.sql`. A screenshot is compared with `tests/it/screenshots/survey-pooltool.png`.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::report::{MAX_DIFFERING, browse, browse_test_sequence, chromium, differing_share};
use crate::common::{TestRun, repo};

/// A run with 4 billiards traces summarised in two conditions, and its survey under `site/`.
fn survey_run(t: &TestRun) -> PathBuf {
    t.run(&[
        "simulate", "--scenes", "4", "--seed", "3", "--dt", "0.05", "--run", "r", "--quiet",
    ])
    .ok();
    for labels in [None, Some("ball collision")] {
        let mut args = vec![
            "summarise",
            "--run",
            "r",
            "--env",
            "pooltool",
            "--traces",
            "4",
            "--identify",
            "none",
            "--quiet",
        ];
        if let Some(l) = labels {
            args.extend(["--labels", l]);
        }
        t.run(&args).ok();
    }
    t.run(&[
        "survey",
        "--run",
        "r",
        "--out",
        "site",
        "--seed",
        "9",
        "--participants",
        "2",
        "--size",
        "128",
        "--fps",
        "4",
        "--max-frames",
        "24",
        "--quiet",
    ])
    .ok()
    .stdout_has(
        "4 item(s) (4 pooltool), conditions: offline:pooltool-human:1, offline:pooltool-human:12",
    );
    t.path("site")
}

/// `window.ANNOTRACE_SURVEY` of the page.
fn data(site: &Path) -> Value {
    let text = std::fs::read_to_string(site.join("data/survey.js")).unwrap();
    let json = text
        .trim()
        .strip_prefix("window.ANNOTRACE_SURVEY = ")
        .and_then(|s| s.strip_suffix(';'))
        .expect("survey.js assigns the survey");
    serde_json::from_str(json).unwrap()
}

/// Frames of an APNG, read with the png crate.
fn apng_frames(bytes: &[u8]) -> u32 {
    let r = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    r.info()
        .animation_control
        .expect("an animated PNG")
        .num_frames
}

#[test]
fn participants_rate_animations_and_their_csv_becomes_the_ratings_table() {
    let t = TestRun::new();
    let site = survey_run(&t);
    let d = data(&site);
    let items = d["items"].as_array().unwrap();
    assert_eq!(items.len(), 4);
    assert_eq!(d["participants"], serde_json::json!(["P001", "P002"]));
    // Every item has an animation of several frames and one summary per condition.
    for it in items {
        let bytes = std::fs::read(site.join(it["video"].as_str().unwrap())).unwrap();
        assert!(apng_frames(&bytes) > 2, "{it}");
        assert_eq!(it["summaries"].as_array().unwrap().len(), 2);
    }
    // The survey's items are a table of the run.
    let rows = t.csv(
        "r",
        "SELECT count(*) AS n, count(DISTINCT trace_id) AS t FROM survey_items",
    );
    assert_eq!(rows, "n,t\n8,4\n");
    // The files are in the manifest.
    t.run(&["verify", "--run", "r"]).ok();
    let Some(bin) = chromium() else { return };
    let url = format!(
        "file://{}#test=1&p=P001",
        std::fs::canonicalize(site.join("index.html"))
            .unwrap()
            .display()
    );
    let r = browse_test_sequence(&bin, &url, &t.path("profile-dom"));
    // The page's shuffle is the library's, item for item.
    let seed: u64 = d["seed"].as_str().unwrap().parse().unwrap();
    let conditions: Vec<String> = d["conditions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap().to_string())
        .collect();
    let expected: Vec<Value> = annotrace::survey::assignment(seed, "P001", 4, 2)
        .iter()
        .enumerate()
        .map(|(k, s)| {
            serde_json::json!({
                "position": k + 1,
                "trace_id": items[s.item]["trace_id"],
                "condition": conditions[s.condition],
            })
        })
        .collect();
    assert_eq!(r["order"], Value::Array(expected), "{r}");
    // The first animation: shown at its size, restarted, and the browser decodes its frames.
    assert_eq!(r["video"]["width"], 128, "{r}");
    assert_eq!(r["replayed"], true, "{r}");
    let first = &items[annotrace::survey::assignment(seed, "P001", 4, 2)[0].item];
    let frames = apng_frames(&std::fs::read(site.join(first["video"].as_str().unwrap())).unwrap());
    assert_eq!(r["decoded"]["frames"], frames, "{r}");
    assert_eq!(r["decoded"]["animated"], true, "{r}");
    assert_eq!(r["decoded"]["first_differs_from_last"], true, "{r}");
    // Every item answered, kept in localStorage, and the CSV holds one row per item.
    assert_eq!(r["answered"], 4, "{r}");
    assert_eq!(r["done_shown"], true, "{r}");
    assert_eq!(r["stored"].as_object().unwrap().len(), 4, "{r}");
    assert_eq!(r["first_checked"], "1", "{r}");
    let csv = r["csv"].as_str().unwrap();
    assert_eq!(csv.lines().count(), 5, "{csv}");
    assert!(csv.starts_with(
        "survey,participant,seed,position,trace_id,env,condition,rating,answered_at\n"
    ));
    // The CSV goes into the run and the SQL aggregates it.
    let file = t.write("answers/P001.csv", csv);
    t.run(&["import-survey", "--run", "r", file.to_str().unwrap()])
        .ok()
        .stdout_has("4 rating(s) of 1 participant(s) from 1 file(s)");
    let sql = std::fs::read_to_string(repo().join("sql/survey_ratings.sql")).unwrap();
    // As the command's hint says: the SQL file after `--` (it starts with a comment).
    let q = t.run(&["query", "--run", "r", "--format", "csv", "--", &sql]);
    q.ok();
    let table = q.stdout.clone();
    // Position k (0-based) was rated 1 + k mod 7; the expected mean per condition from the order.
    let order = r["order"].as_array().unwrap();
    let mut lines = table.lines();
    assert_eq!(lines.next(), Some("env,condition,participants,n,mean,std"));
    let got: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    let mut want: Vec<(String, String, usize, f64, f64)> = Vec::new();
    for env in ["pooltool", "all"] {
        for c in &conditions {
            let ratings: Vec<f64> = order
                .iter()
                .enumerate()
                .filter(|(_, o)| o["condition"] == c.as_str())
                .map(|(k, _)| (1 + k % 7) as f64)
                .collect();
            if ratings.is_empty() {
                continue;
            }
            let n = ratings.len() as f64;
            let mean = ratings.iter().sum::<f64>() / n;
            let std = (ratings.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
            want.push((env.into(), c.clone(), ratings.len(), mean, std));
        }
    }
    assert_eq!(got.len(), want.len(), "{table}");
    for (g, (env, c, n, mean, std)) in got.iter().zip(&want) {
        assert_eq!((&g[0], &g[1], g[2].as_str()), (env, c, "1"), "{table}");
        assert_eq!(g[3].parse::<usize>().unwrap(), *n, "{table}");
        assert!(
            (g[4].parse::<f64>().unwrap() - mean).abs() < 1e-3,
            "{table}"
        );
        assert!((g[5].parse::<f64>().unwrap() - std).abs() < 1e-3, "{table}");
    }
    // A bad CSV names its file, line and field, exits 2 and leaves the table as it was.
    let bad = t.write("answers/bad.csv", &csv.replacen(",1,20", ",8,20", 1));
    let _ = std::fs::remove_file(&file);
    t.run(&["import-survey", "--run", "r", bad.to_str().unwrap()])
        .code(2)
        .stderr_has("bad.csv:2: field `rating`: 8 is outside the scale 1–7");
    assert_eq!(
        t.csv("r", "SELECT count(*) AS n FROM survey_responses"),
        "n\n4\n"
    );
    // The screenshot of the same sequence against the committed one.
    let shot = t.path("survey-pooltool.png");
    browse(
        &bin,
        &url,
        &[&format!("--screenshot={}", shot.display())],
        &t.path("profile-shot"),
    );
    let png = std::fs::read(&shot).expect("chromium wrote the screenshot");
    let committed = repo().join("tests/it/screenshots/survey-pooltool.png");
    if std::env::var("ANNOTRACE_UPDATE_SCREENSHOTS").is_ok_and(|v| v == "1") {
        std::fs::write(&committed, &png).unwrap();
        return;
    }
    let old = std::fs::read(&committed).unwrap_or_else(|_| {
        panic!(
            "{} is missing: run with ANNOTRACE_UPDATE_SCREENSHOTS=1",
            committed.display()
        )
    });
    let share = differing_share(&png, &old);
    if share > MAX_DIFFERING {
        let keep = std::env::temp_dir().join("annotrace-survey-pooltool.png");
        std::fs::write(&keep, &png).unwrap();
        panic!(
            "{:.1} % of pixels differ from {} (new one: {})",
            100.0 * share,
            committed.display(),
            keep.display()
        );
    }
}

#[test]
fn a_run_without_summaries_or_survey_is_refused_with_a_hint() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--scenes", "1", "--seed", "3", "--dt", "0.05", "--run", "r", "--quiet",
    ])
    .ok();
    t.run(&["survey", "--run", "r", "--out", "site"])
        .code(2)
        .stderr_has("survey needs at least 1 traces with a summary in every condition")
        .stderr_has("run `summarise` stages first");
    assert!(!t.path("site").exists());
    let f = t.write(
        "a.csv",
        "survey,participant,seed,position,trace_id,env,condition,rating,answered_at\n\
         abc,P1,1,1,x,pooltool,offline,3,\n",
    );
    t.run(&["import-survey", "--run", "r", f.to_str().unwrap()])
        .code(2)
        .stderr_has("the run has no survey");
    t.run(&["import-survey", "--run", "r", "nope.csv"])
        .code(2)
        .stderr_has("nope.csv");
}
