//! The step against the original, bit for bit: episodes of iphyre 0.2.3 recorded from pymunk 6.11.1 by
//! `tools/iphyre_chipmunk_steps.py --compact` (`tests/data/`, README there) replayed here must give the
//! same running digest of every dynamic body's position, angle and velocities and of the contact order,
//! at every checkpoint (every 30 steps and the last), and the same final states and outcome.
//!
//! Together they cover segment–segment contacts with Chipmunk's contact order (seesaw, angle,
//! hinder_fill), pin joints (pendulum, multi_ball_pendulum), damped springs (spring, impulse_spring),
//! many balls (noisy_fill), removals, and both 60 and 10 fps.

mod support;

use support::recording::{Digest, Recording};

fn replay(name: &str) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut rec = Recording::parse(&text);
    assert!(
        !rec.digests.is_empty() && rec.steps > 0,
        "{name}: not a compact recording"
    );
    let mut space = std::mem::replace(
        &mut rec.space,
        chipmunk_step::Space::new(Default::default()),
    );
    let mut digest = Digest::new();
    let mut checkpoints = rec.digests.iter();
    let mut next = checkpoints.next();
    let mut last_good = 0;
    for step in 1..=rec.steps {
        for &b in rec.removals.get(&step).into_iter().flatten() {
            assert!(
                space.remove_body(b),
                "{name}: step {step}: body {b} removed twice"
            );
        }
        space.step(rec.dt);
        digest.step(&space);
        if let Some(&(at, hex)) = next
            && at == step
        {
            assert_eq!(
                digest.0, hex,
                "{name}: the replay parts from pymunk between steps {last_good} and {step} \
                 (cargo run -p chipmunk-step --example replay on a full recording shows where)"
            );
            last_good = step;
            next = checkpoints.next();
        }
    }
    assert!(next.is_none(), "{name}: checkpoints after the last step");
    for (b, s) in &rec.states[&rec.steps] {
        let body = &space.bodies()[*b];
        assert_eq!(
            [body.p.x, body.p.y, body.angle, body.v.x, body.v.y, body.w],
            *s,
            "{name}: final state of body {b}"
        );
    }
}

#[test]
fn seesaw_at_60_fps_replays_bit_for_bit() {
    replay("seesaw_60.txt");
}

#[test]
fn angle_at_10_fps_replays_bit_for_bit() {
    replay("angle_10.txt");
}

#[test]
fn hinder_fill_at_60_fps_replays_bit_for_bit() {
    replay("hinder_fill_60.txt");
}

#[test]
fn pendulum_at_60_fps_replays_bit_for_bit() {
    replay("pendulum_60.txt");
}

#[test]
fn multi_ball_pendulum_at_10_fps_replays_bit_for_bit() {
    replay("multi_ball_pendulum_10.txt");
}

#[test]
fn spring_at_10_fps_replays_bit_for_bit() {
    replay("spring_10.txt");
}

#[test]
fn impulse_spring_at_60_fps_replays_bit_for_bit() {
    replay("impulse_spring_60.txt");
}

#[test]
fn noisy_fill_at_10_fps_replays_bit_for_bit() {
    replay("noisy_fill_10.txt");
}
