//! Reward programs: every DSL function on hand-made annotated traces (true, false and partial-credit
//! values), the paper's ten goals on constructed stories (each means its sentence, in order), the goal
//! files, verification rules on event logs, error categories and positions, and `annotrace reward`.

use annotrace::detect::{Annotation, DetectorId, Library};
use annotrace::reward::goals::GoalSet;
use annotrace::reward::verify::Rule;
use annotrace::reward::{
    AnnotatedTrace, ErrorCategory, Evaluation, Schema, compile, evaluate, shape,
};
use annotrace::testutil::synthetic_trace;
use annotrace::trace::{Env, Event, JsonMap, Trace};
use serde_json::{Value, json};

use crate::common::{TestRun, repo};

fn schema() -> Schema {
    let lib = Library::load(&repo().join("data/libraries/pooltool")).unwrap();
    let mut s = Schema::from_library(&lib);
    s.learn_keys(&[ann(
        "ball pocketed",
        0.0,
        0.0,
        &["8", "rt"],
        json!({"pocket": "rt", "t": 0.0}),
    )]);
    s
}

/// A 2-second pooltool trace (201 steps, dt 0.01): ball k sits at (k + t, 2k); the cue ball is ball 0.
fn trace() -> Trace {
    let mut t = synthetic_trace(Env::Pooltool, 0, 201, 10);
    t.trace_id = "story".into();
    t.events.clear();
    t
}

fn event(kind: &str, t: f64, payload: Value) -> Event {
    Event {
        kind: kind.into(),
        t: Some(t),
        payload: Some(payload),
        extra: JsonMap::new(),
    }
}

/// The cue ball touches `ball` at time `t` (a simulator event).
fn hit(tr: &mut Trace, ball: &str, t: f64) {
    tr.events.push(event(
        "physics_ball_ball",
        t,
        json!({"agents": ["cue", ball]}),
    ));
    tr.events
        .sort_by(|a, b| a.t.unwrap().total_cmp(&b.t.unwrap()));
}

fn ann(label: &str, t0: f64, t1: f64, objects: &[&str], mut params: Value) -> Annotation {
    let details: serde_json::Map<String, Value> = objects
        .iter()
        .map(|o| (o.to_string(), json!({"ball_id": o})))
        .collect();
    params["object_details"] = Value::Object(details);
    Annotation {
        detector_id: DetectorId(format!("d-{label}")),
        trace_id: "story".into(),
        label: label.into(),
        seq: 0,
        start_step: (t0 * 100.0).round() as i64,
        end_step: (t1 * 100.0).round() as i64,
        t_start: t0,
        t_end: t1,
        objects: objects.iter().map(|s| s.to_string()).collect(),
        parameters: params.as_object().unwrap().clone(),
        provenance: None,
        metadata: None,
        activation: 1.0,
    }
}

fn run(program: &str, tr: &Trace, anns: &[Annotation]) -> Evaluation {
    let p = compile(program, &schema()).unwrap_or_else(|e| panic!("{program}: {e}"));
    evaluate(&p, &AnnotatedTrace::new(tr, anns)).unwrap()
}

fn close(a: f64, b: f64) {
    assert!((a - b).abs() < 1e-9, "{a} != {b}");
}

/// cue strike at 0, cue rolls 0.1–0.5, cue hits 3 at 0.5, cushion rebounds of 3 at 0.8 and 1.0,
/// 3 pocketed in rt at 1.2.
fn basic() -> (Trace, Vec<Annotation>) {
    let mut tr = trace();
    hit(&mut tr, "3", 0.5);
    let anns = vec![
        ann("cue strike", 0.0, 0.0, &["cue"], json!({"t": 0.0})),
        ann("rolling ball", 0.1, 0.5, &["cue"], json!({})),
        ann("ball collision", 0.5, 0.51, &["cue", "3"], json!({})),
        ann(
            "cushion rebound",
            0.8,
            0.8,
            &["3"],
            json!({"cushions": ["12"]}),
        ),
        ann(
            "cushion rebound",
            1.0,
            1.0,
            &["3"],
            json!({"cushions": ["3"]}),
        ),
        ann(
            "ball pocketed",
            1.2,
            1.2,
            &["3", "rt"],
            json!({"pocket": "rt", "t": 1.2}),
        ),
    ];
    (tr, anns)
}

#[test]
fn pattern_with_params_and_keyword_filters() {
    let (tr, a) = basic();
    assert!(run(r#"PATTERN("cue strike")"#, &tr, &a).success);
    assert!(
        run(r#"PATTERN("Ball_Pocket")"#, &tr, &a).success,
        "alias, case and _ ignored"
    );
    assert!(run(r#"PATTERN("ball pocketed", {"pocket": "RT"})"#, &tr, &a).success);
    assert!(!run(r#"PATTERN("ball pocketed", {"pocket": "lb"})"#, &tr, &a).success);
    assert!(
        run(
            r#"PATTERN("ball pocketed", ball="3", pocket="rt")"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        run(r#"PATTERN("ball pocketed", ball=3)"#, &tr, &a).success,
        "numbers match ids"
    );
    assert!(!run(r#"PATTERN("ball pocketed", ball="8")"#, &tr, &a).success);
    assert!(
        run(
            r#"PATTERN("ball collision", contains=["3", "cue"])"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"PATTERN("ball collision", contains=["cue", "2"])"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(r#"PATTERN("ball collision", ball="3")"#, &tr, &a).success,
        "3 is not the subject"
    );
    assert!(!run(r#"PATTERN("gentle touch")"#, &tr, &a).success);
    let e = run(r#"PATTERN("gentle touch")"#, &tr, &a);
    close(e.score, 0.0);
}

#[test]
fn pattern_count_scores_missing_occurrences() {
    let (tr, a) = basic();
    assert!(
        run(
            r#"PATTERN_COUNT("cushion rebound", ball="3", min_count=2)"#,
            &tr,
            &a
        )
        .success
    );
    let e = run(
        r#"PATTERN_COUNT("cushion rebound", ball="3", min_count=3)"#,
        &tr,
        &a,
    );
    assert!(!e.success);
    close(e.score, shape(1.0));
    close(shape(1.0), 1.0 / (1.0 + 2f64.ln()));
    let e = run(
        r#"PATTERN_COUNT("cushion rebound", ball="cue", min_count=2)"#,
        &tr,
        &a,
    );
    close(e.score, shape(2.0));
}

#[test]
fn and_or_not_and_top_level_partial_credit() {
    let (tr, a) = basic();
    let e = run(
        r#"AND(PATTERN("cue strike"), PATTERN("gentle touch"), NOT(PATTERN("spin shot")), OR(PATTERN("thin cut"), PATTERN("sliding ball")))"#,
        &tr,
        &a,
    );
    assert!(!e.success);
    assert_eq!(
        e.clauses.iter().map(|c| c.truth).collect::<Vec<_>>(),
        [true, false, true, false]
    );
    close(e.score, 0.5);
    assert!(
        run(
            r#"OR(PATTERN("gentle touch"), PATTERN("cue strike"))"#,
            &tr,
            &a
        )
        .success
    );
    assert!(!run(r#"NOT(PATTERN("cue strike"))"#, &tr, &a).success);
    // A quantitative clause contributes its graded score to the mean.
    let e = run(
        r#"AND(PATTERN("cue strike"), COUNT("cushion rebound", 3))"#,
        &tr,
        &a,
    );
    close(e.score, (1.0 + shape(1.0)) / 2.0);
    let ok = run(
        r#"AND(PATTERN("cue strike"), COUNT("cushion rebound", 2))"#,
        &tr,
        &a,
    );
    assert!(ok.success);
    close(ok.score, 1.0);
}

#[test]
fn after_holds_when_the_first_argument_comes_later() {
    let (tr, a) = basic();
    assert!(run(r#"AFTER("ball pocketed", "cue strike")"#, &tr, &a).success);
    assert!(!run(r#"AFTER("cue strike", "ball pocketed")"#, &tr, &a).success);
    assert!(
        run(
            r#"AFTER("ball pocketed", "cue strike", min_delta=1.0)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"AFTER("ball pocketed", "cue strike", min_delta=1.5)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"AFTER("ball pocketed", "cue strike", max_delta=1.0)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(run(
        r#"AFTER("ball pocketed", "cushion rebound", first_params={"pocket": "rt"}, second_params={"cushions": ["3"]})"#,
        &tr,
        &a
    )
    .success);
    assert!(
        !run(
            r#"AFTER("ball pocketed", "cushion rebound", first_params={"pocket": "lb"})"#,
            &tr,
            &a
        )
        .success
    );
    // Nested expressions: events from PATTERN, CUE_HIT, PATTERN_COUNT and AFTER itself.
    assert!(
        run(
            r#"AFTER(PATTERN("ball pocketed", ball="3"), CUE_HIT("3"))"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"AFTER(CUE_HIT("3"), PATTERN("ball pocketed", ball="3"))"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        run(
            r#"AFTER(PATTERN_COUNT("cushion rebound", min_count=2), CUE_HIT("3"))"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"AFTER(CUE_HIT("3"), PATTERN_COUNT("cushion rebound", min_count=2))"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        run(
            r#"AFTER(PATTERN("ball pocketed"), AFTER(PATTERN("cushion rebound"), CUE_HIT("3")))"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        run(
            r#"AFTER(OR(PATTERN("gentle touch"), PATTERN("ball pocketed")), "rolling ball")"#,
            &tr,
            &a
        )
        .success
    );
}

#[test]
fn within_bounds_the_delay() {
    let (tr, a) = basic();
    assert!(
        run(
            r#"WITHIN("cushion rebound", "ball collision", 0.35)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"WITHIN("cushion rebound", "ball collision", 0.2)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(
        !run(
            r#"WITHIN("ball collision", "cushion rebound", 5.0)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(run(
        r#"WITHIN("ball pocketed", "cushion rebound", 0.25, event_params={"pocket": "rt"}, reference_params={"cushions": ["3"]})"#,
        &tr,
        &a
    )
    .success);
}

#[test]
fn count_gt_lt_score_their_deviation() {
    let (tr, a) = basic();
    assert!(run(r#"COUNT("cushion rebound", 2)"#, &tr, &a).success);
    let e = run(r#"COUNT("cushion rebound", 5)"#, &tr, &a);
    close(e.score, shape(3.0));
    let e = run(r#"COUNT("cushion rebound", 0)"#, &tr, &a);
    close(e.score, shape(2.0));
    assert!(
        run(
            r#"COUNT("cushion rebound", 1, {"cushions": ["12"]})"#,
            &tr,
            &a
        )
        .success
    );
    assert!(run(r#"GT("cushion rebound", 1)"#, &tr, &a).success);
    let e = run(r#"GT("cushion rebound", 3)"#, &tr, &a);
    close(e.score, shape(2.0));
    assert!(run(r#"LT("cushion rebound", 3)"#, &tr, &a).success);
    let e = run(r#"LT("cushion rebound", 1)"#, &tr, &a);
    close(e.score, shape(2.0));
    assert!(run(r#"LT("gentle touch", 1)"#, &tr, &a).success);
    assert!(run(r#"COUNT("cushion rebound", 2, ball="3")"#, &tr, &a).success);
}

#[test]
fn nearby_at_in_table_metres_with_inverse_log_shaping() {
    let (tr, a) = basic();
    // The cue ball is at (t, 0): at t = 1 s (normalised 0.5) it is at (1, 0).
    assert!(run(r#"NEARBY_AT("cue", 1.05, 0.0, 0.5)"#, &tr, &a).success);
    let e = run(r#"NEARBY_AT("cue", 1.3, 0.0, 0.5)"#, &tr, &a);
    assert!(!e.success);
    close(e.score, shape(0.3 / 0.1 - 1.0));
    let far = run(r#"NEARBY_AT("cue", 1.9, 0.0, 0.5)"#, &tr, &a);
    assert!(far.score < e.score && far.score > 0.0);
    let wide = run(
        r#"NEARBY_AT("cue", 1.3, 0.0, 0.5, threshold_strength=0.5)"#,
        &tr,
        &a,
    );
    assert!(wide.success);
    // Ball 8 (black) starts at (8, 16).
    assert!(
        run(
            r#"NEARBY_AT(OBJECT_ID("black", "ball"), 8.0, 16.0, 0.0)"#,
            &tr,
            &a
        )
        .success
    );
}

#[test]
fn object_id_and_cue_hit_from_the_event_log() {
    let (mut tr, a) = basic();
    assert!(run(r#"CUE_HIT("3")"#, &tr, &a).success);
    assert!(run(r#"CUE_HIT(OBJECT_ID("red", "ball"))"#, &tr, &a).success);
    assert!(!run(r#"CUE_HIT("8")"#, &tr, &a).success);
    // A later contact with 8 does not make 8 the ball the cue ball hit first.
    hit(&mut tr, "8", 0.9);
    assert!(!run(r#"CUE_HIT("8")"#, &tr, &a).success);
    let p = compile(r#"CUE_HIT(OBJECT_ID("pink", "ball"))"#, &schema()).unwrap();
    let e = evaluate(&p, &AnnotatedTrace::new(&tr, &a)).unwrap_err();
    assert_eq!(e.category, ErrorCategory::Runtime);
}

#[test]
fn pocketed_comes_from_the_event_log() {
    let (mut tr, a) = basic();
    tr.events.push(event(
        "physics_ball_pocket",
        1.234,
        json!({"agents": ["3", "rt"], "ball": "3"}),
    ));
    tr.events.push(event(
        "physics_ball_pocket",
        1.5,
        json!({"agents": ["cue", "lb"], "ball": "cue"}),
    ));
    assert!(run(r#"POCKETED("3")"#, &tr, &a).success);
    assert!(run(r#"POCKETED(OBJECT_ID("red", "ball"), "RT")"#, &tr, &a).success);
    assert!(!run(r#"POCKETED("3", "lb")"#, &tr, &a).success);
    assert!(!run(r#"POCKETED("8")"#, &tr, &a).success);
    assert!(
        run(
            r#"AFTER(POCKETED("3"), CUE_HIT("3"), min_delta=0.7)"#,
            &tr,
            &a
        )
        .success
    );
    assert!(run(r#"AFTER(POCKETED("cue"), POCKETED("3"))"#, &tr, &a).success);
    assert!(!run(r#"AFTER(POCKETED("3"), POCKETED("cue"))"#, &tr, &a).success);
    let e = compile(r#"POCKETED("3", 4)"#, &schema()).unwrap_err();
    assert_eq!((e.category, e.pos.col), (ErrorCategory::ArgumentType, 15));
}

/// A trace with its annotations.
type Story = (Trace, Vec<Annotation>);

/// A story: annotations plus the first ball the cue ball hits and when.
fn story(first_hit: (&str, f64), anns: Vec<Annotation>) -> (Trace, Vec<Annotation>) {
    let mut tr = trace();
    hit(&mut tr, first_hit.0, first_hit.1);
    (tr, anns)
}

fn goals() -> GoalSet {
    GoalSet::load(&repo().join("data/goals/pooltool.toml"), &repo()).unwrap()
}

fn goal_on(id: &str, s: &(Trace, Vec<Annotation>)) -> Evaluation {
    let set = goals();
    let mut sch = set.schema.clone();
    sch.learn_keys(&s.1);
    let p = compile(&set.get(id).unwrap().program, &sch).unwrap();
    evaluate(&p, &AnnotatedTrace::new(&s.0, &s.1)).unwrap()
}

#[test]
fn every_paper_goal_means_its_sentence() {
    let curve = |t: f64| {
        ann(
            "ball curves around ball",
            t,
            t + 0.2,
            &["cue", "4"],
            json!({}),
        )
    };
    let pocket = |b: &str, t: f64| ann("ball pocketed", t, t, &[b, "lb"], json!({"pocket": "lb"}));
    let cushion = |b: &str, t: f64| ann("cushion rebound", t, t, &[b], json!({}));
    let episode = |l: &str, b: &str, t0: f64, t1: f64| ann(l, t0, t1, &[b], json!({}));
    let pair = |l: &str, b: &str, t: f64| ann(l, t, t + 0.01, &["cue", b], json!({}));
    // (goal, the sentence acted out in order, the same events in an order the sentence excludes)
    let cases: Vec<(&str, Story, Story)> = vec![
        (
            "curve-pot-8",
            story(("8", 0.6), vec![curve(0.2), pocket("8", 1.2)]),
            story(("8", 0.1), vec![curve(0.2), pocket("8", 1.2)]),
        ),
        (
            "roll-spin-pot-8",
            story(
                ("8", 0.6),
                vec![
                    episode("rolling ball", "cue", 0.2, 0.6),
                    episode("spinning ball", "cue", 0.7, 1.0),
                    pocket("8", 1.1),
                ],
            ),
            story(
                ("8", 0.6),
                vec![
                    episode("rolling ball", "cue", 0.2, 0.6),
                    episode("spinning ball", "cue", 0.3, 0.5),
                    pocket("8", 1.1),
                ],
            ),
        ),
        (
            "spin-curve-pot-3",
            story(
                ("3", 0.7),
                vec![
                    episode("spinning ball", "cue", 0.9, 1.2),
                    curve(0.3),
                    pocket("3", 1.3),
                ],
            ),
            story(
                ("3", 0.7),
                vec![
                    episode("spinning ball", "cue", 0.9, 1.2),
                    curve(0.3),
                    pocket("3", 0.5),
                ],
            ),
        ),
        (
            "slide-cut-pot-2",
            story(
                ("2", 0.4),
                vec![
                    episode("sliding ball", "cue", 0.0, 0.4),
                    pair("high angle collision", "2", 0.4),
                    pocket("2", 1.0),
                ],
            ),
            story(
                ("2", 0.4),
                vec![
                    episode("sliding ball", "cue", 0.6, 0.9),
                    pair("high angle collision", "2", 0.4),
                    pocket("2", 1.0),
                ],
            ),
        ),
        (
            "curve-cushion-pot-6",
            story(
                ("6", 0.5),
                vec![curve(0.1), cushion("6", 0.8), pocket("6", 1.4)],
            ),
            story(
                ("6", 0.5),
                vec![curve(0.1), cushion("6", 1.5), pocket("6", 1.4)],
            ),
        ),
        (
            "cut-pot-7-no-cushion",
            story(
                ("7", 0.5),
                vec![pair("high angle collision", "7", 0.5), pocket("7", 1.0)],
            ),
            story(
                ("7", 0.5),
                vec![
                    pair("high angle collision", "7", 0.5),
                    cushion("7", 0.8),
                    pocket("7", 1.0),
                ],
            ),
        ),
        (
            "cushion-cut-3",
            story(
                ("3", 0.9),
                vec![
                    episode("sliding ball", "cue", 0.0, 0.3),
                    cushion("cue", 0.4),
                    pair("high angle collision", "3", 0.9),
                ],
            ),
            story(
                ("3", 0.3),
                vec![
                    episode("sliding ball", "cue", 0.0, 0.3),
                    cushion("cue", 0.4),
                    pair("high angle collision", "3", 0.3),
                ],
            ),
        ),
        (
            "touch-2-cushion",
            story(
                ("2", 0.5),
                vec![pair("gentle touch", "2", 0.5), cushion("2", 1.1)],
            ),
            story(
                ("2", 0.5),
                vec![pair("gentle touch", "2", 0.5), cushion("2", 0.2)],
            ),
        ),
        (
            "spin-cut-6-curve",
            story(
                ("6", 0.5),
                vec![
                    episode("spinning ball", "cue", 0.8, 1.0),
                    pair("high angle collision", "6", 0.5),
                    ann("ball curves around ball", 0.7, 1.0, &["6", "5"], json!({})),
                ],
            ),
            story(
                ("6", 0.5),
                vec![
                    episode("spinning ball", "cue", 0.8, 1.0),
                    pair("high angle collision", "6", 0.5),
                    ann("ball curves around ball", 0.1, 0.3, &["6", "5"], json!({})),
                ],
            ),
        ),
        (
            "two-cushions-pot-8",
            story(
                ("8", 0.9),
                vec![cushion("cue", 0.3), cushion("cue", 0.6), pocket("8", 1.5)],
            ),
            story(
                ("8", 0.5),
                vec![cushion("cue", 0.3), cushion("cue", 0.6), pocket("8", 1.5)],
            ),
        ),
    ];
    assert_eq!(cases.len(), goals().goals.len());
    for (id, yes, no) in &cases {
        let e = goal_on(id, yes);
        assert!(
            e.success,
            "{id}: the acted-out sentence fails: {:?}",
            e.clauses
        );
        close(e.score, 1.0);
        let e = goal_on(id, no);
        assert!(!e.success, "{id}: the wrong order succeeds");
        assert!(
            e.score > 0.0 && e.score < 1.0,
            "{id}: partial credit {}",
            e.score
        );
    }
}

#[test]
fn goal_files_load_and_check() {
    let set = goals();
    assert_eq!(set.goals.len(), 10);
    for g in &set.goals {
        assert!(g.source.as_deref().unwrap_or("").contains("appendix G"));
    }
    for f in ["phyre.toml", "iphyre.toml"] {
        let s = GoalSet::load(&repo().join("data/goals").join(f), &repo()).unwrap();
        assert!(s.goals.len() >= 3, "{f}");
    }
}

#[test]
fn verification_rules_read_simulator_events() {
    let mut tr = trace();
    let phys = |kind: &str, t: f64, agents: Value| {
        let mut p = json!({"agents": agents.clone()});
        if let Some(b) = agents.get(0) {
            p["ball"] = b.clone();
        }
        event(kind, t, p)
    };
    tr.events = vec![
        phys("physics_ball_linear_cushion", 0.3, json!(["cue", "12"])),
        phys("physics_ball_linear_cushion", 0.31, json!(["cue", "12"])),
        phys("physics_ball_circular_cushion", 0.6, json!(["cue", "8t"])),
        phys("physics_ball_ball", 0.9, json!(["cue", "8"])),
        phys("physics_ball_pocket", 1.5, json!(["8", "lb"])),
    ];
    let holds = |r: &str| Rule::parse(r).unwrap().holds(&tr).unwrap();
    assert!(holds(
        r#"SEQ(CUSHION("cue"), CUSHION("cue"), FIRST_HIT("8"), POCKET("8"))"#
    ));
    assert!(
        !holds(r#"SEQ(CUSHION("cue"), CUSHION("cue"), CUSHION("cue"), FIRST_HIT("8"))"#),
        "a 10 ms burst is one rebound"
    );
    assert!(!holds(r#"SEQ(FIRST_HIT("8"), CUSHION("cue"))"#));
    assert!(holds(r#"POCKET("8", "lb")"#));
    assert!(!holds(r#"POCKET("8", "rt")"#));
    assert!(holds(
        r#"ALL(NONE(CUSHION("8")), AT_LEAST(CUSHION("cue"), 2), NOT(FIRST_HIT("3")))"#
    ));
    assert!(holds(r#"ANY(FIRST_HIT("3"), HIT("cue", "*"))"#));
    let e = Rule::parse(r#"SEQ(BOUNCE("cue"))"#).unwrap_err();
    assert_eq!(e.category, ErrorCategory::UnknownFunction);
    assert_eq!(e.pos.col, 5);
    let e = Rule::parse(r#"CONTACT("a", "b")"#)
        .unwrap()
        .holds(&tr)
        .unwrap_err();
    assert_eq!(e.category, ErrorCategory::Runtime);
}

#[test]
fn malformed_programs_give_category_and_position() {
    let s = schema();
    let cases: &[(&str, ErrorCategory, u32, u32)] = &[
        (
            "AND(PATTERN(\"cue strike\"),\n     PATTERN(\"cue strike\"",
            ErrorCategory::Syntax,
            2,
            26,
        ),
        (
            "AND(PATTERN(\"cue strike\") PATTERN(\"x\"))",
            ErrorCategory::Syntax,
            1,
            27,
        ),
        ("PATTERN('cue strike)", ErrorCategory::Syntax, 1, 9),
        (
            "AND(\n  PATTERNS(\"cue strike\"))",
            ErrorCategory::UnknownFunction,
            2,
            3,
        ),
        (
            "NOT(PATTERN(\"cue strike\"), PATTERN(\"cue strike\"))",
            ErrorCategory::Arity,
            1,
            28,
        ),
        ("AFTER(\"cue strike\")", ErrorCategory::Arity, 1, 1),
        (
            "PATTERN(\"cue strike\", frame=3, frame=4)",
            ErrorCategory::Arity,
            1,
            32,
        ),
        (
            "AFTER(\"cue strike\", \"ball collision\", lag=1)",
            ErrorCategory::Arity,
            1,
            39,
        ),
        ("PATTERN(3)", ErrorCategory::ArgumentType, 1, 9),
        (
            "AFTER(NOT(PATTERN(\"cue strike\")), \"cue strike\")",
            ErrorCategory::ArgumentType,
            1,
            7,
        ),
        (
            "NEARBY_AT(\"cue\", 0.5, 0.5, 2.0)",
            ErrorCategory::ArgumentType,
            1,
            28,
        ),
        (
            "COUNT(\"cue strike\", \"two\")",
            ErrorCategory::ArgumentType,
            1,
            21,
        ),
        (
            "AND(PATTERN(\"double kiss\"))",
            ErrorCategory::UnknownLabel,
            1,
            13,
        ),
        (
            "AFTER(\"cue strike\", \"jump shot\")",
            ErrorCategory::UnknownLabel,
            1,
            21,
        ),
        (
            "PATTERN(\"ball pocketed\", {\"object_a\": \"9\"})",
            ErrorCategory::UnknownParameter,
            1,
            27,
        ),
        (
            "PATTERN(\"ball pocketed\", hole=\"rt\")",
            ErrorCategory::UnknownParameter,
            1,
            26,
        ),
    ];
    for (text, cat, line, col) in cases {
        let e = compile(text, &s).expect_err(text);
        assert_eq!(
            (e.category, e.pos.line, e.pos.col),
            (*cat, *line, *col),
            "{text}: {e}"
        );
    }
    let mut phyre = s.clone();
    phyre.env = Env::Phyre;
    let e = compile(r#"CUE_HIT("8")"#, &phyre).unwrap_err();
    assert_eq!(e.category, ErrorCategory::UnknownFunction);
}

#[test]
fn no_input_makes_the_compiler_panic() {
    let s = schema();
    let alphabet: Vec<char> = "AND(PATTERN\"cue strike\",)=[]{}:0.5-e#\n AFTER'\\x"
        .chars()
        .collect();
    let mut state = 0x1234_5678_9abc_def0_u64;
    for _ in 0..3000 {
        let mut text = String::new();
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        for k in 0..(state % 60) {
            let r = state
                .rotate_left(k as u32 * 7)
                .wrapping_mul(0x9E37_79B9_7F4A_7C15);
            text.push(alphabet[(r >> 33) as usize % alphabet.len()]);
        }
        let _ = compile(&text, &s);
        let _ = Rule::parse(&text);
    }
}

#[test]
fn cli_check_reports_errors_with_a_caret_and_exit_2() {
    let t = TestRun::new();
    t.run(&[
        "reward",
        "check",
        "--no-probe",
        r#"AND(PATTERN("cue strike"), CUE_HIT("8"))"#,
    ])
    .ok()
    .stdout_has("ok: pooltool program");
    t.run(&[
        "reward",
        "check",
        "--no-probe",
        "AND(PATTERN(\"cue strike\"),\n  PATTERN(\"jump\"))",
    ])
    .code(2)
    .stderr_has("line 2, column 11: unknown_label error")
    .stderr_has("  |           ^");
}

#[test]
fn cli_eval_prints_clauses_and_score() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--env", "pooltool", "--scenes", "1", "--shots", "1", "--seed", "3", "--run",
        "r",
    ])
    .ok();
    let id = t.csv("r", "SELECT trace_id FROM traces LIMIT 1");
    let id = id.lines().nth(1).unwrap().trim().to_string();
    let r = t.run(&[
        "reward",
        "eval",
        "--run",
        "r",
        "--trace",
        &id,
        r#"AND(PATTERN("cue strike", ball="cue"), CUE_HIT("cue"), NEARBY_AT("cue", 0.0, 0.0, 1.0))"#,
    ]);
    r.ok()
        .stdout_has("clause  1  true   1.000  PATTERN(\"cue strike\", ball=\"cue\")")
        .stdout_has("clause  2  false  0.000")
        .stdout_has("success: false")
        .stdout_has("score: 0.");
}

/// `eval` on a trace of an annotated run: its own annotations from the table, the parameter keys from
/// every trace's, so a key seen only on another trace is known and an unknown one is an error.
#[test]
fn cli_eval_learns_parameter_keys_from_the_whole_run() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--scenes", "6", "--seed", "5", "--dt", "0.05", "--run", "r", "-q",
    ])
    .ok();
    t.run(&["annotate", "--run", "r", "-q"]).ok();
    let pocketed = |op: &str| {
        let csv = t.csv(
            "r",
            &format!(
                "SELECT trace_id FROM traces WHERE trace_id {op} \
                 (SELECT trace_id FROM annotations WHERE label = 'ball pocketed') ORDER BY trace_id"
            ),
        );
        csv.lines().nth(1).expect("such a trace").to_string()
    };
    // A shot that pocketed nothing: `pocket` is learned from the shots that did.
    let (none, some) = (pocketed("NOT IN"), pocketed("IN"));
    assert_ne!(none, some);
    let eval = |program: &str| t.run(&["reward", "eval", "--run", "r", "--trace", &none, program]);
    eval(r#"AND(PATTERN("cue strike"), PATTERN("ball pocketed", pocket="lb"))"#)
        .ok()
        .stdout_has("annotations from the run's annotations table")
        .stdout_has("clause  1  true   1.000  PATTERN(\"cue strike\")")
        .stdout_has("success: false");
    eval(r#"PATTERN("ball pocketed", nonsense=1)"#)
        .code(2)
        .stderr_has(
            "patterns of \"ball pocketed\" have no parameter `nonsense` (they have: pocket",
        );
}

mod synthesis {
    use annotrace::llm::{LlmClient, LlmConfig, read_calls};
    use annotrace::reward::synth::{SynthRequest, synthesise};
    use annotrace::store::RunDir;

    use super::*;
    use crate::common::chat_server::{ChatServer, Reply};

    fn dsl(p: &str) -> String {
        format!("<think>Plan the steps.</think>\n```dsl\n{p}\n```")
    }

    #[test]
    fn repairs_parse_check_and_execution_errors_with_the_interpreter_message() {
        let server = ChatServer::start(vec![
            Reply::chat(&dsl(r#"AND(PATTERN("cue strike"), CUE_HIT("8")"#)),
            Reply::chat(&dsl(r#"AND(PATTERN("jump shot"), CUE_HIT("8"))"#)),
            Reply::chat(&dsl(
                r#"AND(PATTERN("cue strike"), CUE_HIT(OBJECT_ID("pink", "ball")))"#,
            )),
            Reply::chat(&dsl(r#"AND(PATTERN("cue strike"), CUE_HIT("8"))"#)),
        ]);
        let client = LlmClient::new(LlmConfig::new(server.url(), "m"), None).unwrap();
        let (tr, anns) = basic();
        let sch = schema();
        let req = SynthRequest {
            examples: Vec::new(),
            goal: "Hit the eight ball first.",
            schema: &sch,
            scene_summary: "nine balls".into(),
            image: None,
            probe: Some((&tr, &anns)),
            max_repairs: 3,
            seed: 5,
            temperature: None,
        };
        let out = synthesise(&client, &req).unwrap();
        let p = out.program.expect("the fourth answer is valid");
        assert_eq!(p.source, r#"AND(PATTERN("cue strike"), CUE_HIT("8"))"#);
        let purposes: Vec<&str> = out.attempts.iter().map(|a| a.purpose.as_str()).collect();
        assert_eq!(
            purposes,
            [
                "reward_synthesis",
                "reward_repair",
                "reward_repair",
                "reward_repair"
            ]
        );
        let seen = server.seen();
        assert_eq!(seen.len(), 4);
        let first = seen[0].last_message();
        assert!(first.contains("Goal: Hit the eight ball first."));
        assert!(first.contains("\"high angle collision\"") && first.contains("AFTER(Y, X)"));
        assert!(
            seen[1].last_message().contains("syntax error"),
            "{}",
            seen[1].last_message()
        );
        assert!(seen[2].last_message().contains("unknown_label error"));
        assert!(seen[3].last_message().contains("runtime error: OBJECT_ID"));
        // The conversation grows: the model sees its own earlier answer before each repair request.
        assert_eq!(
            seen[3].body["messages"].as_array().unwrap().len(),
            2 + 2 * 3
        );
    }

    #[test]
    fn gives_up_after_the_retry_limit() {
        let server = ChatServer::start(vec![
            Reply::chat("I would rather not."),
            Reply::chat(&dsl("PATTERN(\"nope\")")),
        ]);
        let client = LlmClient::new(LlmConfig::new(server.url(), "m"), None).unwrap();
        let sch = schema();
        let req = SynthRequest {
            examples: Vec::new(),
            goal: "g",
            schema: &sch,
            scene_summary: String::new(),
            image: None,
            probe: None,
            max_repairs: 1,
            seed: 0,
            temperature: Some(0.2),
        };
        let out = synthesise(&client, &req).unwrap();
        assert!(out.program.is_none());
        assert_eq!(out.attempts.len(), 2);
        assert!(
            out.attempts[0]
                .error
                .as_deref()
                .unwrap()
                .contains("no program")
        );
        assert!(
            out.attempts[1]
                .error
                .as_deref()
                .unwrap()
                .contains("unknown_label")
        );
        assert_eq!(server.remaining(), 0);
    }

    #[test]
    fn cli_synthesise_records_every_call() {
        let server = ChatServer::start(vec![
            Reply::chat(&dsl(
                r#"AND(PATTERN("cushion rebound", ball="cue"), AFTER(CUE_HIT("8"), "cushion rebound"), PATTERN("ball pocketed", ball="8", hole="rt"))"#,
            )),
            Reply::chat(&dsl(
                r#"AND(PATTERN("cushion rebound", ball="cue"), AFTER(CUE_HIT("8"), "cushion rebound"), PATTERN("ball pocketed", ball="8", pocket="rt"))"#,
            )),
        ]);
        let t = TestRun::new();
        let mut c = t.cmd();
        for k in [
            "ANNOTRACE_LLM_BASE_URL",
            "ANNOTRACE_LLM_MODEL",
            "ANNOTRACE_LLM_API_KEY",
            "ANNOTRACE_PROMPTS",
        ] {
            c.env_remove(k);
        }
        let out = c
            .env("ANNOTRACE_LLM_BASE_URL", server.url())
            .env("ANNOTRACE_LLM_MODEL", "m")
            .args([
                "reward",
                "synthesise",
                "Bounce the cue ball off a cushion, then pot the eight ball in the top-right pocket.",
                "--scene",
                "1000:3",
                "--run",
                "run",
                "--out",
                "prog.dsl",
                "--image",
            ])
            .output()
            .unwrap();
        let ran: crate::common::Ran = out.into();
        ran.ok()
            .stdout_has("pocket=\"rt\"")
            .stderr_has("unknown_parameter");
        assert!(
            std::fs::read_to_string(t.path("prog.dsl"))
                .unwrap()
                .contains("pocket=\"rt\"")
        );
        let calls = read_calls(&RunDir::new(t.path("run"))).unwrap();
        let purposes: Vec<&str> = calls.iter().map(|c| c.purpose.as_str()).collect();
        assert_eq!(purposes, ["reward_synthesis", "reward_repair"]);
        let first = &server.seen()[0];
        let text = first.body["messages"][1].to_string();
        assert!(
            text.contains("image_url"),
            "the scene image is attached: {}",
            &text[..200.min(text.len())]
        );
        assert!(text.contains("Balls at rest") && text.contains("top-right pocket"));
    }
}

/// An I-PHYRE story for the object-set functions: 0 gray block (100,300)-(150,300), 1 blue block
/// (100,200)-(150,200), 2 black block (100,500)-(300,500), balls 3 and 4 (radius 10). Ball 3 sits at
/// (280, 478) throughout (2 px above the black block's surface, 83 px from its centre); ball 4 starts
/// at (400, 300) and reaches (322, 478) at the last step (2 px from ball 3).
fn iphyre_story() -> (Trace, Schema) {
    use annotrace::trace::Body;
    let mut t = synthetic_trace(Env::Iphyre, 0, 4, 5);
    t.trace_id = "story".into();
    t.events.clear();
    let last = t.timesteps.len() - 1;
    for (s, ts) in t.timesteps.iter_mut().enumerate() {
        for (k, o) in ts.objects.iter_mut().enumerate() {
            let Body::Iphyre(b) = &mut o.body else {
                unreachable!()
            };
            b.index = k as i64;
            b.radius = 10.0;
            b.eliminable = if k == 0 { 1.0 } else { 0.0 };
            b.dynamic = if k == 1 || k >= 3 { 1.0 } else { 0.0 };
            let (x1, y1, x2, y2) = match k {
                0 => (100.0, 300.0, 150.0, 300.0),
                1 => (100.0, 200.0, 150.0, 200.0),
                2 => (100.0, 500.0, 300.0, 500.0),
                3 => (280.0, 478.0, 280.0, 478.0),
                _ if s == last => (302.0, 478.0, 302.0, 478.0),
                _ => (400.0, 300.0, 400.0, 300.0),
            };
            (b.x1, b.y1, b.x2, b.y2) = (x1, y1, x2, y2);
        }
    }
    let lib = Library::load(&repo().join("data/libraries/iphyre")).unwrap();
    (t, Schema::from_library(&lib))
}

/// `NEAR` grades the closest approach of two objects' outlines (capsules, not centres), and an
/// `OBJECT_ID` in `NEAR`, `ball=` and `contains=` stands for every object of its colour and shape
/// (PHYRE / I-PHYRE), with shape "object" matching any shape and colours listing alternatives. Two
/// references in `contains=` need two different objects.
#[test]
fn near_and_object_sets_in_iphyre() {
    let (tr, schema) = iphyre_story();
    let eval = |p: &str, anns: &[Annotation]| {
        let p = compile(p, &schema).unwrap_or_else(|e| panic!("{p}: {e}"));
        evaluate(&p, &AnnotatedTrace::new(&tr, anns))
    };
    const BALL: &str = r#"OBJECT_ID("red", "ball")"#;
    // Ball 3 is 2 px above the black block's surface although 83 px from its centre.
    let e = eval(
        &format!(r#"NEAR({BALL}, OBJECT_ID("black", "block"), threshold_strength=0.01)"#),
        &[],
    )
    .unwrap();
    assert!(e.success, "{e:?}");
    // The two balls come within 2 px (at the last step): within 6 px, not within 0.6 px.
    assert!(
        eval(
            &format!("NEAR({BALL}, {BALL}, threshold_strength=0.01)"),
            &[]
        )
        .unwrap()
        .success
    );
    let tight = eval(
        &format!("NEAR({BALL}, {BALL}, threshold_strength=0.001)"),
        &[],
    )
    .unwrap();
    assert!(!tight.success);
    close(tight.score, shape(2.0 / 0.6 - 1.0));
    // Far objects score less, but above 0.
    let far = eval(
        &format!(r#"NEAR({BALL}, OBJECT_ID("blue", "block"), threshold_strength=0.01)"#),
        &[],
    )
    .unwrap();
    assert!(far.score > 0.0 && far.score < tight.score, "{far:?}");
    // One gray block never meets another: 0, not an error; a colour the scene lacks is an error.
    let alone = eval(
        r#"NEAR(OBJECT_ID("gray", "block"), OBJECT_ID("gray", "object"))"#,
        &[],
    )
    .unwrap();
    assert_eq!((alone.success, alone.score), (false, 0.0));
    let e = eval(
        &format!(r#"NEAR({BALL}, OBJECT_ID("green", "block"))"#),
        &[],
    )
    .unwrap_err();
    assert_eq!(e.category, ErrorCategory::Runtime);
    // Sets in filters: the second ball is "a ball"; a collision of two balls has two.
    let fall = [ann("falling object", 0.0, 0.02, &["4"], json!({}))];
    assert!(
        eval(&format!(r#"PATTERN("falling object", ball={BALL})"#), &fall)
            .unwrap()
            .success
    );
    let balls = format!(r#"PATTERN("collision", contains=[{BALL}, {BALL}])"#);
    let ball_block = [ann("collision", 0.01, 0.01, &["3", "1"], json!({}))];
    let ball_ball = [ann("collision", 0.01, 0.01, &["4", "3"], json!({}))];
    assert!(!eval(&balls, &ball_block).unwrap().success);
    assert!(eval(&balls, &ball_ball).unwrap().success);
    let blue_or_gray = r#"PATTERN("collision", contains=[OBJECT_ID("blue|gray", "object")])"#;
    assert!(eval(blue_or_gray, &ball_block).unwrap().success);
    assert!(!eval(blue_or_gray, &ball_ball).unwrap().success);
}

/// The I-PHYRE goal programs on the annotated stories that fooled their first drafts in the small
/// optimisation runs of session 9 (each first draft, quoted, scored 1 where its rule failed), and on
/// a story where the goal holds. Objects as in `iphyre_story`: 0 gray, 1 blue, 2 black blocks, balls
/// 3 and 4.
#[test]
fn iphyre_goal_programs_reject_what_fooled_their_first_drafts() {
    let (tr, _) = iphyre_story();
    let set = GoalSet::load(&repo().join("data/goals/iphyre.toml"), &repo()).unwrap();
    let score = |program: &str, anns: &[Annotation]| {
        let mut sch = set.schema.clone();
        sch.learn_keys(anns);
        let p = compile(program, &sch).unwrap_or_else(|e| panic!("{program}: {e}"));
        evaluate(&p, &AnnotatedTrace::new(&tr, anns)).unwrap().score
    };
    let removal = ann("object removal", 0.0, 0.0, &["0", "3"], json!({"t": 0.0}));
    let fall = |o: &str, out: bool| {
        ann(
            "falling object",
            0.01,
            0.02,
            &[o],
            json!({"drop_px": 40.0, "leaves_screen": out}),
        )
    };
    let collision =
        |a: &str, b: &str| ann("collision", 0.01, 0.01, &[a, b], json!({"contacts": 1}));
    let airborne = ann("airborne motion", 0.01, 0.02, &["3"], json!({}));
    // (goal, the first draft, the story that fooled it, a story where the goal holds)
    let cases: Vec<(&str, &str, Vec<Annotation>, Vec<Annotation>)> = vec![
        (
            // The seesaw plank (blue block 1) falls after the removal; the ball stays on screen.
            "remove-then-fall",
            r#"AND(PATTERN("object removal"), PATTERN("falling object"), AFTER(PATTERN("falling object"), PATTERN("object removal")))"#,
            vec![removal.clone(), fall("1", false), fall("3", false)],
            vec![removal.clone(), fall("3", true)],
        ),
        (
            // Two collisions, each of a ball with a block.
            "two-balls-collide",
            r#"AND(PATTERN("falling object"), PATTERN("collision"), GT("collision", 1))"#,
            vec![
                removal.clone(),
                fall("3", false),
                collision("3", "2"),
                collision("4", "2"),
            ],
            vec![removal.clone(), collision("4", "3")],
        ),
        (
            // A ball leaves the screen after touching the other ball once.
            "exit-alone",
            r#"AND(PATTERN("object removal"), PATTERN("airborne motion"), PATTERN("falling object"), LT("collision", 2))"#,
            vec![
                removal.clone(),
                airborne.clone(),
                fall("3", true),
                collision("3", "4"),
            ],
            vec![removal.clone(), fall("3", true), collision("3", "2")],
        ),
        (
            // A ball hits the black block after the removal.
            "ball-hits-blue",
            r#"AND(PATTERN("object removal"), PATTERN("collision"), AFTER(PATTERN("collision"), PATTERN("object removal")))"#,
            vec![removal.clone(), collision("3", "2")],
            vec![removal.clone(), collision("4", "1")],
        ),
    ];
    for (goal, draft, fooled, holds) in cases {
        let program = &set.get(goal).unwrap().program;
        close(score(draft, &fooled), 1.0);
        assert!(score(program, &fooled) < 1.0, "{goal}: fooled again");
        assert!(score(program, &holds) > score(program, &fooled), "{goal}");
        // ball-hits-blue's NEAR also needs a ball near the blue block, which this story has not.
        if goal != "ball-hits-blue" {
            close(score(program, &holds), 1.0);
        }
    }
}
