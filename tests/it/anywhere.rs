//! The binary run from an empty folder, with no path into the repository: every command that uses
//! built-in data (detector libraries, goal files, PHYRE tasks, I-PHYRE games, the billiards table, the
//! prompt templates) finds it in the binary. Also checks that no library code finds data through the
//! compile-time source path.

use std::path::Path;

use crate::common::{TestRun, repo};

/// `annotrace ARGS…` in `t`'s (empty) folder, which must succeed.
fn ok(t: &TestRun, args: &[&str]) -> String {
    let r = t.run(args);
    r.ok();
    r.stdout
}

#[test]
fn simulate_annotate_and_accuracy_work_from_an_empty_folder_in_every_environment() {
    let t = TestRun::new();
    let cases: [(&str, &[&str], &str); 3] = [
        (
            "pooltool",
            &["--scenes", "2", "--dt", "0.1"],
            "pooltool-human",
        ),
        ("iphyre", &["--games", "support", "--fps", "10"], "iphyre"),
        ("phyre", &["--scenes", "2"], "phyre"),
    ];
    for (env, flags, library) in cases {
        let run = format!("run-{env}");
        let mut sim = vec!["simulate", "--env", env, "--run", &run, "-q"];
        sim.extend_from_slice(flags);
        ok(&t, &sim);
        let out = ok(
            &t,
            &[
                "annotate",
                "--env",
                env,
                "--run",
                &run,
                "--workers",
                "1",
                "-q",
            ],
        );
        assert!(
            out.contains(&format!("with 12 detector(s) of {library}")),
            "{env}: {out}"
        );
        let out = ok(
            &t,
            &[
                "accuracy",
                "--env",
                env,
                "--run",
                &run,
                "--workers",
                "1",
                "-q",
            ],
        );
        assert!(out.contains("| label |"), "{env}: {out}");
    }
    // Nothing was unpacked next to the runs: the built-in data is read from memory.
    let mut names: Vec<String> = std::fs::read_dir(t.dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["run-iphyre", "run-phyre", "run-pooltool"]);
}

#[test]
fn render_reward_optimise_and_suggest_labels_work_from_an_empty_folder() {
    let t = TestRun::new();
    ok(&t, &["render", "--task", "00004:063", "--out", "task.png"]);
    ok(
        &t,
        &[
            "render", "--env", "iphyre", "--game", "support", "--out", "game.png",
        ],
    );
    for png in ["task.png", "game.png"] {
        assert_eq!(&std::fs::read(t.path(png)).unwrap()[1..4], b"PNG", "{png}");
    }
    // A built-in goal's program checks against the built-in library.
    let goals: toml::Table =
        toml::from_str(annotrace::builtin::text("data/goals/pooltool.toml").unwrap()).unwrap();
    let program = goals["goal"][0]["program"].as_str().unwrap();
    let out = ok(&t, &["reward", "check", "--no-probe", program]);
    assert!(out.contains("for library pooltool-human"), "{out}");
    // An optimise stage naming the built-in goal file (and, through it, the built-in library).
    t.write(
        "opt.toml",
        "[pipeline]\nname = \"opt\"\n\n[[stage]]\nid = \"o\"\nkind = \"optimise\"\n\
         goals = \"data/goals/pooltool.toml\"\ngoal_ids = [\"touch-2-cushion\"]\nscenes = 1\n\
         seeds = 1\nbudget = 2\ncheckpoint = 1\nrewards = [\"dense\"]\nworkers = 1\n",
    );
    ok(&t, &["run", "opt.toml", "--run-dir", "out", "-q"]);
    let csv = t.csv(
        "out",
        "SELECT goal, reward_type, count(*) AS n FROM optimisation GROUP BY 1, 2",
    );
    assert!(csv.contains("touch-2-cushion,dense,"), "{csv}");
    // The offline path of suggest-labels: the built-in library's labels in the prompt.
    ok(&t, &["suggest-labels", "--help"]);
    let prompt = ok(&t, &["suggest-labels", "--env", "phyre", "--dry-run"]);
    assert!(prompt.contains("tip over"), "{prompt}");
    assert!(!t.path("data").exists());
}

#[test]
fn no_library_code_finds_data_through_the_compile_time_source_path() {
    // `env!("CARGO_MANIFEST_DIR")` is the folder the binary was built in, which a copied or installed
    // binary does not have; only tests and `include_*!` paths may use it.
    let mut stack = vec![repo().join("src")];
    let mut offenders = Vec::new();
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                let code = text.split("#[cfg(test)]").next().unwrap_or_default();
                if code.contains("CARGO_MANIFEST_DIR") {
                    offenders.push(p.strip_prefix(repo()).unwrap_or(Path::new("?")).to_owned());
                }
            }
        }
    }
    assert!(offenders.is_empty(), "{offenders:?}");
}
