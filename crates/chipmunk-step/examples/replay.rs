//! Replays a pymunk episode recorded by `tools/iphyre_chipmunk_steps.py` on this crate's step and
//! reports where the two part: the first step whose contact (arbiter) order differs, and the first step
//! whose body positions differ by more than a threshold (or, for a `--compact` recording, the first
//! checkpoint whose running digest differs).
//!
//! ```text
//! cargo run -p chipmunk-step --example replay -- RECORDING.txt [--all] [--eps PX]
//! ```
//!
//! `--all` prints every step's largest position difference, the state differences of each body and
//! both contact lists where they differ; `--eps` (default 0: bit for bit) is the position difference
//! at which the replay stops.

use std::process::ExitCode;

#[path = "../tests/support/recording.rs"]
mod recording;

use recording::{Digest, Recording, order_of};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: replay RECORDING.txt [--all] [--eps PX]");
        return ExitCode::from(2);
    };
    let all = args.iter().any(|a| a == "--all");
    let eps: f64 = args
        .iter()
        .position(|a| a == "--eps")
        .and_then(|i| args.get(i + 1))
        .map_or(0.0, |s| s.parse().expect("--eps takes a number"));
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("replay: {path}: {e}");
            return ExitCode::from(2);
        }
    };
    let mut rec = Recording::parse(&text);
    let mut space = std::mem::replace(
        &mut rec.space,
        chipmunk_step::Space::new(Default::default()),
    );
    let mut digest = Digest::new();
    let mut checkpoints = rec.digests.iter().peekable();
    let mut first_order = None;
    for step in 1..=rec.steps {
        for &b in rec.removals.get(&step).into_iter().flatten() {
            space.remove_body(b);
        }
        space.step(rec.dt);
        digest.step(&space);
        let ours = order_of(&space);
        if let Some(theirs) = rec.orders.get(&step)
            && &ours != theirs
            && first_order.is_none()
        {
            first_order = Some(step);
            println!("step {step}: contact order differs\n  pymunk: {theirs}\n  ours:   {ours}");
        }
        let mut worst = (0.0f64, usize::MAX);
        for (b, s) in rec.states.get(&step).into_iter().flatten() {
            let body = &space.bodies()[*b];
            let d = (body.p.x - s[0]).abs().max((body.p.y - s[1]).abs());
            let dv = [
                body.angle - s[2],
                body.v.x - s[3],
                body.v.y - s[4],
                body.w - s[5],
            ];
            if all && dv.iter().any(|&x| x != 0.0) {
                println!(
                    "  body {b}: d(angle, vx, vy, w) = {:.3e} {:.3e} {:.3e} {:.3e}",
                    dv[0], dv[1], dv[2], dv[3]
                );
            }
            if d > worst.0 || d.is_nan() {
                worst = (d, *b);
            }
        }
        if all {
            let ours_c: Vec<String> = space
                .contact_points()
                .iter()
                .map(|c| {
                    let mut s = format!(
                        "{} {} {:?} {:?}",
                        c.body_a, c.body_b, c.normal.x, c.normal.y
                    );
                    for (p1, p2) in &c.points {
                        s += &format!(" {:?} {:?} {:?} {:?}", p1.x, p1.y, p2.x, p2.y);
                    }
                    s
                })
                .collect();
            if let Some(theirs_c) = rec.contacts.get(&step)
                && &ours_c != theirs_c
            {
                println!("  contacts differ\n    pymunk: {theirs_c:?}\n    ours:   {ours_c:?}");
            }
            println!("step {step}: max |dp| {:.3e} (body {})", worst.0, worst.1);
        }
        if worst.0 > eps || worst.0.is_nan() {
            println!(
                "step {step}: positions part by {:.3e} px (body {}); first contact-order difference: {}",
                worst.0,
                worst.1,
                first_order.map_or("none".into(), |s| format!("step {s}"))
            );
            return ExitCode::FAILURE;
        }
        if let Some(&&(at, hex)) = checkpoints.peek()
            && at == step
        {
            checkpoints.next();
            if hex != digest.0 {
                println!(
                    "step {step}: the running digest differs (steps up to {step} are not bit for bit)"
                );
                return ExitCode::FAILURE;
            }
        }
    }
    println!(
        "agree within {eps:e} px over all {} steps (pymunk success {}); first contact-order difference: {}",
        rec.steps,
        u8::from(rec.success),
        first_order.map_or("none".into(), |s| format!("step {s}"))
    );
    ExitCode::SUCCESS
}
