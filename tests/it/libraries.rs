//! The built-in I-PHYRE and PHYRE detector libraries on small simulated datasets: they load, every
//! detector runs clean, and the event-grounded labels find the simulator's events (F1 thresholds via
//! `detect::accuracy`, the same scoring as `annotrace accuracy`).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::OnceLock;
use std::time::Duration;

use annotrace::detect::accuracy::{LabelScore, grounded, score_trace, truth};
use annotrace::detect::{Annotation, CandidateStatus, Library, SandboxLimits, WorkerPool};
use annotrace::envs::iphyre::{Games, PhysicsParams, click_block, clicks_rng, play, random_clicks};
use annotrace::envs::phyre::{
    RecordOptions, TaskSet, action_rng, dataset_tasks, episode, random_valid_action,
};
use annotrace::trace::{Env, Trace};

use crate::common::TestRun;

pub(crate) fn library(env: &str) -> Library {
    Library::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data/libraries")
            .join(env),
    )
    .unwrap()
}

/// One seeded random click set per I-PHYRE game at the gym rate (10 fps, 150 frames each).
fn iphyre_traces() -> &'static [Trace] {
    static TRACES: OnceLock<Vec<Trace>> = OnceLock::new();
    TRACES.get_or_init(|| {
        let games = Games::default_games().unwrap();
        let params = PhysicsParams::with_fps(10.0);
        games
            .all()
            .iter()
            .map(|g| {
                let clicks = random_clicks(g, &mut clicks_rng(3, g.index as u64, 0));
                let r = play(g, &clicks, &params).unwrap();
                annotrace::envs::iphyre::trace_of(&r, g, &format!("lib-{}", g.name))
            })
            .collect()
    })
}

/// Runs `lib` over `traces`, asserting every call is `ok`; returns the annotations.
pub(crate) fn annotate(lib: &Library, traces: &[Trace]) -> Vec<Annotation> {
    let pool = WorkerPool::new(SandboxLimits {
        workers: 2,
        call_timeout: Duration::from_secs(30),
        ..SandboxLimits::default()
    })
    .unwrap();
    let batch = pool.run(&lib.detectors, traces);
    let mut out = Vec::new();
    for r in &batch.results {
        assert_eq!(
            r.status,
            CandidateStatus::Ok,
            "{} on {}: {:?}",
            lib.detectors[r.detector].label,
            traces[r.trace].trace_id,
            r.status
        );
        for (seq, p) in r.patterns.iter().enumerate() {
            out.push(Annotation::new(
                &lib.detectors[r.detector],
                &traces[r.trace],
                seq,
                p.clone(),
            ));
        }
    }
    out
}

/// Scores annotations of `traces` against their simulator events (tolerance and merge 50 ms).
pub(crate) fn score(
    env: Env,
    traces: &[Trace],
    anns: &[Annotation],
) -> BTreeMap<String, LabelScore> {
    let mut scores = BTreeMap::new();
    for t in traces {
        let mine: Vec<&Annotation> = anns.iter().filter(|a| a.trace_id == t.trace_id).collect();
        score_trace(
            grounded(env),
            &truth(env, t, 0.05),
            &mine,
            0.05,
            &mut scores,
        );
    }
    scores
}

/// One seeded random valid red ball on the first task of each of the 25 PHYRE ball-tier templates (frames
/// every 6 steps, as `simulate --env phyre`).
fn phyre_traces() -> &'static [Trace] {
    static TRACES: OnceLock<Vec<Trace>> = OnceLock::new();
    TRACES.get_or_init(|| {
        let set = TaskSet::default_tasks().unwrap();
        let params = annotrace::envs::phyre::PhysicsParams::default();
        dataset_tasks(set, 25, &[])
            .iter()
            .map(|id| {
                let task = set.get(id).unwrap();
                let index = set.position(id).unwrap() as u64;
                let action = random_valid_action(&task, &mut action_rng(3, index, 0))
                    .unwrap()
                    .unwrap();
                let r = episode::run(&task, &action, &params, &RecordOptions::default()).unwrap();
                annotrace::envs::phyre::trace_of(&r, &task, &format!("lib-{id}"))
            })
            .collect()
    })
}

fn count(anns: &[Annotation], label: &str) -> usize {
    anns.iter().filter(|a| a.label == label).count()
}

#[test]
fn the_iphyre_library_loads_with_the_papers_twelve_labels() {
    let lib = library("iphyre");
    let labels: Vec<&str> = lib.detectors.iter().map(|d| d.label.as_str()).collect();
    assert_eq!(
        labels,
        [
            "collision",
            "support contact",
            "falling object",
            "swinging object",
            "object removal",
            "sliding contact",
            "airborne motion",
            "bounce",
            "chain movement",
            "spring pull towards",
            "spring resist movement",
            "lever launch"
        ]
    );
}

#[test]
fn the_iphyre_library_runs_clean_and_scores_its_grounded_labels() {
    let traces = iphyre_traces();
    let lib = library("iphyre");
    let anns = annotate(&lib, traces);
    let scores = score(Env::Iphyre, traces, &anns);
    for label in grounded(Env::Iphyre) {
        let s = &scores[*label];
        eprintln!("{label}: {} events, F1 {:.3}", s.events, s.f1());
    }
    for label in [
        "collision",
        "object removal",
        "airborne motion",
        "support contact",
    ] {
        let s = &scores[label];
        assert!(s.events > 20, "{label}: only {} events", s.events);
        assert!(s.f1() >= 0.95, "{label}: {s:?}");
    }
    // Every grounded label with a few truth events scores F1 >= 0.9 (docs/accuracy.md); at 10 fps a
    // swing of the 40 games' joints is too slow to count, so one label may have none, and with the
    // one-substep physics (docs/fidelity.md) these clicks launch a lever once (three times before).
    let mut seen = 0;
    for label in grounded(Env::Iphyre) {
        let s = &scores[*label];
        if s.events >= 3 {
            seen += 1;
            assert!(s.f1() >= 0.9, "{label}: {s:?}");
        }
    }
    assert!(seen >= 9, "{seen} labels with events");
    // The geometric labels fire somewhere in the 40 games (each is calibrated in docs/accuracy.md).
    for label in [
        "support contact",
        "falling object",
        "sliding contact",
        "airborne motion",
        "spring pull towards",
    ] {
        assert!(count(&anns, label) > 0, "{label} never fired");
    }
}

#[test]
fn without_an_event_log_the_iphyre_library_infers_contacts_and_removals() {
    let traces: Vec<Trace> = iphyre_traces()
        .iter()
        .take(20)
        .map(|t| Trace {
            events: Vec::new(),
            ..t.clone()
        })
        .collect();
    let lib = library("iphyre");
    let anns = annotate(&lib, &traces);
    // Scored against the full traces' events.
    let scores = score(Env::Iphyre, &iphyre_traces()[..20], &anns);
    let removal = &scores["object removal"];
    assert!(removal.f1() >= 0.95, "{removal:?}");
    // Contacts from 10 fps geometry are coarse (docs/accuracy.md scores them at 60 fps); they must
    // still be found and partly line up with the simulator's.
    let collision = &scores["collision"];
    assert!(collision.true_positives > 0, "{collision:?}");
}

#[test]
fn the_support_game_shows_a_removal_then_the_ball_falling() {
    let games = Games::default_games().unwrap();
    let g = games.get("support").unwrap();
    // The ball lands on block 0 at about 0.8 s and rests there until the click at 2 s.
    let clicks = [click_block(g, 0, 2.0).unwrap()];
    let r = play(g, &clicks, &PhysicsParams::with_fps(10.0)).unwrap();
    let trace = annotrace::envs::iphyre::trace_of(&r, g, "support-known");
    let removed = g.eliminable().next().unwrap().index.to_string();
    let anns = annotate(&library("iphyre"), std::slice::from_ref(&trace));
    let removal: Vec<&Annotation> = anns
        .iter()
        .filter(|a| a.label == "object removal")
        .collect();
    assert_eq!(removal.len(), 1, "{anns:#?}");
    assert!(removal[0].objects.contains(&removed));
    assert!((removal[0].t_start - 2.0).abs() <= 0.11, "{:?}", removal[0]);
    // The red ball rested on the removed block, then falls again after the removal.
    assert!(
        anns.iter()
            .any(|a| a.label == "falling object" && a.t_start >= removal[0].t_start - 0.11),
        "{anns:#?}"
    );
    assert!(
        anns.iter()
            .any(|a| a.label == "support contact" && a.objects.contains(&removed)),
        "{anns:#?}"
    );
}

#[test]
fn accuracy_scores_an_iphyre_run_from_the_cli() {
    let run = TestRun::new();
    let args = [
        "simulate", "--env", "iphyre", "--games", "basic", "--fps", "10",
    ];
    run.run(&[&args[..], &["--seed", "5", "--run", "r"]].concat())
        .ok();
    let lib = crate::common::repo().join("data/libraries/iphyre");
    let lib = lib.to_str().unwrap();
    run.run(&[
        "accuracy",
        "--env",
        "iphyre",
        "--workers",
        "2",
        "--run",
        "r",
        "--library",
        lib,
    ])
    .ok()
    .stdout_has("| collision |")
    .stdout_has("| object removal |");
}

#[test]
fn the_phyre_library_loads_with_the_papers_twelve_labels() {
    let lib = library("phyre");
    let labels: Vec<&str> = lib.detectors.iter().map(|d| d.label.as_str()).collect();
    assert_eq!(
        labels,
        [
            "moving object hits stationary object",
            "near collision",
            "support relationship",
            "lose support",
            "falling object",
            "rolling object",
            "sliding contact",
            "airborne motion",
            "bounce",
            "grid cell transition",
            "wedged",
            "tip over"
        ]
    );
}

#[test]
fn the_phyre_library_runs_clean_and_scores_its_grounded_labels() {
    let traces = phyre_traces();
    let lib = library("phyre");
    let anns = annotate(&lib, traces);
    let scores = score(Env::Phyre, traces, &anns);
    for label in grounded(Env::Phyre) {
        let s = &scores[*label];
        eprintln!("{label}: {} events, F1 {:.3}", s.events, s.f1());
    }
    let s = &scores["moving object hits stationary object"];
    assert!(s.events > 20, "only {} events", s.events);
    assert!(s.f1() >= 0.9, "{s:?}");
    let mut seen = 0;
    // Every grounded label with a few truth events, airborne motion and wedged included, scores F1 >= 0.9.
    for label in grounded(Env::Phyre) {
        let s = &scores[*label];
        if s.events >= 3 {
            seen += 1;
            assert!(s.f1() >= 0.9, "{label}: {s:?}");
        }
    }
    assert!(seen >= 9, "{seen} labels with events");
    for label in [
        "support relationship",
        "falling object",
        "airborne motion",
        "bounce",
        "grid cell transition",
    ] {
        assert!(count(&anns, label) > 0, "{label} never fired");
    }
    // Every falling object moves down (y up) between its first and last step.
    for a in anns.iter().filter(|a| a.label == "falling object") {
        let d = &a.parameters["object_details"];
        let (_, o) = d.as_object().unwrap().iter().next().unwrap();
        assert!(
            o["start_position"][1].as_f64() > o["end_position"][1].as_f64(),
            "{a:?}"
        );
    }
}

#[test]
fn without_an_event_log_the_phyre_library_still_runs_clean() {
    let traces: Vec<Trace> = phyre_traces()
        .iter()
        .take(10)
        .map(|t| Trace {
            events: Vec::new(),
            ..t.clone()
        })
        .collect();
    let anns = annotate(&library("phyre"), &traces);
    // Ball contacts from geometry: a ball landing on the floor is found.
    assert!(count(&anns, "support relationship") > 0, "{anns:#?}");
}

/// The clock every built-in detector starts from (`_clock` of each library's `_common.py` prelude):
/// indices and times by subscript when every step has both, else each step's own defaults (its
/// position, time 0), with the errors the per-step loop raises on a bad time.
#[test]
fn the_preludes_clock_is_each_steps_index_and_time_with_defaults_for_missing_ones() {
    const CHECK: &str = r#"
cases = [
    ({"timesteps": [{"index": 3, "t": 0.5}, {"index": 4, "t": 1}]}, ([3, 4], [0.5, 1.0])),
    ({"timesteps": [{"t": 0.5}, {"index": 9, "t": 0.75}]}, ([0, 9], [0.5, 0.75])),
    ({"timesteps": [{"index": 2}, {"index": 3, "t": 0.1}]}, ([2, 3], [0.0, 0.1])),
    ({"timesteps": [{"index": 5, "t": 1}, {"t": 2}, {}]}, ([5, 1, 2], [1.0, 2.0, 0.0])),
    ({"timesteps": ()}, ([], [])),
    ({}, ([], [])),
]
for trace, want in cases:
    got = _clock(trace)
    assert got == want, (trace, got)
    assert all(type(t) is float for t in got[1]), got
for steps, error in (([{"index": 0, "t": None}], TypeError), ([{"t": "x"}], ValueError),
                     ([{"index": 0, "t": 0}, [1, 2]], AttributeError)):
    try:
        _clock({"timesteps": steps})
    except error:
        pass
    else:
        raise AssertionError("no %s for %r" % (error.__name__, steps))
print("ok")
"#;
    for env in ["pooltool", "phyre", "iphyre"] {
        let prelude = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data/libraries")
            .join(env)
            .join("_common.py");
        let code = format!("{}\n{CHECK}", std::fs::read_to_string(&prelude).unwrap());
        let out = std::process::Command::new("python3")
            .args(["-c", &code])
            .output()
            .expect("python3 runs");
        assert!(
            out.status.success() && out.stdout == b"ok\n",
            "{env}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
