//! Where PHYRE's Box2D (the 2018 snapshot `33af62e` between 2.3.1 and 2.4.0) computes differently from
//! the 2.4.1 that `box2d-rs` ports, and the settings that give 2.4.1 the old results to the last bit.
//!
//! **Owns:** the old polygon mass computation ([`legacy_mass_data`]) and the gravity scale that makes
//! 2.4.1's integration of gravity equal the old one ([`legacy_gravity_scale`]).
//! **Does not:** build worlds (`box2d_world.rs`).
//!
//! The two differences (found by diffing the two Box2D sources; docs/fidelity.md):
//!
//! * `b2PolygonShape::ComputeMass`: the old code integrates the triangles about the vertex average,
//!   2.4.1 about the first vertex, so mass, centre and inertia of a polygon differ in the last bits.
//! * `b2Island::Solve`: the old code adds `h·g` to a body's velocity, 2.4.1 adds
//!   `(h·m⁻¹)·((s·m)·g)` (`s` the gravity scale), which rounds differently for most masses. A gravity
//!   scale a few ulps from 1 makes the two equal for a given mass.

use box2d_rs::b2_math::B2vec2;
use box2d_rs::b2_shape::B2massData;

/// A fixture's shape in Box2D's local coordinates (m): a circle's radius (centred on the body origin)
/// or a polygon's vertices as `b2PolygonShape::Set` left them.
#[derive(Debug, Clone)]
pub(super) enum Fixture {
    /// A circle of this radius at the body origin.
    Circle(f32),
    /// A convex polygon (counter-clockwise, 3–8 vertices).
    Polygon(Vec<B2vec2>),
}

/// Box2D's `b2_pi` (f32).
const B2_PI: f32 = std::f32::consts::PI;

fn dot(a: B2vec2, b: B2vec2) -> f32 {
    a.x * b.x + a.y * b.y
}

/// The old `b2PolygonShape::ComputeMass` / `b2CircleShape::ComputeMass`: (mass, centre, inertia about
/// the body origin), in the old code's operation order.
fn fixture_mass(f: &Fixture, density: f32) -> (f32, B2vec2, f32) {
    match f {
        Fixture::Circle(r) => {
            let mass = density * B2_PI * r * r;
            (mass, B2vec2::new(0.0, 0.0), mass * (0.5 * r * r + 0.0))
        }
        Fixture::Polygon(vs) => {
            let n = vs.len();
            let inv_n = 1.0f32 / n as f32;
            let (mut sx, mut sy) = (0.0f32, 0.0f32);
            for v in vs {
                sx += v.x;
                sy += v.y;
            }
            let s = B2vec2::new(sx * inv_n, sy * inv_n);
            let k_inv3 = 1.0f32 / 3.0;
            let (mut cx, mut cy, mut area, mut inertia) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
            for i in 0..n {
                let e1 = B2vec2::new(vs[i].x - s.x, vs[i].y - s.y);
                let next = vs[(i + 1) % n];
                let e2 = B2vec2::new(next.x - s.x, next.y - s.y);
                let d = e1.x * e2.y - e1.y * e2.x;
                let triangle_area = 0.5 * d;
                area += triangle_area;
                let k = triangle_area * k_inv3;
                cx += k * (e1.x + e2.x);
                cy += k * (e1.y + e2.y);
                let intx2 = e1.x * e1.x + e2.x * e1.x + e2.x * e2.x;
                let inty2 = e1.y * e1.y + e2.y * e1.y + e2.y * e2.y;
                inertia += (0.25 * k_inv3 * d) * (intx2 + inty2);
            }
            let mass = density * area;
            let inv_area = 1.0f32 / area;
            let c = B2vec2::new(cx * inv_area, cy * inv_area);
            let center = B2vec2::new(c.x + s.x, c.y + s.y);
            let i = density * inertia + mass * (dot(center, center) - dot(c, c));
            (mass, center, i)
        }
    }
}

/// The old `b2Body::ResetMassData` sums for a dynamic body whose fixtures were created in the order
/// given (Box2D's fixture list runs newest first), as the mass data to pass to `SetMassData`, which
/// then computes the old body inertia and centre: `SetMassData` subtracts `m·c·c` from the summed
/// inertia as `ResetMassData` does.
pub(super) fn legacy_mass_data(fixtures: &[Fixture], density: f32) -> B2massData {
    let (mut mass, mut lx, mut ly, mut inertia) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for f in fixtures.iter().rev() {
        let (m, c, i) = fixture_mass(f, density);
        mass += m;
        lx += m * c.x;
        ly += m * c.y;
        inertia += i;
    }
    let center = if mass > 0.0 {
        let inv = 1.0f32 / mass;
        B2vec2::new(lx * inv, ly * inv)
    } else {
        B2vec2::new(0.0, 0.0)
    };
    B2massData {
        mass,
        center,
        i: inertia,
    }
}

/// A gravity scale `s` for which 2.4.1's `(h·m⁻¹)·((s·m)·g)` is the old `h·g` in `f32`, or as close to it
/// as any scale within ±64 ulps of 1 gets (for some masses the products skip the old value; the
/// velocity then differs by an ulp per step, as without the scale).
pub(super) fn legacy_gravity_scale(mass: f32, h: f32, g: f32) -> f32 {
    let inv_mass = 1.0f32 / mass;
    let want = h * g;
    let a = h * inv_mass;
    let error = |s: f32| (a * ((s * mass) * g) - want).abs();
    let mut best = (error(1.0), 1.0f32);
    let (mut up, mut down) = (1.0f32, 1.0f32);
    for _ in 0..64 {
        if best.0 == 0.0 {
            break;
        }
        up = f32::from_bits(up.to_bits() + 1);
        down = f32::from_bits(down.to_bits() - 1);
        for s in [up, down] {
            if error(s) < best.0 {
                best = (error(s), s);
            }
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gravity_scale_reproduces_the_old_increment() {
        let h = 1.0f32 / 60.0;
        let g = -9.8f32;
        let step = |mass: f32, s: f32| (h * (1.0 / mass)) * ((s * mass) * g);
        let (mut plain_exact, mut scaled_exact) = (0, 0);
        for k in 1..=200 {
            let mass = 0.037 * k as f32;
            let s = legacy_gravity_scale(mass, h, g);
            assert!((s - 1.0).abs() < 1e-5, "{mass} {s}");
            // Never further from the old increment than the plain 2.4.1 one, at most an ulp off.
            let (plain, scaled) = (
                (step(mass, 1.0) - h * g).abs(),
                (step(mass, s) - h * g).abs(),
            );
            assert!(
                scaled <= plain && scaled <= 2e-8,
                "{mass}: {plain} {scaled}"
            );
            plain_exact += usize::from(plain == 0.0);
            scaled_exact += usize::from(scaled == 0.0);
        }
        // 2.4.1's formula misses the old increment for many masses; the scale fixes most of them.
        assert!(
            plain_exact < 180 && scaled_exact > plain_exact,
            "{plain_exact} {scaled_exact}"
        );
    }

    #[test]
    fn polygon_mass_is_the_area_times_density_about_the_centroid() {
        // A 2 × 1 box centred on (1, 0.5): area 2, centre (1, 0.5), inertia about the origin
        // m·(w² + h²)/12 + m·|c|² = 0.5·5/12 + 0.5·1.25.
        let b = Fixture::Polygon(vec![
            B2vec2::new(0.0, 0.0),
            B2vec2::new(2.0, 0.0),
            B2vec2::new(2.0, 1.0),
            B2vec2::new(0.0, 1.0),
        ]);
        let md = legacy_mass_data(&[b], 0.25);
        assert!((md.mass - 0.5).abs() < 1e-6);
        assert!((md.center.x - 1.0).abs() < 1e-6 && (md.center.y - 0.5).abs() < 1e-6);
        assert!(
            (md.i - (0.5 * 5.0 / 12.0 + 0.5 * 1.25)).abs() < 1e-5,
            "{}",
            md.i
        );
    }
}
