//! Optimisation: annealing improves a dense reward on a seeded billiards case and is deterministic;
//! the optimise stage writes its table, figure and summary through a small pipeline.

use annotrace::detect::{Library, SandboxLimits, WorkerPool};
use annotrace::envs::Environment;
use annotrace::envs::pool::PoolEnv;
use annotrace::optimise::{
    Chain, GoalTask, PoolProblem, RewardKind, Schedule, Settings, ShotBounds, run_chains,
};
use annotrace::reward::annotate::detectors_for;
use annotrace::reward::verify::Rule;
use annotrace::reward::{Schema, compile, labels_used};

use crate::common::{TestRun, repo};

fn settings() -> Settings<PoolProblem> {
    let mut env = PoolEnv::default();
    env.trace.dt = 0.05;
    Settings {
        problem: PoolProblem::new(env, ShotBounds::default()).unwrap(),
        schedule: Schedule::default(),
        checkpoint: Some(10),
    }
}

#[test]
fn annealing_improves_a_dense_reward_and_is_seeded() {
    let lib = Library::load(&repo().join("data/libraries/pooltool")).unwrap();
    let schema = Schema::from_library(&lib);
    // Put the cue ball near a spot of the table at the end, after a cushion rebound.
    let program = compile(
        r#"AND(NEARBY_AT("cue", 0.3, 1.6, 1.0, threshold_strength=0.03), PATTERN("cushion rebound", ball="cue"))"#,
        &schema,
    )
    .unwrap();
    let task = GoalTask {
        id: "toy".into(),
        detectors: detectors_for(&lib, &labels_used(&program)),
        program,
        rule: Rule::parse(r#"CUSHION("cue")"#).unwrap(),
    };
    assert_eq!(task.detectors.len(), 1);
    let env = PoolEnv::default();
    let scene = env.scenes(1, 5).unwrap().remove(0);
    let chains: Vec<Chain<_>> = [11, 12]
        .iter()
        .map(|&seed| Chain {
            goal: 0,
            scene: scene.clone(),
            seed,
            kind: RewardKind::Dense,
            budget: 80,
        })
        .collect();
    let limits = SandboxLimits {
        workers: 2,
        ..SandboxLimits::default()
    };
    let pool = WorkerPool::new(limits).unwrap();
    let s = settings();
    let mut steps = 0;
    let (rows, timings) = run_chains(&s, std::slice::from_ref(&task), &chains, Some(&pool), |k| {
        steps = k
    })
    .unwrap();
    assert_eq!(steps, 80);
    assert_eq!(rows.len(), 2 * 8);
    assert_eq!(timings.samples, 160);
    assert_eq!(timings.dense_samples, 160);
    for seed in [11, 12] {
        let curve: Vec<f64> = rows
            .iter()
            .filter(|r| r.seed == seed)
            .map(|r| r.best_reward)
            .collect();
        assert!(
            curve.windows(2).all(|w| w[1] >= w[0]),
            "best-so-far never drops"
        );
        // The first sample is a uniform random shot; annealing must beat it.
        let first = rows.iter().find(|r| r.seed == seed).unwrap();
        let last = rows.iter().rev().find(|r| r.seed == seed).unwrap();
        assert!(last.best_reward > 0.6, "seed {seed}: {curve:?}");
        assert!(
            last.best_reward > first.best_reward || first.best_sample > 1,
            "seed {seed}: no improvement {curve:?}"
        );
    }
    // Same seeds, same rows.
    let (again, _) = run_chains(
        &s,
        std::slice::from_ref(&task),
        &chains,
        Some(&pool),
        |_| {},
    )
    .unwrap();
    assert_eq!(rows, again);
}

#[test]
fn sparse_chains_need_no_detectors() {
    let lib = Library::load(&repo().join("data/libraries/pooltool")).unwrap();
    let program = compile(r#"PATTERN("cue strike")"#, &Schema::from_library(&lib)).unwrap();
    let task = GoalTask {
        id: "any-cushion".into(),
        detectors: Vec::new(),
        program,
        rule: Rule::parse(r#"CUSHION("cue")"#).unwrap(),
    };
    let scene = PoolEnv::default().scenes(1, 9).unwrap().remove(0);
    let chain = Chain {
        goal: 0,
        scene,
        seed: 3,
        kind: RewardKind::Sparse,
        budget: 30,
    };
    let (rows, t) = run_chains(&settings(), &[task], &[chain], None, |_| {}).unwrap();
    assert_eq!(t.dense_samples, 0);
    // A cue-ball cushion contact is easy: the sparse chain finds one, and its success is verified.
    let last = rows.last().unwrap();
    assert_eq!(last.best_reward, 1.0);
    assert!(last.success);
}

#[test]
fn optimise_pipeline_writes_table_figure_and_summary() {
    let t = TestRun::new();
    let text =
        std::fs::read_to_string(repo().join("pipelines/optimisation-pooltool.toml")).unwrap();
    let text = text
        .replace("seeds = 2 ", "seeds = 1 ")
        .replace("budget = 100 ", "budget = 10 ")
        .replace(
            "checkpoint = 50",
            "checkpoint = 5\ngoal_ids = [\"two-cushions-pot-8\", \"touch-2-cushion\"]\nworkers = 2",
        );
    t.write("pipelines/opt.toml", &text);
    std::fs::create_dir_all(t.path("sql")).unwrap();
    for f in ["optimisation_summary.sql", "optimisation_by_goal.sql"] {
        std::fs::copy(repo().join("sql").join(f), t.path("sql").join(f)).unwrap();
    }
    t.run(&["run", "pipelines/opt.toml", "--run-dir", "out"])
        .ok();
    let csv = t.csv(
        "out",
        "SELECT goal, reward_type, budget, count(*) AS n FROM optimisation GROUP BY goal, reward_type, budget ORDER BY goal, reward_type, budget",
    );
    assert_eq!(csv.lines().count(), 1 + 2 * 2 * 2, "{csv}");
    assert!(csv.contains("touch-2-cushion,sparse,10,1"), "{csv}");
    let summary = t.csv(
        "out",
        "SELECT reward_type, budget, seeds FROM optimisation_summary ORDER BY 1, 2",
    );
    assert!(
        summary.contains("dense,5,1") && summary.contains("sparse,10,1"),
        "{summary}"
    );
    let svg =
        std::fs::read_to_string(t.path("out/exports/optimise/success_vs_budget.svg")).unwrap();
    assert!(svg.contains("dense") && svg.contains("sparse") && svg.contains("success rate"));
    let png = std::fs::read(t.path("out/exports/optimise/success_vs_budget.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert!(t.path("out/exports/optimisation_summary.tex").is_file());
    // Nothing changed: everything is cached.
    t.run(&["run", "pipelines/opt.toml", "--run-dir", "out"])
        .ok()
        .stderr_has("0 stage(s) ran");
}

#[test]
fn optimise_rejects_bad_parameters() {
    let t = TestRun::new();
    t.write(
        "p.toml",
        "[pipeline]\nname = \"x\"\n[[stage]]\nid = \"o\"\nkind = \"optimise\"\ngoal_ids = [\"nope\"]\n",
    );
    t.run(&["run", "p.toml", "--run-dir", "out"])
        .code(2)
        .stderr_has("no goal \"nope\"");
    t.write(
        "q.toml",
        "[pipeline]\nname = \"x\"\n[[stage]]\nid = \"o\"\nkind = \"optimise\"\nrewards = [\"dense\", \"medium\"]\n",
    );
    t.run(&["run", "q.toml", "--run-dir", "out"])
        .code(2)
        .stderr_has(
            "q.toml:6: stage \"o\": `rewards[1]` must be one of \"dense\", \"sparse\", found \"medium\"",
        );
}

/// Synthesis → optimise for one goal per environment through the scripted chat server: the first
/// answer names a label the library lacks and is repaired, the second is accepted, recorded in
/// reward_programs and optimised.
#[test]
fn synthesised_programs_are_repaired_and_optimised_in_every_environment() {
    use crate::common::chat_server::{ChatServer, Reply};
    let dsl = |p: &str| format!("<think>Plan the steps.</think>\n```dsl\n{p}\n```");
    for (env, goal, good) in [
        (
            "pooltool",
            "touch-2-cushion",
            r#"AND(PATTERN("cushion rebound", ball="cue"), CUE_HIT("2"))"#,
        ),
        (
            "phyre",
            "red-touches-green",
            r#"AND(PATTERN("falling object"), PATTERN("moving object hits stationary object"))"#,
        ),
        (
            "iphyre",
            "ball-hits-blue",
            r#"AND(PATTERN("object removal"), PATTERN("collision"))"#,
        ),
    ] {
        let server = ChatServer::start(vec![
            Reply::chat(&dsl(r#"AND(PATTERN("teleporting ball"))"#)),
            Reply::chat(&dsl(good)),
        ]);
        let t = TestRun::new();
        t.write(
            "p.toml",
            &format!(
                "[pipeline]\nname = \"s\"\nseed = 3\n\
                 [[stage]]\nid = \"synth\"\nkind = \"synthesise\"\nenv = \"{env}\"\ngoal_ids = [\"{goal}\"]\n\
                 workers = 2\nllm = {{ base_url = \"{}\", model = \"m\" }}\n\
                 [[stage]]\nid = \"optimise\"\nkind = \"optimise\"\ninputs = [\"synth\"]\nenv = \"{env}\"\n\
                 scenes = 1\nseeds = 1\nbudget = 4\ncheckpoint = 2\nworkers = 2\nframes = 2\n",
                server.url()
            ),
        );
        t.run_env(
            &["run", "p.toml", "--run-dir", "out"],
            &[("ANNOTRACE_LLM_BASE_URL", ""), ("ANNOTRACE_LLM_MODEL", "m")],
        )
        .ok();
        let programs = t.csv(
            "out",
            "SELECT goal, origin, accepted, attempts, errors, program FROM reward_programs",
        );
        assert!(
            programs.contains(&format!("{goal},llm,true,2,")),
            "{env}: {programs}"
        );
        assert!(programs.contains("teleporting ball"), "{env}: {programs}");
        let rows = t.csv(
            "out",
            "SELECT reward_type, budget, count(*) AS n FROM optimisation GROUP BY 1, 2 ORDER BY 1, 2",
        );
        assert_eq!(
            rows.lines().skip(1).collect::<Vec<_>>(),
            ["dense,2,1", "dense,4,1", "sparse,2,1", "sparse,4,1"],
            "{env}"
        );
        assert_eq!(server.seen().len(), 2, "{env}: one synthesis, one repair");
        let svg =
            std::fs::read_to_string(t.path(&format!("out/exports/optimise/action_{goal}.svg")))
                .unwrap();
        assert!(
            svg.contains("data:image/png;base64,") && svg.contains("PATTERN(&quot;"),
            "{env}"
        );
    }
}

/// Annealing the PHYRE red ball and the I-PHYRE removal times improves a dense reward on a fixed seed.
#[test]
fn annealing_improves_a_dense_reward_in_phyre_and_iphyre() {
    use annotrace::envs::iphyre::IphyreEnv;
    use annotrace::envs::phyre::{PhyreEnv, TaskSet};
    use annotrace::optimise::{IphyreProblem, PhyreProblem, Problem};
    let pool = WorkerPool::new(SandboxLimits {
        workers: 2,
        ..SandboxLimits::default()
    })
    .unwrap();
    fn run<P: Problem>(
        problem: P,
        scene: P::Scene,
        lib: &str,
        program: &str,
        pool: &WorkerPool,
    ) -> Vec<f64> {
        let lib = Library::load(&repo().join(lib)).unwrap();
        let program = compile(program, &Schema::from_library(&lib)).unwrap();
        let task = GoalTask {
            id: "toy".into(),
            detectors: detectors_for(&lib, &labels_used(&program)),
            program,
            rule: Rule::parse("SUCCESS()").unwrap(),
        };
        let chain = Chain {
            goal: 0,
            scene,
            seed: 7,
            kind: RewardKind::Dense,
            budget: 30,
        };
        let s = Settings {
            problem,
            schedule: Schedule::default(),
            checkpoint: Some(1),
        };
        let (rows, _) = run_chains(&s, &[task], &[chain], Some(pool), |_| {}).unwrap();
        rows.iter().map(|r| r.best_reward).collect()
    }
    // PHYRE: the red ball placed near a spot of the scene.
    let task = TaskSet::default_tasks().unwrap().get("00001:000").unwrap();
    let curve = run(
        PhyreProblem {
            env: PhyreEnv::default(),
        },
        task,
        "data/libraries/phyre",
        r#"NEARBY_AT(OBJECT_ID("red", "ball"), 60.0, 220.0, 0.0, threshold_strength=0.02)"#,
        &pool,
    );
    assert!(curve.windows(2).all(|w| w[1] >= w[0]), "{curve:?}");
    assert!(curve[29] > curve[0] + 0.05, "phyre: {curve:?}");
    // I-PHYRE: a ball where it ends up after the removals, with a detector clause.
    let env = IphyreEnv::new().unwrap();
    let game = env.games.get("support").unwrap().clone();
    let curve = run(
        IphyreProblem {
            env,
            horizon: 5.0,
            never: 0.25,
        },
        game,
        "data/libraries/iphyre",
        r#"AND(PATTERN("falling object"), NEARBY_AT(OBJECT_ID("red", "ball"), 250.0, 470.0, 0.2, threshold_strength=0.02))"#,
        &pool,
    );
    assert!(curve.windows(2).all(|w| w[1] >= w[0]), "{curve:?}");
    assert!(curve[29] > curve[0], "iphyre: {curve:?}");
}

/// A sentence file has no hand-written programs: offline it is a clear input error; asking for the
/// reward_programs table without a synthesise input is refused when the pipeline is checked.
#[test]
fn synthesise_and_optimise_refuse_what_they_cannot_do_offline() {
    let t = TestRun::new();
    t.write(
        "goals.txt",
        "# my goals\nMake the red ball hit the blue object.\n\n",
    );
    t.write(
        "p.toml",
        "[pipeline]\nname = \"x\"\n[[stage]]\nid = \"s\"\nkind = \"synthesise\"\nenv = \"phyre\"\nsentences = \"goals.txt\"\n",
    );
    t.run_env(
        &["run", "p.toml", "--run-dir", "out"],
        &[("ANNOTRACE_LLM_BASE_URL", "")],
    )
    .code(2)
    .stderr_has("goal \"s1\" has no hand-written program");
    t.write(
        "q.toml",
        "[pipeline]\nname = \"x\"\n[[stage]]\nid = \"o\"\nkind = \"optimise\"\nenv = \"iphyre\"\nprograms = \"reward_programs\"\n",
    );
    t.run(&["run", "q.toml", "--run-dir", "out"])
        .code(2)
        .stderr_has("reward_programs needs a synthesise stage among the stage's `inputs`");
    t.write(
        "r.toml",
        "[pipeline]\nname = \"x\"\n[[stage]]\nid = \"o\"\nkind = \"optimise\"\nenv = \"phyre\"\ngoals = \"data/goals/iphyre.toml\"\n",
    );
    t.run(&["run", "r.toml", "--run-dir", "out"])
        .code(2)
        .stderr_has("is for iphyre, but this stage optimises phyre");
}

/// A PHYRE action the environment refuses (`INVALID_INPUT`: the trace has no red ball) scores 0 under
/// both rewards, is counted as an invalid action rather than a program error, and never reaches the
/// detector workers; a program naming the red ball used to raise a runtime error on it.
#[test]
fn an_invalid_phyre_placement_scores_zero_without_a_program_error() {
    use annotrace::envs::EnvError;
    use annotrace::envs::phyre::{PhyreEnv, Task, TaskSet};
    use annotrace::optimise::{Dim, PhyreProblem, Problem, invalid_action};
    use annotrace::trace::{Env, Trace};
    use serde_json::Value;

    /// PHYRE with every point mapped to one action the environment refuses.
    struct Refused(PhyreProblem, [f64; 3]);
    impl Problem for Refused {
        type Scene = Task;
        fn env(&self) -> Env {
            self.0.env()
        }
        fn dims(&self, scene: &Task) -> Vec<Dim> {
            self.0.dims(scene)
        }
        fn simulate(&self, scene: &Task, _x: &[f64]) -> Result<Trace, EnvError> {
            self.0.simulate(scene, &self.1)
        }
        fn scene_id(&self, scene: &Task) -> String {
            self.0.scene_id(scene)
        }
        fn action_json(&self, scene: &Task, x: &[f64]) -> Value {
            self.0.action_json(scene, x)
        }
        fn describe(&self, scene: &Task) -> String {
            self.0.describe(scene)
        }
        fn strip(&self, scene: &Task, trace: &Trace, k: usize) -> Result<Vec<u8>, EnvError> {
            self.0.strip(scene, trace, k)
        }
    }
    let phyre = PhyreProblem {
        env: PhyreEnv::default(),
    };
    let task = TaskSet::default_tasks().unwrap().get("00001:000").unwrap();
    // The largest ball on a grid over the scene, at the first spot where it overlaps an object.
    let refused = (0..=10)
        .flat_map(|i| (0..=10).map(move |j| [i as f64 / 10.0, j as f64 / 10.0, 1.0]))
        .find(|x| invalid_action(&phyre.simulate(&task, x).unwrap()))
        .expect("some placement overlaps an object");
    let problem = Refused(phyre, refused);
    let lib = Library::load(&repo().join("data/libraries/phyre")).unwrap();
    let program = compile(
        r#"NEARBY_AT(OBJECT_ID("red", "ball"), 60.0, 220.0, 0.0)"#,
        &Schema::from_library(&lib),
    )
    .unwrap();
    let goal = GoalTask {
        id: "toy".into(),
        detectors: detectors_for(&lib, &labels_used(&program)),
        program,
        rule: Rule::parse("NOT(SUCCESS())").unwrap(),
    };
    let chains: Vec<Chain<Task>> = [RewardKind::Dense, RewardKind::Sparse]
        .into_iter()
        .map(|kind| Chain {
            goal: 0,
            scene: task.clone(),
            seed: 3,
            kind,
            budget: 4,
        })
        .collect();
    let s = Settings {
        problem,
        schedule: Schedule::default(),
        checkpoint: None,
    };
    let pool = WorkerPool::new(SandboxLimits {
        workers: 1,
        ..SandboxLimits::default()
    })
    .unwrap();
    let (rows, timings) = run_chains(&s, &[goal], &chains, Some(&pool), |_| {}).unwrap();
    assert_eq!(rows.len(), 2);
    for r in &rows {
        // The rule would hold on the refused trace (it is not solved), but nothing is asked of it.
        assert_eq!((r.best_reward, r.success), (0.0, false), "{r:?}");
    }
    assert_eq!(timings.samples, 8);
    assert_eq!(timings.invalid_actions, 8);
    assert_eq!(timings.program_errors, 0);
    assert_eq!(timings.dense_samples, 0);
}

/// The PHYRE and I-PHYRE goal programs name objects with `OBJECT_ID` (the red ball, the green
/// object, the goal object `"blue|purple"`, a blue block, …): on a simulated trace of every PHYRE
/// template and every I-PHYRE game they run without a runtime error, except the blue-block goals in
/// the games without a blue block and the black-block goals in those without a black one (goals the
/// scene cannot reach, reported as program errors).
/// Invalid PHYRE placements never reach a program (see the test above), so no program has to cope
/// with a trace that lacks the red ball.
#[test]
fn goal_programs_find_their_objects_in_every_phyre_template_and_iphyre_game() {
    use annotrace::envs::iphyre::IphyreEnv;
    use annotrace::envs::phyre::{PhyreEnv, TaskSet};
    use annotrace::optimise::{IphyreProblem, PhyreProblem, Problem, invalid_action};
    use annotrace::reward::goals::GoalSet;
    use annotrace::reward::{AnnotatedTrace, ErrorCategory, evaluate};

    let programs = |file: &str| {
        let set = GoalSet::load(&repo().join("data/goals").join(file), &repo()).unwrap();
        set.goals
            .iter()
            .map(|g| (g.id.clone(), compile(&g.program, &set.schema).unwrap()))
            .collect::<Vec<_>>()
    };
    let phyre = PhyreProblem {
        env: PhyreEnv::default(),
    };
    let tasks = TaskSet::default_tasks().unwrap();
    // The first task of each template.
    let mut firsts: Vec<String> = Vec::new();
    for id in tasks.ids() {
        let tpl = id.split(':').next().unwrap();
        if !firsts.iter().any(|t| t.starts_with(tpl)) {
            firsts.push(id.to_string());
        }
    }
    assert_eq!(firsts.len(), 25);
    let goals = programs("phyre.toml");
    for tpl in &firsts {
        let task = tasks.get(tpl).unwrap();
        let trace = (1..10)
            .flat_map(|i| (1..10).map(move |j| [i as f64 / 10.0, j as f64 / 10.0, 0.2]))
            .map(|x| phyre.simulate(&task, &x).unwrap())
            .find(|t| !invalid_action(t))
            .expect("a small ball fits somewhere");
        for (id, p) in &goals {
            evaluate(p, &AnnotatedTrace::new(&trace, &[]))
                .unwrap_or_else(|e| panic!("{tpl}: {id}: {e}"));
        }
    }
    let env = IphyreEnv::new().unwrap();
    let games = env.games.all().to_vec();
    let iphyre = IphyreProblem {
        env,
        horizon: 5.0,
        never: 0.25,
    };
    let goals = programs("iphyre.toml");
    for game in &games {
        let trace = iphyre
            .simulate(game, &vec![0.5; iphyre.dims(game).len()])
            .unwrap();
        let blue = game.blocks().any(|o| o.dynamic);
        let black = game.blocks().any(|o| !o.dynamic && !o.eliminable);
        for (id, p) in &goals {
            let lacks = (!blue && p.source.contains("\"blue\""))
                || (!black && p.source.contains("\"black\""));
            match evaluate(p, &AnnotatedTrace::new(&trace, &[])) {
                Ok(_) => {}
                Err(e) if lacks => {
                    assert_eq!(e.category, ErrorCategory::Runtime, "{}: {id}", game.name)
                }
                Err(e) => panic!("{}: {id}: {e}", game.name),
            }
        }
    }
}

/// A sparse billiards sample is checked on its columns, never built into a `Trace`: every goal rule
/// and the rule functions that read ball states (`CURVE`, `HIT` with `state=` / `min_cut=`,
/// `SUCCESS`) give the same verdict on the columns as on the trace, over random shots of the
/// paper run's scattered scenes (and they hold on some of them, so the comparison is not vacuous).
#[test]
fn billiards_rules_read_the_same_from_columns_as_from_the_trace() {
    use annotrace::optimise::{Layout, scenes};
    use annotrace::reward::goals::GoalSet;

    let set = GoalSet::load(&repo().join("data/goals/pooltool.toml"), &repo()).unwrap();
    let mut rules: Vec<Rule> = set
        .goals
        .iter()
        .map(|g| Rule::parse(&g.verify).unwrap())
        .collect();
    let curve_any = (1..=9)
        .map(|b| format!("CURVE(\"{b}\")"))
        .chain(["CURVE(\"cue\")".to_string()])
        .collect::<Vec<_>>()
        .join(", ");
    let reads_states = [
        format!("ANY({curve_any})"),
        "HIT(\"cue\", \"*\", state=\"sliding\")".to_string(),
        "HIT(\"cue\", \"*\", state=\"rolling\")".to_string(),
        "HIT(\"*\", \"*\", min_cut=25)".to_string(),
        "SEQ(HIT(\"cue\", \"*\", min_cut=10), POCKET(\"*\"))".to_string(),
        "SUCCESS()".to_string(),
    ];
    let first_extra = rules.len();
    rules.extend(reads_states.iter().map(|r| Rule::parse(r).unwrap()));

    let mut env = PoolEnv::default();
    env.trace.dt = 0.02;
    let bounds = ShotBounds::default();
    let scenes = scenes(&env, Layout::Scatter, 12, 1000).unwrap();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut held = vec![0usize; rules.len()];
    for scene in &scenes {
        for _ in 0..25 {
            let x = [
                0.2 + 5.8 * uniform(),
                360.0 * uniform(),
                45.0 * uniform(),
                1.8 * uniform() - 0.9,
                1.8 * uniform() - 0.9,
            ];
            let cols = env.simulate_columns(scene, &bounds.shot(&x)).unwrap();
            let trace = cols.clone().into_trace();
            for (k, rule) in rules.iter().enumerate() {
                let on_trace = rule.holds(&trace).map_err(|e| e.to_string());
                let on_columns = rule.holds_on_columns(&cols).map_err(|e| e.to_string());
                assert_eq!(on_trace, on_columns, "{} on {x:?}", rule.source);
                held[k] += usize::from(on_trace == Ok(true));
            }
        }
    }
    for (k, r) in reads_states.iter().enumerate() {
        if r != "SUCCESS()" {
            assert!(held[first_extra + k] > 0, "{r} never held: {held:?}");
        }
    }
}
