//! `annotrace report`: the static viewer, generated for a run with one trace per environment, opened
//! in headless Chromium (Debian's `chromium`; `ANNOTRACE_CHROMIUM` names another binary).
//!
//! The page's test hook (`index.html#test=N`) loads trace N, plays it, pauses, clicks an annotation and
//! hovers it, and writes what it saw into `<pre id="test-result">`, which `--dump-dom` prints; a
//! `--screenshot` of the same sequence is compared with `tests/it/screenshots/report-<env>.png` within
//! a tolerance (`ANNOTRACE_UPDATE_SCREENSHOTS=1` rewrites them; read the new images before committing).
//!
//! Without Chromium the browser test fails, locally as in CI (`.ci/run` installs it when missing);
//! `ANNOTRACE_SKIP_BROWSER=1` skips it with a message, except under CI (`CI=true`), where it still fails.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use crate::common::{TestRun, repo};

/// The Chromium binary, or `None` when the browser test may be skipped.
pub(crate) fn chromium() -> Option<String> {
    let bin = std::env::var("ANNOTRACE_CHROMIUM").unwrap_or_else(|_| "chromium".into());
    let found = Command::new(&bin)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if found {
        return Some(bin);
    }
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false");
    if std::env::var("ANNOTRACE_SKIP_BROWSER").is_ok_and(|v| v == "1") && !ci {
        eprintln!(
            "SKIPPED: the report browser test needs {bin:?} (apt-get install -y chromium); \
             ANNOTRACE_SKIP_BROWSER=1 is set"
        );
        return None;
    }
    panic!(
        "the report browser test needs headless Chromium: {bin:?} does not run. Install it with \
         `apt-get install -y chromium` (.ci/run does), name another binary with ANNOTRACE_CHROMIUM, \
         or skip locally with ANNOTRACE_SKIP_BROWSER=1"
    );
}

/// Runs Chromium headless on `url` with a virtual-time budget; `extra` adds `--dump-dom` or
/// `--screenshot=…`. Returns stdout.
pub(crate) fn browse(bin: &str, url: &str, extra: &[&str], profile: &Path) -> String {
    browse_for(bin, url, extra, profile, 8000)
}

/// The DOM of a page's test sequence (`#test=1…`) once it has finished: the sequence runs on Chromium's
/// virtual time, and on a loaded machine loading the page's files can outlast the budget, so a sequence
/// that did not finish is run again (new profile) with a budget 2.5× larger, up to three times; the
/// result's contents are then checked by the caller as usual.
pub(crate) fn browse_test_sequence(bin: &str, url: &str, profile: &Path) -> Value {
    let mut budget = 8000;
    let mut dom = String::new();
    for attempt in 0..3 {
        let dir = profile.with_extension(attempt.to_string());
        dom = browse_for(bin, url, &["--dump-dom"], &dir, budget);
        if dom.contains("data-done=\"1\"") {
            break;
        }
        budget = budget * 5 / 2;
    }
    test_result(&dom)
}

fn browse_for(bin: &str, url: &str, extra: &[&str], profile: &Path, budget_ms: u32) -> String {
    let out = Command::new(bin)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            "--window-size=1280,1100",
            "--no-first-run",
            "--allow-file-access-from-files",
        ])
        .arg(format!("--virtual-time-budget={budget_ms}"))
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium runs");
    assert!(
        out.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A run with one trace per environment, the built-in libraries, a second (smaller) billiards library
/// and the billiards ground truth; its report under `site/`.
fn report_run(t: &TestRun) -> PathBuf {
    t.run(&[
        "simulate", "--scenes", "1", "--seed", "3", "--dt", "0.05", "--run", "r", "--quiet",
    ])
    .ok();
    t.run(&[
        "simulate",
        "--env",
        "phyre",
        "--task",
        "00000:000",
        "--action",
        "[0.3, 0.8, 0.4]",
        "--run",
        "r",
        "--quiet",
    ])
    .ok();
    t.run(&[
        "simulate", "--env", "iphyre", "--game", "support", "--clicks", "0@0.5", "--run", "r",
        "--quiet",
    ])
    .ok();
    for env in ["pooltool", "phyre", "iphyre"] {
        t.run(&["annotate", "--env", env, "--run", "r", "--quiet"])
            .ok();
    }
    t.run(&["accuracy", "--env", "pooltool", "--run", "r", "--quiet"])
        .ok();
    // A second library: the first three detectors of the built-in one, under another name.
    let src = repo().join("data/libraries/pooltool");
    let dst = t.path("subset");
    std::fs::create_dir_all(&dst).unwrap();
    for e in std::fs::read_dir(&src).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
    }
    let toml = std::fs::read_to_string(src.join("library.toml")).unwrap();
    let cut: Vec<&str> = toml.split("[[detector]]").take(4).collect();
    let toml = cut
        .join("[[detector]]")
        .replace("name = \"pooltool-human\"", "name = \"pooltool-subset\"");
    std::fs::write(dst.join("library.toml"), toml).unwrap();
    t.run(&[
        "annotate",
        "--env",
        "pooltool",
        "--library",
        "subset",
        "--run",
        "r",
        "--quiet",
    ])
    .ok();
    t.run(&["report", "--run", "r", "--out", "site"])
        .ok()
        .stdout_has("report of 3 trace(s)")
        .stdout_has("pooltool-human, pooltool-subset");
    t.path("site")
}

/// The list of the report (`data/index.js`).
fn index(site: &Path) -> Value {
    let text = std::fs::read_to_string(site.join("data/index.js")).unwrap();
    let json = text
        .trim()
        .strip_prefix("window.ANNOTRACE_INDEX = ")
        .and_then(|s| s.strip_suffix(';'))
        .expect("index.js assigns the index");
    serde_json::from_str(json).unwrap()
}

/// The payload of trace `n` (`data/t/NNNNNN.js`).
fn payload(site: &Path, n: u64) -> Value {
    let text = std::fs::read_to_string(site.join(format!("data/t/{n:06}.js"))).unwrap();
    let json = text
        .trim()
        .strip_prefix("annotraceLoaded(")
        .and_then(|s| s.strip_suffix(");"))
        .unwrap();
    serde_json::from_str(json).unwrap()
}

/// The JSON the test hook wrote into `<pre id="test-result" …>`.
pub(crate) fn test_result(dom: &str) -> Value {
    let start = dom
        .find("id=\"test-result\"")
        .unwrap_or_else(|| panic!("no test result in the DOM:\n{dom}"));
    let rest = &dom[start..];
    let open = rest.find('>').unwrap() + 1;
    let close = rest.find("</pre>").unwrap();
    let text = rest[open..close]
        .replace("&quot;", "\"")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&");
    assert!(
        rest[..open].contains("data-done=\"1\""),
        "the test sequence did not finish:\n{}",
        &rest[..close]
    );
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Share of pixels whose largest channel difference exceeds 48 (images of equal size), or 1.0 when
/// the sizes differ.
pub(crate) fn differing_share(a: &[u8], b: &[u8]) -> f64 {
    let (a, b) = (
        tiny_skia::Pixmap::decode_png(a).unwrap(),
        tiny_skia::Pixmap::decode_png(b).unwrap(),
    );
    if (a.width(), a.height()) != (b.width(), b.height()) {
        return 1.0;
    }
    let differing = a
        .data()
        .chunks_exact(4)
        .zip(b.data().chunks_exact(4))
        .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 48))
        .count();
    differing as f64 / (a.width() as f64 * a.height() as f64)
}

/// Most pixels may differ from the committed screenshot (fonts, anti-aliasing, a ball a pixel off).
pub(crate) const MAX_DIFFERING: f64 = 0.02;

#[test]
fn the_viewer_plays_each_environment_and_clicking_an_annotation_seeks_the_player() {
    let t = TestRun::new();
    let site = report_run(&t);
    for f in ["index.html", "viewer.js", "viewer.css", "data/index.js"] {
        assert!(site.join(f).is_file(), "{f}");
    }
    let idx = index(&site);
    let traces = idx["traces"].as_array().unwrap();
    assert_eq!(traces.len(), 3);
    // The text is `annotrace show`'s, with its token count.
    for row in traces {
        let id = row["trace_id"].as_str().unwrap();
        let p = payload(&site, row["index"].as_u64().unwrap());
        let shown = t.run(&["show", "--run", "r", "--trace", id]);
        shown.ok();
        let expected = format!(
            "{}# tokens: {} (cl100k-style estimate, see docs/detectors.md)\n",
            p["text"].as_str().unwrap(),
            p["tokens"]
        );
        assert_eq!(shown.stdout, expected, "{id}");
    }
    let Some(bin) = chromium() else { return };
    let update = std::env::var("ANNOTRACE_UPDATE_SCREENSHOTS").is_ok_and(|v| v == "1");
    let mut failures = Vec::new();
    for row in traces {
        let env = row["env"].as_str().unwrap();
        let n = row["index"].as_u64().unwrap();
        let url = format!(
            "file://{}#test={n}",
            std::fs::canonicalize(site.join("index.html"))
                .unwrap()
                .display()
        );
        let r = browse_test_sequence(&bin, &url, &t.path("profile-dom"));
        assert_eq!(r["env"], env, "{r}");
        let steps = r["steps"].as_u64().unwrap();
        assert!(steps > 2, "{r}");
        // Playing moved the clock, the frame and the playhead.
        let (b, a) = (&r["before"], &r["after"]);
        assert!(
            a["t"].as_f64() > b["t"].as_f64(),
            "{env}: playing did not advance the time: {r}"
        );
        assert!(a["step"].as_u64() > b["step"].as_u64(), "{env}: {r}");
        assert!(
            a["playhead"].as_f64() > b["playhead"].as_f64(),
            "{env}: the playhead did not move: {r}"
        );
        // Clicking an annotation seeks the player to its start.
        assert!(
            r["bars"].as_u64().unwrap() > 0,
            "{env}: no annotations: {r}"
        );
        let t0 = r["clicked"]["t0"].as_f64().unwrap();
        let seeked = r["seeked"]["t"].as_f64().unwrap();
        assert!(
            (seeked - t0).abs() < 1e-6,
            "{env}: seek {seeked} ≠ {t0}: {r}"
        );
        assert_ne!(
            r["seeked"]["playhead"], a["playhead"],
            "{env}: the playhead stayed: {r}"
        );
        // Hovering it highlights its objects.
        assert_eq!(r["highlight"], r["clicked"]["objects"], "{env}: {r}");
        assert!(r["text_chars"].as_u64().unwrap() > 100, "{r}");
        let sections: Vec<&str> = r["sections"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(Value::as_str)
            .collect();
        if env == "pooltool" {
            assert_eq!(
                sections,
                [
                    "library:pooltool-human",
                    "library:pooltool-subset",
                    "truth:ground truth",
                    "events:simulator events"
                ],
                "{r}"
            );
        } else {
            assert_eq!(sections.len(), 2, "{r}");
        }
        // The screenshot of the same sequence against the committed one.
        let shot = t.path(&format!("report-{env}.png"));
        browse(
            &bin,
            &url,
            &[&format!("--screenshot={}", shot.display())],
            &t.path("profile-shot"),
        );
        let png = std::fs::read(&shot).expect("chromium wrote the screenshot");
        let committed = repo().join(format!("tests/it/screenshots/report-{env}.png"));
        if update {
            std::fs::write(&committed, &png).unwrap();
            continue;
        }
        let old = std::fs::read(&committed).unwrap_or_else(|_| {
            panic!(
                "{} is missing: run with ANNOTRACE_UPDATE_SCREENSHOTS=1",
                committed.display()
            )
        });
        let share = differing_share(&png, &old);
        if share > MAX_DIFFERING {
            let keep = std::env::temp_dir().join(format!("annotrace-report-{env}.png"));
            std::fs::write(&keep, &png).unwrap();
            failures.push(format!(
                "{env}: {:.1} % of pixels differ from {} (new one: {})",
                100.0 * share,
                committed.display(),
                keep.display()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_run_without_traces_is_refused_and_leaves_no_report() {
    let t = TestRun::new();
    std::fs::create_dir_all(t.path("empty")).unwrap();
    t.run(&["report", "--run", "empty", "--out", "site"])
        .code(2)
        .stderr_has("report needs at least 1 traces");
    assert!(!t.path("site").exists());
    t.run(&["report", "--run", "nope"])
        .code(2)
        .stderr_has("no such run folder");
}

#[test]
fn the_trace_filters_pick_in_the_sets_order_and_show_what_the_full_report_shows() {
    let t = TestRun::new();
    // Two simulate stages: two trace file sets.
    for (scenes, seed) in [("3", "3"), ("2", "4")] {
        t.run(&[
            "simulate", "--scenes", scenes, "--seed", seed, "--dt", "0.05", "--run", "r", "-q",
        ])
        .ok();
    }
    t.run(&["annotate", "--run", "r", "-q"]).ok();
    t.run(&["report", "--run", "r", "--out", "all"]).ok();
    let all = index(&t.path("all"));
    let rows = all["traces"].as_array().unwrap();
    assert_eq!(rows.len(), 5);
    let id = |row: &Value| row["trace_id"].as_str().unwrap().to_string();
    // Each trace shows every annotation the table holds for it (read per set, by trace id).
    for row in rows {
        let n = t.csv(
            "r",
            &format!(
                "SELECT count(*) AS n FROM annotations WHERE trace_id = '{}'",
                id(row)
            ),
        );
        assert_eq!(n, format!("n\n{}\n", row["annotations"]), "{row}");
    }
    // The payload of a trace in a report, with its position in that report left out.
    let shown = |site: &str, trace: &str| {
        let idx = index(&t.path(site));
        let row = idx["traces"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["trace_id"] == trace)
            .unwrap_or_else(|| panic!("{trace} is not in {site}"))
            .clone();
        let mut row = row.as_object().unwrap().clone();
        let n = row.remove("index").unwrap().as_u64().unwrap();
        let mut p = payload(&t.path(site), n);
        assert_eq!(p.as_object_mut().unwrap().remove("index"), Some(n.into()));
        (Value::Object(row), p)
    };
    // A rerun of the stage replaces its earlier output, so each report is read before the next.
    let (second, last) = (id(&rows[1]), id(&rows[4]));
    let (all_second, all_last) = (shown("all", &second), shown("all", &last));
    // The first two, in the order of the sets and of their `traces` files.
    t.run(&["report", "--run", "r", "--out", "two", "--max-traces", "2"])
        .ok()
        .stdout_has("report of 2 trace(s)");
    let two = index(&t.path("two"));
    let two: Vec<String> = two["traces"].as_array().unwrap().iter().map(id).collect();
    assert_eq!(two, [id(&rows[0]), second.clone()]);
    assert_eq!(shown("two", &second), all_second);
    // One trace by id, the last of the full report: the same row and payload (annotations, text).
    t.run(&["report", "--run", "r", "--out", "one", "--trace", &last])
        .ok()
        .stdout_has("report of 1 trace(s)");
    assert_eq!(shown("one", &last), all_last);
}
