//! Behaviour of the Chipmunk-faithful step on the scenes it is built for.

use chipmunk_step::{Body, Constraint, DampedSpring, Geometry, PinJoint, Space, Vect};

const DT: f64 = 1.0 / 60.0;

fn ball(space: &mut Space, p: Vect, r: f64) -> usize {
    let id = space.add_body(Body::dynamic(1.0, 0.5 * r * r, p));
    space.add_shape(
        id,
        Geometry::Circle {
            offset: Vect::ZERO,
            r,
        },
        0.5,
        0.1,
    );
    id
}

fn segment(space: &mut Space, body: Body, half: f64) -> usize {
    let id = space.add_body(body);
    space.add_shape(
        id,
        Geometry::Segment {
            a: Vect::new(-half, 0.0),
            b: Vect::new(half, 0.0),
            r: 10.0,
        },
        0.5,
        0.1,
    );
    id
}

#[test]
fn free_fall_moves_positions_before_velocities() {
    // Positions move with the previous step's velocity: after k steps y = y0 + g·dt²·k(k−1)/2.
    let mut space = Space::new(Vect::new(0.0, 100.0));
    let b = ball(&mut space, Vect::new(300.0, 50.0), 20.0);
    for k in 1..=120u32 {
        space.step(DT);
        let y = space.body(b).unwrap().p.y;
        let exact = 50.0 + 100.0 * DT * DT * f64::from(k * (k - 1)) / 2.0;
        assert!((y - exact).abs() < 1e-9, "step {k}: {y} vs {exact}");
        let v = space.body(b).unwrap().v.y;
        assert!((v - 100.0 * DT * f64::from(k)).abs() < 1e-9);
    }
    assert_eq!(space.body(b).unwrap().p.x, 300.0);
}

#[test]
fn a_ball_comes_to_rest_on_a_static_segment() {
    let mut space = Space::new(Vect::new(0.0, 100.0));
    segment(&mut space, Body::fixed(Vect::new(300.0, 400.0)), 100.0);
    let b = ball(&mut space, Vect::new(300.0, 300.0), 20.0);
    for _ in 0..600 {
        space.step(DT);
    }
    let body = space.body(b).unwrap();
    // Resting on the capsule's top (y = 390) with at most the slop of overlap, and still.
    assert!((body.p.y - 370.0).abs() < 0.2, "{:?}", body.p);
    assert!(body.v.length() < 0.5, "{:?}", body.v);
    assert!((body.p.x - 300.0).abs() < 1e-6);
    assert_eq!(space.touching_bodies().count(), 1);
}

#[test]
fn a_bar_rests_on_a_block_without_sinking_or_drifting() {
    let mut space = Space::new(Vect::new(0.0, 100.0));
    segment(&mut space, Body::fixed(Vect::new(300.0, 400.0)), 100.0);
    let bar = segment(
        &mut space,
        Body::dynamic(1.0, 200.0 / 3.0, Vect::new(300.0, 380.0)),
        60.0,
    );
    for _ in 0..600 {
        space.step(DT);
        let body = space.body(bar).unwrap();
        assert!(body.p.y > 379.5 && body.p.y < 380.2, "{:?}", body.p);
    }
    let body = space.body(bar).unwrap();
    // Sequential impulses over the two contact points in a fixed order leave a small tilt, no slide.
    assert!(
        body.angle.abs() < 0.005 && (body.p.x - 300.0).abs() < 0.05,
        "{body:?}"
    );
    assert!(body.v.length() < 1e-3, "{body:?}");
}

#[test]
fn a_pin_joint_keeps_its_length_while_the_pendulum_swings() {
    let mut space = Space::new(Vect::new(0.0, 100.0));
    let pivot = space.add_body(Body::fixed(Vect::new(300.0, 100.0)));
    let bob = ball(&mut space, Vect::new(450.0, 100.0), 10.0);
    let joint = PinJoint::new(
        space.bodies(),
        pivot,
        bob,
        Vect::ZERO,
        Vect::ZERO,
        0.9f64.powi(60),
    );
    assert!((joint.distance() - 150.0).abs() < 1e-12);
    space.add_constraint(Constraint::Pin(joint));
    let mut lowest: f64 = 0.0;
    for _ in 0..600 {
        space.step(DT);
        let p = space.body(bob).unwrap().p;
        let d = (p - Vect::new(300.0, 100.0)).length();
        assert!((d - 150.0).abs() < 0.5, "rod length {d}");
        lowest = lowest.max(p.y);
    }
    assert!(lowest > 240.0, "the bob swung down to y = {lowest}");
    // Removing the bob removes the joint with it.
    assert!(space.remove_body(bob));
    assert!(!space.remove_body(bob));
    space.step(DT);
}

#[test]
fn a_damped_spring_pulls_towards_its_rest_length_and_settles() {
    let mut space = Space::new(Vect::ZERO);
    let a = ball(&mut space, Vect::new(100.0, 300.0), 10.0);
    let b = ball(&mut space, Vect::new(300.0, 300.0), 10.0);
    space.add_constraint(Constraint::Spring(DampedSpring::new(
        a,
        b,
        Vect::ZERO,
        Vect::ZERO,
        50.0,
        1.0,
        0.3,
    )));
    let dist = |s: &Space| (s.body(b).unwrap().p - s.body(a).unwrap().p).length();
    for _ in 0..60 {
        space.step(DT);
    }
    assert!(dist(&space) < 195.0, "{}", dist(&space));
    // Momentum is conserved: the midpoint stays put.
    let mid = (space.body(a).unwrap().p + space.body(b).unwrap().p) * 0.5;
    assert!((mid.x - 200.0).abs() < 1e-9 && (mid.y - 300.0).abs() < 1e-9);
}
