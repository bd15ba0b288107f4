//! Traces recorded by the original simulators (pooltool 0.6.0, iphyre 0.2.3, phyre 0.2.2; committed
//! gzipped under `tests/data/originals/`, provenance in `data/README.md`): they import, the built-in
//! libraries annotate them clean, and `detect::accuracy` (the scoring of `annotrace accuracy`) finds
//! the targets of docs/accuracy.md with the event log and without it.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::PathBuf;
use std::sync::OnceLock;

use annotrace::detect::Annotation;
use annotrace::detect::accuracy::{LabelScore, grounded, scorable};
use annotrace::trace::{Env, Trace, json};

use crate::common::{TestRun, repo};
use crate::libraries::{annotate, library, score};

fn folder(env: Env) -> PathBuf {
    repo().join("tests/data/originals").join(env.as_str())
}

/// The committed `.json.gz` files of one simulator, sorted: (file name without `.gz`, JSON text).
fn files(env: Env) -> Vec<(String, String)> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(folder(env))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".json.gz"))
        .collect();
    paths.sort();
    paths
        .iter()
        .map(|p| {
            let mut text = String::new();
            flate2::read::GzDecoder::new(std::fs::File::open(p).unwrap())
                .read_to_string(&mut text)
                .unwrap();
            let name = p.file_name().unwrap().to_string_lossy();
            (name.trim_end_matches(".gz").to_string(), text)
        })
        .collect()
}

/// The traces of one simulator, read by annotrace's importer.
pub(crate) fn traces(env: Env) -> &'static [Trace] {
    static CELLS: [OnceLock<Vec<Trace>>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let i = match env {
        Env::Pooltool => 0,
        Env::Iphyre => 1,
        Env::Phyre => 2,
    };
    CELLS[i].get_or_init(|| {
        files(env)
            .iter()
            .flat_map(|(name, text)| json::read_str(name, text, env))
            .map(|r| r.expect("an original's trace imports"))
            .collect()
    })
}

pub(crate) fn blind(traces: &[Trace]) -> Vec<Trace> {
    traces
        .iter()
        .map(|t| Trace {
            events: Vec::new(),
            ..t.clone()
        })
        .collect()
}

/// Annotates (with or without the event log) and scores against the full traces.
fn scores(env: Env, hide_events: bool) -> BTreeMap<String, LabelScore> {
    let full = traces(env);
    let anns: Vec<Annotation> = if hide_events {
        annotate(&library(env.as_str()), &blind(full))
    } else {
        annotate(&library(env.as_str()), full)
    };
    score(env, full, &anns)
}

fn at_least(scores: &BTreeMap<String, LabelScore>, label: &str, f1: f64) {
    let s = &scores[label];
    assert!(s.events > 0, "{label}: no truth events");
    assert!(s.f1() >= f1, "{label}: F1 {:.3} < {f1}: {s:?}", s.f1());
}

#[test]
fn the_originals_traces_are_all_there_and_scorable() {
    for (env, n) in [(Env::Pooltool, 30), (Env::Iphyre, 10), (Env::Phyre, 10)] {
        let ts = traces(env);
        assert_eq!(ts.len(), n, "{env}");
        assert!(ts.iter().all(|t| scorable(env, t)), "{env}");
    }
    // What pooltool records: payload `agents` only.
    for t in traces(Env::Pooltool) {
        for e in &t.events {
            let p = e.payload.as_ref().unwrap().as_object().unwrap();
            assert_eq!(p.keys().collect::<Vec<_>>(), ["agents"], "{e:?}");
        }
    }
    // No contact events in PHYRE's and I-PHYRE's.
    for env in [Env::Iphyre, Env::Phyre] {
        assert!(
            traces(env)
                .iter()
                .flat_map(|t| &t.events)
                .all(|e| !e.kind.starts_with("contact"))
        );
    }
}

#[test]
fn pooltool_library_on_pooltools_own_traces_with_events() {
    let s = scores(Env::Pooltool, false);
    for label in grounded(Env::Pooltool) {
        at_least(&s, label, 0.97);
    }
}

#[test]
fn pooltool_library_on_pooltools_own_traces_without_events() {
    let s = scores(Env::Pooltool, true);
    for label in [
        "cue strike",
        "ball collision",
        "cushion rebound",
        "ball pocketed",
    ] {
        at_least(&s, label, 0.9);
    }
}

#[test]
fn iphyre_library_on_iphyres_own_traces() {
    for hide in [false, true] {
        let s = scores(Env::Iphyre, hide);
        at_least(&s, "collision", 0.9);
        at_least(&s, "object removal", 0.95);
        at_least(&s, "airborne motion", 0.85);
        // The motion labels with ten or more truth events here (docs/accuracy.md).
        for label in ["support contact", "falling object", "sliding contact"] {
            at_least(&s, label, 0.9);
        }
    }
}

#[test]
fn phyre_library_on_phyres_own_traces() {
    // PHYRE records no contacts: with or without the rest of its log the detector works from geometry.
    let s = scores(Env::Phyre, true);
    at_least(&s, "moving object hits stationary object", 0.9);
    // Every label with ten or more truth events here but bounce (docs/accuracy.md: phyre's impacts
    // resolved inside one step never show touching outlines in its frames, so the truth misses them).
    for label in [
        "falling object",
        "rolling object",
        "sliding contact",
        "grid cell transition",
        "support relationship",
        "airborne motion",
    ] {
        at_least(&s, label, 0.9);
    }
    // The implicit floor and sides support and wedge bodies too.
    at_least(&s, "wedged", 0.9);
}

#[test]
fn show_says_what_an_imported_original_trace_lacks() {
    let run = TestRun::new();
    for env in [Env::Iphyre, Env::Phyre] {
        let (name, text) = &files(env)[0];
        run.write(&format!("in-{env}/{name}"), text);
        let (input, out) = (format!("in-{env}"), format!("r-{env}"));
        run.run(&["import", "--env", env.as_str(), &input, "--run", &out])
            .ok();
    }
    let id = |env: Env| files(env)[0].0.trim_end_matches(".json").to_string();
    run.run(&["show", "--run", "r-iphyre", "--trace", &id(Env::Iphyre)])
        .ok()
        .stdout_has("no contact log")
        .stdout_has("objects without angle, vx, vy, angular_velocity");
    run.run(&["show", "--run", "r-phyre", "--trace", &id(Env::Phyre)])
        .ok()
        .stdout_has("no contact log")
        .stdout_has("walls not listed")
        .stdout_has("velocities estimated from positions");
}

#[test]
fn accuracy_imports_and_scores_pooltools_traces_from_the_cli() {
    let run = TestRun::new();
    for (name, text) in files(Env::Pooltool).iter().take(6) {
        run.write(&format!("in/{name}"), text);
    }
    run.run(&["import", "--env", "pooltool", "in", "--run", "r"])
        .ok();
    let lib = repo().join("data/libraries/pooltool");
    let out = run.run(&[
        "accuracy",
        "--run",
        "r",
        "--workers",
        "2",
        "--library",
        lib.to_str().unwrap(),
    ]);
    out.ok()
        .stdout_has("| ball pocketed |")
        .stdout_has("6 trace(s)");
    // Pocketing is grounded in `agents` alone: a row with events and F1 1.000.
    let row = out
        .stdout
        .lines()
        .find(|l| l.starts_with("| cushion rebound |"))
        .unwrap();
    assert!(row.ends_with("| 1.000 |"), "{row}");
}

/// Traces read back by id (`store::read_traces`: what `summarise`, `suggest-labels`, `show` and
/// `export` read) are the traces imported: the originals of two simulators in one run, asked for in
/// a shuffled order across both partitions with one id twice, each equal to the importer's trace;
/// one alone through `read_trace`; an unknown id among known ones is an error naming it.
#[test]
fn traces_read_back_by_id_are_the_imported_ones() {
    use annotrace::store::{RunDir, read_trace, read_traces};
    let run = TestRun::new();
    for env in [Env::Pooltool, Env::Phyre] {
        for (name, text) in files(env) {
            run.write(&format!("in-{env}/{name}"), &text);
        }
        let input = format!("in-{env}");
        run.run(&["import", "--env", env.as_str(), &input, "--run", "r"])
            .ok();
    }
    let dir = RunDir::new(run.path("r"));
    // The command names a trace after its file, without `.json`.
    let truth: BTreeMap<String, Trace> = traces(Env::Pooltool)
        .iter()
        .chain(traces(Env::Phyre))
        .map(|t| {
            let id = t.trace_id.trim_end_matches(".json").to_string();
            let t = Trace {
                trace_id: id.clone(),
                ..t.clone()
            };
            (id, t)
        })
        .collect();
    assert_eq!(truth.len(), 40);
    // Every id, shuffled (a fixed permutation), and one of them again.
    let sorted: Vec<&str> = truth.keys().map(String::as_str).collect();
    let mut ids: Vec<String> = (0..sorted.len())
        .map(|i| sorted[(i * 17 + 5) % sorted.len()].to_string())
        .collect();
    ids.push(ids[3].clone());
    let back = read_traces(&dir, &ids).unwrap();
    assert_eq!(back.len(), ids.len());
    for (id, t) in ids.iter().zip(&back) {
        assert_eq!(&t.trace_id, id);
        assert!(*t == truth[id], "{id} reads back otherwise");
    }
    assert!(read_trace(&dir, &ids[7]).unwrap() == truth[&ids[7]]);
    let err = read_traces(&dir, &[ids[0].as_str(), "nope"])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("no trace \"nope\"") && err.contains("40 trace(s)"),
        "{err}"
    );
}
