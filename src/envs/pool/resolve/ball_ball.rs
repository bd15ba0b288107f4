//! Ball–ball resolution (docs/envs/pool.md §P8 (b); pooltool
//! `physics/resolve/ball_ball/core.py` and `frictional_inelastic/__init__.py`,
//! `friction.py::AlciatoreBallBallFriction`):
//! 1. `make_kiss`: place the balls 2R + MIN_DIST apart along their velocities (fallback:
//!    push apart along the line of centres);
//! 2. frictional inelastic impulse with μ_b from the Alciatore curve, e = mean(e_b);
//! 3. the "continually touching" fix-up for nearly co-moving balls.
//!
//! Both balls end sliding.

use super::super::detect::roots::quadratic_complex;
use super::super::evolve::EPS;
use super::super::params::{BallParams, ModelParams};
use super::super::state::{BallState, MotionState};
use super::super::vec3::{self, V3};
use super::MIN_DIST;

fn fallback_positions(r1: V3, r2: V3, radius: f64, spacer: f64) -> (V3, V3) {
    let correction = 2.0 * radius - vec3::norm(vec3::sub(r2, r1)) + spacer;
    let u = vec3::unit(vec3::sub(r2, r1));
    (
        vec3::sub(r1, vec3::scale(u, correction / 2.0)),
        vec3::add(r2, vec3::scale(u, correction / 2.0)),
    )
}

/// pooltool `CoreBallBallCollision.make_kiss` (radius of ball 1 for both).
pub fn make_kiss(s1: &mut BallState, s2: &mut BallState, radius: f64) {
    let (r1, r2, v1, v2) = (s1.r, s2.r, s1.v, s2.v);
    let spacer = MIN_DIST;
    let (n1, n2) = if s1.s.is_nontranslating() && s2.s.is_nontranslating() {
        fallback_positions(r1, r2, radius, spacer)
    } else {
        let b = vec3::sub(v2, v1);
        let c = vec3::sub(r2, r1);
        let alpha = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
        let beta = 2.0 * b[0] * c[0] + 2.0 * b[1] * c[1] + 2.0 * b[2] * c[2];
        let target = 2.0 * radius + spacer;
        let gamma = c[0] * c[0] + c[1] * c[1] + c[2] * c[2] - target * target;
        let roots = quadratic_complex(alpha, beta, gamma);
        let mut best: Option<f64> = None;
        for z in roots {
            let keep = (z.im.abs() / z.re.abs()) < 1e-3;
            if keep && best.is_none_or(|t| z.re.abs() < t.abs()) {
                best = Some(z.re);
            }
        }
        match best {
            None => fallback_positions(r1, r2, radius, spacer),
            Some(t) => {
                let c1 = vec3::add(r1, vec3::scale(v1, t));
                let c2 = vec3::add(r2, vec3::scale(v2, t));
                let mid = vec3::scale(vec3::add(r1, r2), 0.5);
                let midc = vec3::scale(vec3::add(c1, c2), 0.5);
                if vec3::norm(vec3::sub(mid, midc)) > 5.0 * spacer {
                    fallback_positions(r1, r2, radius, spacer)
                } else {
                    (c1, c2)
                }
            }
        }
    };
    s1.r = n1;
    s2.r = n2;
}

/// Alciatore ball–ball friction μ = a + b·exp(−c·|Δv_surface,tangential|).
pub fn alciatore_friction(
    s1: &BallState,
    p1: &BallParams,
    s2: &BallState,
    p2: &BallParams,
    m: &ModelParams,
) -> f64 {
    let n = vec3::unit(vec3::sub(s2.r, s1.r));
    let tsv = |s: &BallState, d: V3, r: f64| {
        let vn = s.v[0] * d[0] + s.v[1] * d[1] + s.v[2] * d[2];
        vec3::add(
            vec3::sub(s.v, vec3::scale(d, vn)),
            vec3::cross(s.w, vec3::scale(d, r)),
        )
    };
    let v1c = tsv(s1, n, p1.r);
    let v2c = tsv(s2, vec3::neg(n), p2.r);
    let speed = vec3::norm(vec3::sub(v1c, v2c));
    m.alciatore_a + m.alciatore_b * (-m.alciatore_c * speed).exp()
}

#[inline]
fn surface_velocity(v: V3, w: V3, d: V3, r: f64) -> V3 {
    vec3::add(v, vec3::cross(w, vec3::scale(d, r)))
}

/// The frictional inelastic impulse (pooltool `_resolve_ball_ball`). Returns new
/// (v1, w1, v2, w2); positions are untouched.
pub fn frictional_inelastic(
    s1: &BallState,
    s2: &BallState,
    radius: f64,
    u_b: f64,
    e_b: f64,
) -> (V3, V3, V3, V3) {
    let unit_x = [1.0, 0.0, 0.0];
    let theta = vec3::angle(vec3::sub(s2.r, s1.r));
    let (sm, cm) = (-theta).sin_cos();
    let mut v1 = vec3::rotate_z_cs(s1.v, cm, sm);
    let mut w1 = vec3::rotate_z_cs(s1.w, cm, sm);
    let mut v2 = vec3::rotate_z_cs(s2.v, cm, sm);
    let mut w2 = vec3::rotate_z_cs(s2.w, cm, sm);
    let v1_n_f = 0.5 * ((1.0 - e_b) * v1[0] + (1.0 + e_b) * v2[0]);
    let v2_n_f = 0.5 * ((1.0 + e_b) * v1[0] + (1.0 - e_b) * v2[0]);
    let dvn = (v2_n_f - v1_n_f).abs();
    let (w1_n_f, w2_n_f) = (w1[0], w2[0]);
    v1[0] = 0.0;
    v2[0] = 0.0;
    w1[0] = 0.0;
    w2[0] = 0.0;
    let mut v1f = v1;
    let mut w1f = w1;
    let mut v2f = v2;
    let mut w2f = w2;
    let v1c = surface_velocity(v1, w1, unit_x, radius);
    let v2c = surface_velocity(v2, w2, vec3::neg(unit_x), radius);
    let v12c = vec3::sub(v1c, v2c);
    let has_rel = vec3::norm(v12c) > EPS;
    let mut use_noslip = !has_rel;
    if has_rel {
        let hat = vec3::unit(v12c);
        let k = u_b * dvn;
        let dv = [k * -hat[0], k * -hat[1], k * -hat[2]];
        let dw = vec3::scale(vec3::cross(unit_x, dv), 2.5 / radius);
        v1f = vec3::add(v1, dv);
        w1f = vec3::add(w1, dw);
        v2f = vec3::sub(v2, dv);
        w2f = vec3::add(w2, dw);
        let s1c = surface_velocity(v1f, w1f, unit_x, radius);
        let s2c = surface_velocity(v2f, w2f, vec3::neg(unit_x), radius);
        let slip = vec3::sub(s1c, s2c);
        use_noslip = vec3::dot(v12c, slip) <= 0.0;
    }
    if use_noslip {
        let wsum = vec3::add(w1, w2);
        let dv = vec3::scale(
            vec3::add(
                vec3::sub(v1, v2),
                vec3::scale(vec3::cross(wsum, unit_x), radius),
            ),
            -(1.0 / 7.0),
        );
        let cx = vec3::cross(unit_x, vec3::sub(v1, v2));
        let inner = vec3::add(
            vec3::add([cx[0] / radius, cx[1] / radius, cx[2] / radius], w1),
            w2,
        );
        let dw = vec3::scale(inner, -(5.0 / 14.0));
        v1f = vec3::add(v1, dv);
        w1f = vec3::add(w1, dw);
        v2f = vec3::sub(v2, dv);
        w2f = vec3::add(w2, dw);
    }
    v1f[0] = v1_n_f;
    v2f[0] = v2_n_f;
    w1f[0] = w1_n_f;
    w2f[0] = w2_n_f;
    let (s, c) = theta.sin_cos();
    let mut v1o = vec3::rotate_z_cs(v1f, c, s);
    let w1o = vec3::rotate_z_cs(w1f, c, s);
    let mut v2o = vec3::rotate_z_cs(v2f, c, s);
    let w2o = vec3::rotate_z_cs(w2f, c, s);
    v1o[2] = 0.0;
    v2o[2] = 0.0;
    (v1o, w1o, v2o, w2o)
}

/// pooltool `resolve_continually_touching`: if both balls move, their line-of-centres
/// speeds differ by < 0.01 m/s and their velocities are aligned (cos > 0.9), the chased
/// ball takes 10 % of the chaser's line-of-centres velocity.
pub fn continually_touching(s1: &mut BallState, s2: &mut BallState) {
    let (r1, r2, v1, v2) = (s1.r, s2.r, s1.v, s2.v);
    let sp1 = vec3::norm(v1);
    let sp2 = vec3::norm(v2);
    if !(sp1 > 0.0 && sp2 > 0.0) {
        return;
    }
    let loc = vec3::unit(vec3::sub(r2, r1));
    let l1 = vec3::dot(v1, loc);
    let l2 = vec3::dot(v2, loc);
    let cos = vec3::dot(v1, v2) / (sp1 * sp2);
    if (l2 - l1).abs() < 0.01 && cos > 0.9 {
        let (n1, n2) = if l1 > l2 {
            let st = l1 * 0.10;
            (l1 - st, l2 + st)
        } else {
            let st = l2 * 0.10;
            (l1 + st, l2 - st)
        };
        s1.v = vec3::add(vec3::sub(v1, vec3::scale(loc, l1)), vec3::scale(loc, n1));
        s2.v = vec3::add(vec3::sub(v2, vec3::scale(loc, l2)), vec3::scale(loc, n2));
    }
}

/// Full default ball–ball resolution, in place. Both balls become sliding.
pub fn resolve(
    s1: &mut BallState,
    p1: &BallParams,
    s2: &mut BallState,
    p2: &BallParams,
    model: &ModelParams,
) {
    make_kiss(s1, s2, p1.r);
    let u_b = alciatore_friction(s1, p1, s2, p2, model);
    let e_b = (p1.e_b + p2.e_b) / 2.0;
    let (v1, w1, v2, w2) = frictional_inelastic(s1, s2, p1.r, u_b, e_b);
    s1.v = v1;
    s1.w = w1;
    s2.v = v2;
    s2.w = w2;
    s1.s = MotionState::Sliding;
    s2.s = MotionState::Sliding;
    continually_touching(s1, s2);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Head-on, no spin: normal velocities exchange with restitution e_b:
    /// v1' = (1−e)/2·v, v2' = (1+e)/2·v (§P8 (b) step 4). No tangential slip, so spins
    /// stay 0. make_kiss leaves a 2R + 1e-6 gap. Tol 1e-12.
    #[test]
    fn head_on_exchange_with_restitution() {
        let p = BallParams::pool_default();
        let v = 1.5;
        let mut a = BallState {
            r: [0.5 - 2.0 * p.r, 0.5, p.r],
            v: [v, 0.0, 0.0],
            w: [0.0; 3],
            s: MotionState::Sliding,
            t: 0.0,
        };
        let mut b = BallState::at_rest(0.5, 0.5, p.r);
        resolve(&mut a, &p, &mut b, &p, &ModelParams::default());
        assert!((a.v[0] - (1.0 - p.e_b) / 2.0 * v).abs() < 1e-12);
        assert!((b.v[0] - (1.0 + p.e_b) / 2.0 * v).abs() < 1e-12);
        assert!(a.v[1].abs() < 1e-12 && b.v[1].abs() < 1e-12);
        assert!(vec3::norm(a.w) < 1e-9 && vec3::norm(b.w) < 1e-9);
        let gap = vec3::norm(vec3::sub(b.r, a.r));
        assert!((gap - (2.0 * p.r + MIN_DIST)).abs() < 1e-12, "gap {gap}");
        assert_eq!(a.s, MotionState::Sliding);
        assert_eq!(b.s, MotionState::Sliding);
        // momentum conserved
        assert!((a.v[0] + b.v[0] - v).abs() < 1e-12);
    }

    /// Continually-touching fix-up: nearly co-moving balls, chaser gives 10 % of its
    /// line-of-centres velocity; momentum is conserved.
    #[test]
    fn continually_touching_transfers_momentum() {
        let mut a = BallState {
            r: [0.0, 0.0, 0.0],
            v: [1.0, 0.0, 0.0],
            w: [0.0; 3],
            s: MotionState::Sliding,
            t: 0.0,
        };
        let mut b = BallState {
            r: [0.06, 0.0, 0.0],
            v: [0.995, 0.0, 0.0],
            w: [0.0; 3],
            s: MotionState::Sliding,
            t: 0.0,
        };
        continually_touching(&mut a, &mut b);
        assert!((a.v[0] - 0.9).abs() < 1e-15);
        assert!((b.v[0] - 1.095).abs() < 1e-15);
    }
}
