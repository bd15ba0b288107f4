//! Outcome agreement of annotrace's PHYRE and I-PHYRE with the originals on balanced outcome sets
//! (docs/fidelity.md), split by the original's status and, for I-PHYRE, by frame rate.
//!
//! ```bash
//! cargo run --example fidelity -- phyre tests/data/phyre/balanced_tune.jsonl.gz tests/data/phyre/balanced_holdout.jsonl.gz
//! cargo run --example fidelity -- iphyre tests/data/iphyre/balanced_tune.jsonl.gz
//! # options: --list (print every disagreeing pair), --set NAME=VALUE (a physics parameter, for tuning)
//! ```
//!
//! PHYRE sets are `phyre_gen.py outcomes` output, I-PHYRE sets `iphyre_gen.py outcomes` output
//! (`shared/tools/reference-traces/`), plain or gzipped.

use std::process::ExitCode;

use annotrace::envs::{iphyre, phyre};

fn usage() -> ExitCode {
    eprintln!("usage: fidelity phyre|iphyre FILE... [--list] [--set NAME=VALUE]...");
    ExitCode::from(2)
}

fn pct(k: usize, n: usize) -> String {
    if n == 0 {
        "-".into()
    } else {
        format!("{:.1} %", 100.0 * k as f64 / n as f64)
    }
}

fn parse<T: std::str::FromStr>(name: &str, v: &str) -> Result<T, String> {
    v.parse()
        .map_err(|_| format!("--set {name}={v}: not a valid value"))
}

fn phyre_params(sets: &[(String, String)]) -> Result<phyre::PhysicsParams, String> {
    let mut p = phyre::PhysicsParams::default();
    for (k, v) in sets {
        match k.as_str() {
            "engine" => {
                p.engine = phyre::Engine::from_name(v)
                    .ok_or_else(|| format!("--set engine={v}: expected box2d or rapier"))?
            }
            "box2d_phyre_compat" => p.box2d_phyre_compat = parse(k, v)?,
            "solver_iterations" => p.solver_iterations = parse(k, v)?,
            "stabilization_iterations" => p.stabilization_iterations = parse(k, v)?,
            "pgs_iterations" => p.pgs_iterations = parse(k, v)?,
            "contact_recycling" => p.contact_recycling = parse(k, v)?,
            "prediction_distance" => p.prediction_distance = parse(k, v)?,
            "ccd" => p.ccd = parse(k, v)?,
            "polygon_skin" => p.polygon_skin = parse(k, v)?,
            "restitution_threshold" => p.restitution_threshold = parse(k, v)?,
            "touch_distance" => p.touch_distance = parse(k, v)?,
            "sleep_linear" => p.sleep_linear = parse(k, v)?,
            "sleep_time" => p.sleep_time = parse(k, v)?,
            "sleeping" => p.sleeping = parse(k, v)?,
            "friction" => p.friction = parse(k, v)?,
            "restitution" => p.restitution = parse(k, v)?,
            "angular_damping" => p.angular_damping = parse(k, v)?,
            "steps_for_solution" => p.steps_for_solution = parse(k, v)?,
            _ => return Err(format!("--set {k}: unknown PHYRE parameter")),
        }
    }
    Ok(p)
}

fn iphyre_params(sets: &[(String, String)]) -> Result<iphyre::PhysicsParams, String> {
    let mut p = iphyre::PhysicsParams::default();
    for (k, v) in sets {
        match k.as_str() {
            "solver_iterations" => p.solver_iterations = parse(k, v)?,
            "stabilization_iterations" => p.stabilization_iterations = parse(k, v)?,
            "length_unit" => p.length_unit = parse(k, v)?,
            "pgs_iterations" => p.pgs_iterations = parse(k, v)?,
            "contact_frequency" => p.contact_frequency = parse(k, v)?,
            "contact_damping_ratio" => p.contact_damping_ratio = parse(k, v)?,
            "max_corrective_velocity" => p.max_corrective_velocity = parse(k, v)?,
            "friction" => p.friction = parse(k, v)?,
            "restitution" => p.restitution = parse(k, v)?,
            "engine" => {
                p.engine = iphyre::Engine::from_name(v).ok_or_else(|| {
                    format!("--set engine={v}: expected box2d, chipmunk or rapier")
                })?
            }
            "box2d_pixels_per_metre" => p.box2d_pixels_per_metre = parse(k, v)?,
            "box2d_velocity_iterations" => p.box2d_velocity_iterations = parse(k, v)?,
            "box2d_position_iterations" => p.box2d_position_iterations = parse(k, v)?,
            "box2d_polygon_skin" => p.box2d_polygon_skin = parse(k, v)?,
            "chipmunk_iterations" => p.chipmunk_iterations = parse(k, v)?,
            _ => return Err(format!("--set {k}: unknown I-PHYRE parameter")),
        }
    }
    Ok(p)
}

fn run_phyre(files: &[String], sets: &[(String, String)], list: bool) -> Result<(), String> {
    use phyre::Status;
    let params = phyre_params(sets)?;
    let tasks = phyre::TaskSet::default_tasks().map_err(|e| e.to_string())?;
    for f in files {
        let bytes = std::fs::read(f).map_err(|e| format!("{f}: {e}"))?;
        let set =
            phyre::reference::OutcomeSet::from_bytes(&bytes).map_err(|e| format!("{f}: {e}"))?;
        let a =
            phyre::reference::agreement(&set, tasks, &params).map_err(|e| format!("{f}: {e}"))?;
        println!(
            "PHYRE {f}: {} pairs, status agrees on {} ({})",
            a.pairs(),
            a.agree(),
            pct(a.agree(), a.pairs())
        );
        for s in [Status::Solved, Status::NotSolved, Status::InvalidInput] {
            let row = a.by_status[phyre::reference::status_slot(s)];
            println!(
                "  original {:<13} {:>4}: reproduced {:>4} ({:>7}); annotrace SOLVED {}, NOT_SOLVED {}, INVALID_INPUT {}",
                s.name(),
                a.original(s),
                a.reproduced(s),
                pct(a.reproduced(s), a.original(s)),
                row[0],
                row[1],
                row[2]
            );
        }
        let per: Vec<String> = a
            .per_template
            .iter()
            .filter(|(_, (n, k))| n != k)
            .map(|(t, (n, k))| format!("{t} {}", n - k))
            .collect();
        println!("  disagreements per template: {}", per.join(", "));
        println!(
            "  solved by both: {}, at the same step: {} ({})",
            a.both_solved,
            a.same_solving_step,
            pct(a.same_solving_step, a.both_solved)
        );
        if list {
            for &i in &a.disagreements {
                let p = &set.pairs[i];
                println!(
                    "    #{i} {} [{}, {}, {}] original {} (steps {:?}) annotrace {}",
                    p.task_id,
                    p.action.x,
                    p.action.y,
                    p.action.r,
                    p.status.name(),
                    p.steps,
                    a.ours[i].name()
                );
            }
        }
    }
    Ok(())
}

fn run_iphyre(files: &[String], sets: &[(String, String)], list: bool) -> Result<(), String> {
    let params = iphyre_params(sets)?;
    let games = iphyre::Games::default_games().map_err(|e| e.to_string())?;
    for f in files {
        let bytes = std::fs::read(f).map_err(|e| format!("{f}: {e}"))?;
        // The generator's outcome sets (JSON Lines, gzipped or not), or the older
        // `tools/iphyre_reference.py` JSON file.
        let set = match iphyre::reference::ReferenceSet::from_outcomes_bytes(&bytes) {
            Ok(set) => set,
            Err(e) => std::str::from_utf8(&bytes)
                .ok()
                .and_then(|text| iphyre::reference::ReferenceSet::from_json(text).ok())
                .ok_or_else(|| format!("{f}: {e}"))?,
        };
        for fps in [60.0, 10.0] {
            let sub = set.at_fps(fps);
            let a = iphyre::reference::agreement(&sub, &games, &params)
                .map_err(|e| format!("{f}: {e}"))?;
            let failed = a.pairs - a.solved.0;
            println!(
                "I-PHYRE {f} @ {fps} fps: {} pairs, success agrees on {} ({}); original successes {} reproduced {} ({}); \
                 failures {} reproduced {} ({}); eliminations agree {}; annotrace solved {}",
                a.pairs,
                a.success_agree,
                pct(a.success_agree, a.pairs),
                a.solved.0,
                a.solved_both,
                pct(a.solved_both, a.solved.0),
                failed,
                a.failed_both(),
                pct(a.failed_both(), failed),
                a.eliminations_agree,
                a.solved.1
            );
            let per: Vec<String> = a
                .per_game
                .iter()
                .filter(|(_, (n, k))| n != k)
                .map(|(g, (n, k))| format!("{g} {}", n - k))
                .collect();
            println!("  disagreements per game: {}", per.join(", "));
            if list {
                for &i in &a.disagreements {
                    let p = &sub.pairs[i];
                    println!(
                        "    #{i} {} {:?} original success {} (t {:.3})",
                        p.game, p.clicks, p.success, p.time
                    );
                }
            }
        }
    }
    Ok(())
}

/// `phyre-trace TASK X Y R`: every step's body states (px, y up) and goal runs as JSON lines, to compare
/// with a `phyre_gen.py` trace of the same pair.
fn phyre_trace(args: &[String], sets: &[(String, String)]) -> Result<(), String> {
    let [task_id, x, y, r] = args else {
        return Err("phyre-trace TASK X Y R".into());
    };
    let params = phyre_params(sets)?;
    let tasks = phyre::TaskSet::default_tasks().map_err(|e| e.to_string())?;
    let task = tasks.get(task_id).map_err(|e| e.to_string())?;
    let action = phyre::BallAction {
        x: parse("x", x)?,
        y: parse("y", y)?,
        r: parse("r", r)?,
    };
    let opts = phyre::RecordOptions {
        stride: 1,
        record: true,
    };
    let res = phyre::episode::run(&task, &action, &params, &opts).map_err(|e| e.to_string())?;
    for f in &res.frames {
        let bodies: Vec<[f64; 3]> = f.bodies.iter().map(|b| [b.x, b.y, b.angle]).collect();
        println!("{}", serde_json::json!({"step": f.step, "bodies": bodies}));
    }
    for e in &res.events {
        println!("{}", serde_json::json!({"event": format!("{e:?}")}));
    }
    println!(
        "{}",
        serde_json::json!({"status": res.status.name(), "steps": res.steps, "goal": [task.body1, task.body2]})
    );
    Ok(())
}

/// `iphyre-trace GAME CLICKS_JSON [FPS]`: every step's object ends (px, y down) as JSON lines, to compare
/// with an `iphyre_gen.py` recording of the same clicks.
fn iphyre_trace(args: &[String], sets: &[(String, String)]) -> Result<(), String> {
    let (game, clicks, fps) = match args {
        [g, c] => (g, c, 60.0),
        [g, c, f] => (g, c, parse("fps", f)?),
        _ => return Err("iphyre-trace GAME CLICKS_JSON [FPS]".into()),
    };
    let mut params = iphyre_params(sets)?;
    params.fps = fps;
    let games = iphyre::Games::default_games().map_err(|e| e.to_string())?;
    let game = games.get(game).map_err(|e| e.to_string())?;
    let clicks: Vec<[f64; 3]> = serde_json::from_str(clicks).map_err(|e| e.to_string())?;
    let clicks: Vec<iphyre::Click> = clicks
        .iter()
        .map(|&[x, y, t]| iphyre::Click { x, y, t })
        .collect();
    let mut episode =
        iphyre::Episode::new(game, &clicks, &params, true).map_err(|e| e.to_string())?;
    while !episode.done() {
        episode.step();
    }
    let r = episode.finish();
    for f in &r.frames {
        let objects: Vec<serde_json::Value> = f
            .objects
            .iter()
            .map(|o| serde_json::json!([o.index, o.p1[0], o.p1[1], o.p2[0], o.p2[1]]))
            .collect();
        println!(
            "{}",
            serde_json::json!({"step": f.step, "objects": objects})
        );
    }
    println!(
        "{}",
        serde_json::json!({"success": r.success, "steps": r.steps})
    );
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(env) = args.first() else {
        return usage();
    };
    let (mut files, mut sets, mut list) = (Vec::new(), Vec::new(), false);
    let mut it = args[1..].iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--list" => list = true,
            "--set" => {
                let Some((k, v)) = it.next().and_then(|kv| kv.split_once('=')) else {
                    return usage();
                };
                sets.push((k.to_string(), v.to_string()));
            }
            _ => files.push(a.clone()),
        }
    }
    if files.is_empty() {
        return usage();
    }
    let r = match env.as_str() {
        "phyre" => run_phyre(&files, &sets, list),
        "iphyre" => run_iphyre(&files, &sets, list),
        "phyre-trace" => phyre_trace(&files, &sets),
        "iphyre-trace" => iphyre_trace(&files, &sets),
        _ => return usage(),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fidelity: {e}");
            ExitCode::from(2)
        }
    }
}
