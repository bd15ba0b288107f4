//! Replays a scene recorded from pymunk by `tools/iphyre_chipmunk_steps.py` on this crate's step and
//! reports, step by step, where the two part: the first step whose contact (arbiter) order differs, and
//! the largest position difference per step until it exceeds a threshold.
//!
//! ```text
//! cargo run -p chipmunk-step --example replay -- SCENE.txt [--all] [--eps PX]
//! ```
//!
//! `--all` prints every step's largest difference and both contact orders; `--eps` (default 1e-6 px)
//! is the difference at which the replay stops.

use std::collections::HashMap;
use std::process::ExitCode;

use chipmunk_step::{
    Body, Constraint, DampedSpring, Geometry, PinJoint, Space, Vect, default_bias,
};

fn num(s: &str) -> f64 {
    s.parse().unwrap_or_else(|_| panic!("not a number: {s:?}"))
}

fn int(s: &str) -> usize {
    s.parse()
        .unwrap_or_else(|_| panic!("not an integer: {s:?}"))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: replay SCENE.txt [--all] [--eps PX]");
        return ExitCode::from(2);
    };
    let all = args.iter().any(|a| a == "--all");
    let eps = args
        .iter()
        .position(|a| a == "--eps")
        .map(|i| num(&args[i + 1]))
        .unwrap_or(1e-6);
    let text = std::fs::read_to_string(path).expect("read the scene");

    let mut space = Space::new(Vect::ZERO);
    let mut dt = 0.0;
    // Recorded per step: body states and contact order; removals per step.
    let mut states: HashMap<usize, Vec<(usize, [f64; 6])>> = HashMap::new();
    let mut orders: HashMap<usize, String> = HashMap::new();
    let mut removals: HashMap<usize, Vec<usize>> = HashMap::new();
    let mut contacts: HashMap<usize, Vec<String>> = HashMap::new();
    let mut result = (0, 0);
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first().copied() {
            Some("space") => {
                space = Space::new(Vect::new(num(f[1]), num(f[2])));
                space.iterations = int(f[3]);
                dt = num(f[4]);
            }
            Some("body") => {
                let p = Vect::new(num(f[5]), num(f[6]));
                assert_eq!(num(f[7]), 0.0, "initial angles are 0");
                let body = if f[2] == "dynamic" {
                    Body::dynamic(num(f[3]), num(f[4]), p)
                } else {
                    Body::fixed(p)
                };
                assert_eq!(space.add_body(body), int(f[1]));
            }
            Some("circle") => {
                let g = Geometry::Circle {
                    offset: Vect::ZERO,
                    r: num(f[2]),
                };
                space.add_shape(int(f[1]), g, num(f[3]), num(f[4]));
            }
            Some("segment") => {
                let g = Geometry::Segment {
                    a: Vect::new(num(f[2]), num(f[3])),
                    b: Vect::new(num(f[4]), num(f[5])),
                    r: num(f[6]),
                };
                space.add_shape(int(f[1]), g, num(f[7]), num(f[8]));
            }
            Some("pin") => {
                let j = PinJoint::new(
                    space.bodies(),
                    int(f[1]),
                    int(f[2]),
                    Vect::ZERO,
                    Vect::ZERO,
                    default_bias(),
                );
                space.add_constraint(Constraint::Pin(j));
            }
            Some("spring") => {
                let s = DampedSpring::new(
                    int(f[1]),
                    int(f[2]),
                    Vect::ZERO,
                    Vect::ZERO,
                    num(f[3]),
                    num(f[4]),
                    num(f[5]),
                );
                space.add_constraint(Constraint::Spring(s));
            }
            Some("remove") => removals.entry(int(f[1])).or_default().push(int(f[2])),
            Some("state") => states.entry(int(f[1])).or_default().push((
                int(f[2]),
                [
                    num(f[3]),
                    num(f[4]),
                    num(f[5]),
                    num(f[6]),
                    num(f[7]),
                    num(f[8]),
                ],
            )),
            Some("arbiters") => {
                orders.insert(int(f[1]), f[2..].join(" "));
            }
            Some("contact") => contacts
                .entry(int(f[1]))
                .or_default()
                .push(f[2..].join(" ")),
            Some("result") => result = (int(f[1]), int(f[2])),
            _ => {}
        }
    }

    let mut first_order = None;
    for step in 1..=result.1 {
        for &b in removals.get(&step).into_iter().flatten() {
            space.remove_body(b);
        }
        space.step(dt);
        let ours: Vec<String> = space
            .contacts()
            .map(|(a, b, n)| format!("{a}:{b}:{n}"))
            .collect();
        let ours = ours.join(" ");
        let theirs = orders.get(&step).cloned().unwrap_or_default();
        if ours != theirs && first_order.is_none() {
            first_order = Some(step);
            println!("step {step}: contact order differs\n  pymunk: {theirs}\n  ours:   {ours}");
        }
        let mut worst = (0.0f64, usize::MAX);
        for (b, s) in states.get(&step).into_iter().flatten() {
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
                .map(|(a, b, n, pts)| {
                    let mut s = format!("{a} {b} {:?} {:?}", n.x, n.y);
                    for (p1, p2) in pts {
                        s += &format!(" {:?} {:?} {:?} {:?}", p1.x, p1.y, p2.x, p2.y);
                    }
                    s
                })
                .collect();
            let theirs_c = contacts.get(&step).cloned().unwrap_or_default();
            if ours_c != theirs_c {
                println!("  contacts differ\n    pymunk: {theirs_c:?}\n    ours:   {ours_c:?}");
            }
            println!(
                "step {step}: max |dp| {:.3e} (body {}) | pymunk {theirs} | ours {ours}",
                worst.0, worst.1
            );
        }
        if !(worst.0 <= eps) {
            println!(
                "step {step}: positions part by {:.3e} px (body {}) — first contact-order difference: {}",
                worst.0,
                worst.1,
                first_order.map_or("none".into(), |s| format!("step {s}"))
            );
            return ExitCode::SUCCESS;
        }
    }
    println!(
        "agree within {eps:e} px over all {} steps (pymunk success {}); first contact-order difference: {}",
        result.1,
        result.0,
        first_order.map_or("none".into(), |s| format!("step {s}"))
    );
    ExitCode::SUCCESS
}
