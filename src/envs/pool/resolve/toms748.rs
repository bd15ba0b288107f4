//! Bracketing root finder used by the Stronge cushion model's stick branches: a faithful
//! port of scipy's `optimize.toms748` (Alefeld, Potra & Shi, TOMS 748; scipy 1.17,
//! defaults k = 1, xtol = 2e-12, rtol = 4·eps, maxiter = 100), which pooltool 0.6.0 calls
//! in `physics/resolve/stronge_compliant.py` (docs/envs/pool.md §P8 (c)).
//!
//! The slip-time functions can have several roots in [t_c, t_f] (a near-tangency of
//! |u_t| with the friction limit); which one is found depends on the iteration path, so
//! the port reproduces scipy's steps exactly rather than using another bracketing method.
//! Where scipy raises (no sign change, non-finite values) we return the endpoint with the
//! smaller |f| instead of failing.

const XTOL: f64 = 2e-12;
const RTOL: f64 = 4.0 * f64::EPSILON;
const MAXITER: usize = 100;

#[inline]
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

fn frexp_exp(x: f64) -> i32 {
    if x == 0.0 || !x.is_finite() {
        return 0;
    }
    let bits = x.to_bits();
    let e = ((bits >> 52) & 0x7ff) as i32;
    if e == 0 {
        // subnormal
        let m = x.abs() * 2f64.powi(64);
        return frexp_exp(m) - 64;
    }
    e - 1022
}

fn secant(ab: [f64; 2], fab: [f64; 2]) -> f64 {
    let (x0, x1, f0, f1) = (ab[0], ab[1], fab[0], fab[1]);
    if f0 == f1 {
        return f64::NAN;
    }
    if f1.abs() > f0.abs() {
        (-f0 / f1 * x1 + x0) / (1.0 - f0 / f1)
    } else {
        (-f1 / f0 * x0 + x1) / (1.0 - f1 / f0)
    }
}

fn update_bracket(ab: &mut [f64; 2], fab: &mut [f64; 2], c: f64, fc: f64) -> (f64, f64) {
    let idx = if sign(fab[0]) * sign(fc) > 0.0 { 0 } else { 1 };
    let (rx, rfx) = (ab[idx], fab[idx]);
    fab[idx] = fc;
    ab[idx] = c;
    (rx, rfx)
}

fn notclose(fs: [f64; 4], atol: f64) -> bool {
    if fs.iter().any(|f| *f == 0.0 || !f.is_finite()) {
        return false;
    }
    for i in 0..3 {
        for j in (i + 1)..4 {
            if (fs[i] - fs[j]).abs() <= atol {
                return false;
            }
        }
    }
    true
}

/// scipy `_interpolated_poly` (Neville) evaluated at x.
fn interpolated_poly(xv: [f64; 4], fv: [f64; 4], x: f64) -> f64 {
    const N: usize = 4;
    let mut q = [[0.0f64; N]; N];
    let mut d = [[0.0f64; N]; N];
    for i in 0..N {
        q[i][0] = fv[i];
        d[i][0] = fv[i];
    }
    for k in 1..N {
        for i in k..N {
            let alpha = d[i][k - 1] - q[i - 1][k - 1];
            let diffik = xv[i - k] - xv[i];
            q[i][k] = (xv[i] - x) / diffik * alpha;
            d[i][k] = (xv[i - k] - x) / diffik * alpha;
        }
    }
    ((q[N - 1][1] + q[N - 1][2]) + q[N - 1][3]) + q[N - 1][0]
}

fn newton_quadratic(ab: [f64; 2], fab: [f64; 2], d: f64, fd: f64, k: usize) -> f64 {
    let (a, b) = (ab[0], ab[1]);
    let (fa, fb) = (fab[0], fab[1]);
    let r1 = [(fb - fa) / (b - a), (fd - fb) / (d - b)];
    let bb = r1[0];
    let aa = (r1[1] - r1[0]) / (d - a);
    let p = |x: f64| (aa * (x - b) + bb) * (x - a) + fa;
    if aa == 0.0 {
        return a - fa / bb;
    }
    let mut r = if sign(aa) * sign(fa) > 0.0 { a } else { b };
    for _ in 0..k {
        let r1 = r - p(r) / (bb + aa * (2.0 * r - a - b));
        if !(ab[0] < r1 && r1 < ab[1]) {
            if ab[0] < r && r < ab[1] {
                return r;
            }
            r = (ab[0] + ab[1]) / 2.0;
            break;
        }
        r = r1;
    }
    r
}

/// Root of `f` in `[a, b]` following scipy's `toms748(f, a, b)` step by step.
pub fn toms748<F: Fn(f64) -> f64>(f: F, a: f64, b: f64) -> f64 {
    let k = 1usize;
    let mut ab = [a, b];
    let fa = f(a);
    if fa == 0.0 {
        return a;
    }
    let fb = f(b);
    if fb == 0.0 {
        return b;
    }
    if !fa.is_finite() || !fb.is_finite() || sign(fa) * sign(fb) > 0.0 {
        return if fa.abs() < fb.abs() { a } else { b };
    }
    let mut fab = [fa, fb];
    let mut c = secant(ab, fab);
    if !(ab[0] < c && c < ab[1]) {
        c = (ab[0] + ab[1]) / 2.0;
    }
    let fc = f(c);
    if fc == 0.0 {
        return c;
    }
    let (mut d, mut fd) = update_bracket(&mut ab, &mut fab, c, fc);
    let (mut e, mut fe): (f64, Option<f64>) = (f64::NAN, None);
    let mut iterations = 1usize;
    let eps = f64::EPSILON;
    loop {
        iterations += 1;
        let ab_width = ab[1] - ab[0];
        let mut cc: Option<f64> = None;
        for nsteps in 2..(k + 2) {
            if let Some(fe_v) = fe
                && notclose([fab[0], fab[1], fd, fe_v], 32.0 * eps)
            {
                let c0 = interpolated_poly([fab[0], fab[1], fd, fe_v], [ab[0], ab[1], d, e], 0.0);
                if ab[0] < c0 && c0 < ab[1] {
                    cc = Some(c0);
                }
            }
            let c = match cc {
                Some(c) => c,
                None => newton_quadratic(ab, fab, d, fd, nsteps),
            };
            let fc = f(c);
            if fc == 0.0 {
                return c;
            }
            if !fc.is_finite() {
                return (ab[0] + ab[1]) / 2.0;
            }
            e = d;
            fe = Some(fd);
            let (nd, nfd) = update_bracket(&mut ab, &mut fab, c, fc);
            d = nd;
            fd = nfd;
            cc = None;
        }
        let uix = if fab[0].abs() < fab[1].abs() { 0 } else { 1 };
        let (u, fu) = (ab[uix], fab[uix]);
        let aa = (fab[1] - fab[0]) / (ab[1] - ab[0]);
        let mut c = u - 2.0 * fu / aa;
        if (c - u).abs() > 0.5 * (ab[1] - ab[0]) {
            c = (ab[0] + ab[1]) / 2.0;
        } else {
            if (c - u).abs() <= eps * u.abs() {
                let (e0, e1) = (frexp_exp(fab[uix]), frexp_exp(fab[1 - uix]));
                if e0 < e1 - 50 {
                    c = (31.0 * ab[uix] + ab[1 - uix]) / 32.0;
                } else {
                    let mm = if uix == 0 { 1.0 } else { -1.0 };
                    let adj = mm * c.abs() * RTOL + mm * XTOL;
                    c = u + adj;
                }
            }
            if !(ab[0] < c && c < ab[1]) {
                c = (ab[0] + ab[1]) / 2.0;
            }
        }
        let fc = f(c);
        if fc == 0.0 {
            return c;
        }
        if !fc.is_finite() {
            return (ab[0] + ab[1]) / 2.0;
        }
        e = d;
        fe = Some(fd);
        let (nd, nfd) = update_bracket(&mut ab, &mut fab, c, fc);
        d = nd;
        fd = nfd;
        if ab[1] - ab[0] > 0.5 * ab_width {
            e = d;
            fe = Some(fd);
            let z = (ab[0] + ab[1]) / 2.0;
            let fz = f(z);
            if fz == 0.0 {
                return z;
            }
            let (nd, nfd) = update_bracket(&mut ab, &mut fab, z, fz);
            d = nd;
            fd = nfd;
        }
        let (a, b) = (ab[0], ab[1]);
        if (a - b).abs() <= XTOL + RTOL * b.abs() || iterations >= MAXITER {
            return (a + b) / 2.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Simple roots to xtol (2e-12).
    #[test]
    fn finds_simple_roots() {
        let r = toms748(|x| x * x - 2.0, 0.0, 2.0);
        assert!((r - 2f64.sqrt()).abs() < 1e-11);
        let r = toms748(|x: f64| x.cos() - x, 0.0, 1.0);
        assert!((r - 0.7390851332151607).abs() < 1e-11);
        // no sign change: endpoint with the smaller |f|
        assert_eq!(toms748(|x| x * x + 1.0, 0.0, 2.0), 0.0);
    }
}
