//! Polynomial root finding for collision detection (docs/envs/pool.md §P7).
//!
//! * [`quadratic_real`]: pooltool's real quadratic (`ptmath/roots/quadratic.py::solve`),
//!   used for linear cushions.
//! * [`quadratic_complex`]: pooltool's `solve_complex`, used by the `make_kiss` placement.
//! * [`quartic`]: our own complex quartic solver. pooltool uses the OQS "Algorithm 1010"
//!   port, which returns four zero roots when the leading coefficient is 0 (issue #263 →
//!   spurious t = 0 event). Here a (relatively) vanishing leading coefficient drops the
//!   degree (cubic → quadratic → linear), the quartic itself is solved by Ferrari's
//!   method on the depressed polynomial, and every root is polished by complex Newton
//!   iterations on the original polynomial.
//! * [`smallest_positive_real`]: the §P7 root filter
//!   (`ptmath/roots/core.py::get_real_positive_smallest_root`).

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Minimal complex number.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct C64 {
    pub re: f64,
    pub im: f64,
}

impl C64 {
    pub const ZERO: C64 = C64 { re: 0.0, im: 0.0 };
    #[inline]
    pub fn new(re: f64, im: f64) -> C64 {
        C64 { re, im }
    }
    #[inline]
    pub fn real(re: f64) -> C64 {
        C64 { re, im: 0.0 }
    }
    #[inline]
    pub fn norm_sqr(self) -> f64 {
        self.re * self.re + self.im * self.im
    }
    /// Principal square root (branch cut on the negative real axis, like `cmath.sqrt`).
    pub fn sqrt(self) -> C64 {
        if self.re == 0.0 && self.im == 0.0 {
            return C64::new(0.0, self.im);
        }
        let m = (self.re * self.re + self.im * self.im).sqrt();
        if self.re >= 0.0 {
            let t = ((m + self.re) * 0.5).sqrt();
            C64::new(t, self.im / (2.0 * t))
        } else {
            let t = ((m - self.re) * 0.5).sqrt();
            let im = if self.im.is_sign_negative() { -t } else { t };
            C64::new(self.im.abs() / (2.0 * t), im)
        }
    }
    #[inline]
    pub fn is_finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
}

impl Add for C64 {
    type Output = C64;
    #[inline]
    fn add(self, o: C64) -> C64 {
        C64::new(self.re + o.re, self.im + o.im)
    }
}
impl Sub for C64 {
    type Output = C64;
    #[inline]
    fn sub(self, o: C64) -> C64 {
        C64::new(self.re - o.re, self.im - o.im)
    }
}
impl Mul for C64 {
    type Output = C64;
    #[inline]
    fn mul(self, o: C64) -> C64 {
        C64::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
}
impl Mul<f64> for C64 {
    type Output = C64;
    #[inline]
    fn mul(self, k: f64) -> C64 {
        C64::new(self.re * k, self.im * k)
    }
}
impl Div for C64 {
    type Output = C64;
    #[inline]
    fn div(self, o: C64) -> C64 {
        // Smith's algorithm
        if o.re.abs() >= o.im.abs() {
            let r = o.im / o.re;
            let d = o.re + o.im * r;
            C64::new((self.re + self.im * r) / d, (self.im - self.re * r) / d)
        } else {
            let r = o.re / o.im;
            let d = o.re * r + o.im;
            C64::new((self.re * r + self.im) / d, (self.im * r - self.re) / d)
        }
    }
}
impl Neg for C64 {
    type Output = C64;
    #[inline]
    fn neg(self) -> C64 {
        C64::new(-self.re, -self.im)
    }
}

/// Up to four roots.
#[derive(Debug, Clone, Copy, Default)]
pub struct Roots {
    pub n: usize,
    pub z: [C64; 4],
}

impl Roots {
    #[inline]
    fn push(&mut self, z: C64) {
        if self.n < 4 {
            self.z[self.n] = z;
            self.n += 1;
        }
    }
    pub fn as_slice(&self) -> &[C64] {
        &self.z[..self.n]
    }
}

/// `EPS = 100·eps(f64)`.
const EPS: f64 = f64::EPSILON * 100.0;

/// pooltool's real quadratic `A t² + B t + C = 0`: NaN pair if A and B vanish, the linear
/// root twice if only A vanishes, NaN roots for a negative discriminant.
pub fn quadratic_real(a: f64, b: f64, c: f64) -> (f64, f64) {
    if a.abs() < EPS {
        if b.abs() < EPS {
            return (f64::NAN, f64::NAN);
        }
        let u = -c / b;
        return (u, u);
    }
    let bp = b / 2.0;
    let delta = bp * bp - a * c;
    let u1 = (-bp - delta.sqrt()) / a;
    let u2 = -u1 - b / a;
    (u1, u2)
}

/// pooltool's `solve_complex` quadratic (stable form). Missing roots are NaN.
pub fn quadratic_complex(a: f64, b: f64, c: f64) -> [C64; 2] {
    let nan = C64::new(f64::NAN, f64::NAN);
    let (ca, cb, cc) = (C64::real(a), C64::real(b), C64::real(c));
    if a != 0.0 {
        let d = cb * cb - C64::real(4.0) * ca * cc;
        let sd = d.sqrt();
        let sign_b = if b >= 0.0 { 1.0 } else { -1.0 };
        let mut num = -cb - sd * sign_b;
        let den = ca * 2.0;
        // |num| < 1e-14 |den| and |r1| < 1e-14, compared squared (no hypot)
        if num.norm_sqr() < 1e-28 * den.norm_sqr() {
            num = -cb + sd * sign_b;
        }
        let r1 = num / den;
        let r2 = if r1.norm_sqr() < 1e-28 {
            (-cb + sd) / (ca * 2.0)
        } else {
            (cc / ca) / r1
        };
        return [r1, r2];
    }
    if b != 0.0 {
        return [-cc / cb, nan];
    }
    [nan, nan]
}

#[inline]
fn horner(c: &[f64], z: C64) -> (C64, C64) {
    // value and derivative
    let mut p = C64::real(c[0]);
    let mut dp = C64::ZERO;
    for &k in &c[1..] {
        dp = dp * z + p;
        p = p * z + C64::real(k);
    }
    (p, dp)
}

/// Newton polish of `z` on the polynomial `c` (highest degree first). Roots that cannot
/// pass the §P7 filter (clearly negative or clearly complex) are returned unpolished.
fn polish(c: &[f64], mut z: C64) -> C64 {
    if z.re < -1e-6 || z.im.abs() > 1e-3 * z.re.abs() + 1e-6 {
        return z;
    }
    let (mut p, mut dp) = horner(c, z);
    let mut pa = p.norm_sqr();
    for _ in 0..8 {
        if pa == 0.0 || dp.norm_sqr() == 0.0 {
            break;
        }
        let zn = z - p / dp;
        if !zn.is_finite() {
            break;
        }
        let (pn, dpn) = horner(c, zn);
        let pna = pn.norm_sqr();
        if pna >= pa {
            break;
        }
        let step = (zn - z).norm_sqr();
        z = zn;
        p = pn;
        dp = dpn;
        pa = pna;
        if step <= 1e-32 * z.norm_sqr() {
            break;
        }
    }
    z
}

/// Real roots of a monic depressed cubic y³ + p y + q = 0; returns the largest real root.
fn cubic_largest_real(p: f64, q: f64) -> f64 {
    if p == 0.0 {
        return (-q).cbrt();
    }
    let disc = (q / 2.0) * (q / 2.0) + (p / 3.0) * (p / 3.0) * (p / 3.0);
    if disc > 0.0 {
        let sd = disc.sqrt();
        // stable Cardano
        let u = if q > 0.0 {
            -(q / 2.0 + sd).cbrt()
        } else {
            (-q / 2.0 + sd).cbrt()
        };
        if u == 0.0 {
            return 0.0;
        }
        u - p / (3.0 * u)
    } else {
        let m = 2.0 * (-p / 3.0).sqrt();
        let arg = (3.0 * q / (p * m)).clamp(-1.0, 1.0);
        let theta = arg.acos() / 3.0;
        m * theta.cos()
    }
}

/// All complex roots of `c[0] z³ + c[1] z² + c[2] z + c[3]` (c[0] ≠ 0).
fn cubic_roots(c: [f64; 4], out: &mut Roots) {
    let (a, b, dd) = (c[1] / c[0], c[2] / c[0], c[3] / c[0]);
    // depressed: z = y − a/3
    let p = b - a * a / 3.0;
    let q = 2.0 * a * a * a / 27.0 - a * b / 3.0 + dd;
    let y1 = cubic_largest_real(p, q);
    let mut z1 = y1 - a / 3.0;
    z1 = polish(&c, C64::real(z1)).re;
    // deflate: z² + (a + z1) z + (b + z1 (a + z1))
    let b2 = a + z1;
    let c2 = b + z1 * b2;
    out.push(C64::real(z1));
    let q2 = quadratic_complex(1.0, b2, c2);
    for z in q2 {
        if z.is_finite() {
            out.push(polish(&c, z));
        }
    }
}

/// Roots of `a z⁴ + b z³ + c z² + d z + e` (all complex roots; fewer than four when the
/// leading coefficients vanish relative to the others).
pub fn quartic(a: f64, b: f64, c: f64, d: f64, e: f64) -> Roots {
    let mut out = Roots::default();
    let co = [a, b, c, d, e];
    if co.iter().any(|x| !x.is_finite()) {
        return out;
    }
    let scale = b.abs().max(c.abs()).max(d.abs()).max(e.abs());
    const REL: f64 = 1e-13;
    if a.abs() <= REL * scale || a == 0.0 {
        // degenerate leading coefficient: cubic (pooltool issue #263)
        let s3 = c.abs().max(d.abs()).max(e.abs());
        if b.abs() <= REL * s3 || b == 0.0 {
            let s2 = d.abs().max(e.abs());
            if c.abs() <= REL * s2 || c == 0.0 {
                if d != 0.0 {
                    out.push(C64::real(-e / d));
                }
                return out;
            }
            for z in quadratic_complex(c, d, e) {
                if z.is_finite() {
                    out.push(polish(&[c, d, e], z));
                }
            }
            return out;
        }
        cubic_roots([b, c, d, e], &mut out);
        return out;
    }
    if e == 0.0 {
        out.push(C64::ZERO);
        cubic_roots([a, b, c, d], &mut out);
        return out;
    }
    // monic
    let (b1, c1, d1, e1) = (b / a, c / a, d / a, e / a);
    // depressed quartic y⁴ + p y² + q y + r, z = y − b1/4
    let s = b1 / 4.0;
    let s2 = s * s;
    let p = c1 - 6.0 * s2;
    let q = d1 - 2.0 * c1 * s + 8.0 * s2 * s;
    let r = e1 - d1 * s + c1 * s2 - 3.0 * s2 * s2;
    let ys: [C64; 4];
    let qscale = p.abs().max(r.abs().sqrt()).max(1e-300);
    if q.abs() <= 1e-14 * qscale * qscale.sqrt() {
        // biquadratic: w² + p w + r, y = ±sqrt(w)
        let w = quadratic_complex(1.0, p, r);
        let (w0, w1) = (
            if w[0].is_finite() { w[0] } else { C64::ZERO },
            if w[1].is_finite() { w[1] } else { C64::ZERO },
        );
        let (r0, r1) = (w0.sqrt(), w1.sqrt());
        ys = [r0, -r0, r1, -r1];
    } else {
        // resolvent cubic 8m³ + 8p m² + (2p² − 8r) m − q² = 0 → m³ + p m² + (p²/4 − r) m − q²/8
        let ca = p;
        let cb = p * p / 4.0 - r;
        let cc = -q * q / 8.0;
        let pp = cb - ca * ca / 3.0;
        let qq = 2.0 * ca * ca * ca / 27.0 - ca * cb / 3.0 + cc;
        let mut m = cubic_largest_real(pp, qq) - ca / 3.0;
        // polish m on the resolvent (real Newton)
        for _ in 0..4 {
            let f = ((m + ca) * m + cb) * m + cc;
            let df = (3.0 * m + 2.0 * ca) * m + cb;
            if df == 0.0 {
                break;
            }
            let mn = m - f / df;
            if !mn.is_finite() || (mn - m).abs() <= 1e-16 * m.abs() {
                if mn.is_finite() {
                    m = mn;
                }
                break;
            }
            m = mn;
        }
        // Also catches NaN.
        if m.is_nan() || m <= 0.0 {
            m = m.abs().max(1e-300);
        }
        let s2m = (2.0 * m).sqrt();
        let k = q / (2.0 * s2m);
        let qa = quadratic_complex(1.0, -s2m, p / 2.0 + m + k);
        let qb = quadratic_complex(1.0, s2m, p / 2.0 + m - k);
        ys = [qa[0], qa[1], qb[0], qb[1]];
    }
    for y in ys {
        if !y.is_finite() {
            continue;
        }
        let z = C64::new(y.re - s, y.im);
        out.push(polish(&co, z));
    }
    out
}

/// The §P7 root filter: smallest root with re ≥ 0 that counts as real, else ∞.
/// Real means |im| < 1e-9 when |re| > 1e-3, |im|/|re| < 1e-3 when 0 < |re| ≤ 1e-3, and
/// im == 0 when re == 0.
pub fn smallest_positive_real(roots: &[C64]) -> f64 {
    let mut min = f64::INFINITY;
    for z in roots {
        let (re, im) = (z.re, z.im);
        if re.is_nan() || re < 0.0 {
            continue;
        }
        let (ia, ra) = (im.abs(), re.abs());
        let is_real = if ra > 1e-3 {
            ia < 1e-9
        } else if ra > 0.0 {
            ia / ra < 1e-3
        } else {
            ia == 0.0
        };
        if is_real && re < min {
            min = re;
        }
    }
    min
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(c: &[f64], x: f64) -> f64 {
        c.iter().fold(0.0, |acc, k| acc * x + k)
    }

    fn check_real_roots(c: [f64; 5], expect: &[f64], tol: f64) {
        let r = quartic(c[0], c[1], c[2], c[3], c[4]);
        for &x in expect {
            let best = r
                .as_slice()
                .iter()
                .map(|z| (z.re - x).abs() + z.im.abs())
                .fold(f64::INFINITY, f64::min);
            assert!(
                best < tol,
                "root {x} not found in {:?} (coeffs {:?})",
                r.as_slice(),
                c
            );
        }
    }

    /// Quartic with known roots (t−0.5)(t−1.5)(t+2)(t−3): exact to 1e-12.
    #[test]
    fn quartic_known_roots() {
        // expand
        let roots = [0.5, 1.5, -2.0, 3.0];
        let mut c = vec![1.0];
        for r in roots {
            let mut n = vec![0.0; c.len() + 1];
            for (i, k) in c.iter().enumerate() {
                n[i] += k;
                n[i + 1] -= k * r;
            }
            c = n;
        }
        check_real_roots([c[0], c[1], c[2], c[3], c[4]], &roots, 1e-12);
        let r = quartic(c[0], c[1], c[2], c[3], c[4]);
        assert_eq!(
            smallest_positive_real(r.as_slice()),
            r.as_slice()
                .iter()
                .map(|z| z.re)
                .filter(|x| *x > 0.0)
                .fold(f64::INFINITY, f64::min)
        );
        assert!((smallest_positive_real(r.as_slice()) - 0.5).abs() < 1e-12);
    }

    /// Degenerate leading coefficient a = 0 (pooltool issue #263): pooltool's OQS returns
    /// four zero roots (a spurious t = 0 event); we must fall back to the cubic/quadratic.
    #[test]
    fn degenerate_quartic_falls_back() {
        // a = b = 0: quadratic 1·t² − 3 t + 2 = (t−1)(t−2)
        let r = quartic(0.0, 0.0, 1.0, -3.0, 2.0);
        assert_eq!(r.n, 2);
        assert!((smallest_positive_real(r.as_slice()) - 1.0).abs() < 1e-14);
        // a = 0: cubic (t−0.25)(t−1)(t+1) = t³ − 0.25t² − t + 0.25
        let r = quartic(0.0, 1.0, -0.25, -1.0, 0.25);
        assert_eq!(r.n, 3);
        assert!((smallest_positive_real(r.as_slice()) - 0.25).abs() < 1e-14);
        // a tiny relative to the rest: roots near the cubic's, no spurious zero
        let r = quartic(1e-18, 1.0, -0.25, -1.0, 0.25);
        assert!((smallest_positive_real(r.as_slice()) - 0.25).abs() < 1e-12);
        // everything zero: no roots at all (never a t = 0 event)
        let r = quartic(0.0, 0.0, 0.0, 0.0, 0.0);
        assert_eq!(smallest_positive_real(r.as_slice()), f64::INFINITY);
        // non-finite input
        let r = quartic(f64::INFINITY, 0.0, 0.0, 0.0, 1.0);
        assert_eq!(r.n, 0);
    }

    /// Ball–ball-like quartic: two balls 1 m apart closing at 2 m/s with small relative
    /// acceleration; contact when |C + Bt + At²| = 2R. Compare with bisection to 1e-12 s.
    #[test]
    fn ball_ball_like_and_tiny_roots() {
        let rr = 0.028575;
        let (ax, bx, cx) = (0.05, -2.0, 1.0);
        let c = [
            ax * ax,
            2.0 * ax * bx,
            bx * bx + 2.0 * ax * cx,
            2.0 * bx * cx,
            cx * cx - 4.0 * rr * rr,
        ];
        let r = quartic(c[0], c[1], c[2], c[3], c[4]);
        let t = smallest_positive_real(r.as_slice());
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if eval(&c, mid) > 0.0 {
                lo = mid
            } else {
                hi = mid
            }
        }
        assert!((t - lo).abs() < 1e-12, "{t} vs {lo}");
        // just-kissed pair: e ≈ 4R·1e-6 > 0, approaching at 1e-3 m/s: root ≈ 1.14e-4 s
        let e = (2.0 * rr + 1e-6f64).powi(2) - 4.0 * rr * rr;
        let gap = 2.0 * rr + 1e-6;
        let c = [
            1e-4,
            2e-2 * 1e-3,
            1e-6 + 2.0 * 1e-2 * gap,
            -2.0 * 1e-3 * gap,
            e,
        ];
        let r = quartic(c[0], c[1], c[2], c[3], c[4]);
        let t = smallest_positive_real(r.as_slice());
        assert!(eval(&c, t).abs() < 1e-18, "residual {}", eval(&c, t));
    }

    /// The §P7 filter rules.
    #[test]
    fn root_filter_rules() {
        let z = |re, im| C64::new(re, im);
        assert_eq!(smallest_positive_real(&[z(-1.0, 0.0)]), f64::INFINITY);
        assert_eq!(smallest_positive_real(&[z(0.5, 5e-10)]), 0.5);
        assert_eq!(smallest_positive_real(&[z(0.5, 2e-9)]), f64::INFINITY);
        assert_eq!(smallest_positive_real(&[z(1e-4, 5e-8)]), 1e-4);
        assert_eq!(smallest_positive_real(&[z(1e-4, 5e-7)]), f64::INFINITY);
        assert_eq!(smallest_positive_real(&[z(0.0, 0.0)]), 0.0);
        assert_eq!(smallest_positive_real(&[z(0.0, 1e-30)]), f64::INFINITY);
        assert_eq!(smallest_positive_real(&[z(2.0, 0.0), z(0.3, 0.0)]), 0.3);
    }

    #[test]
    fn pooltool_quadratics() {
        let (a, b) = quadratic_real(1.0, -3.0, 2.0);
        assert_eq!((a.min(b), a.max(b)), (1.0, 2.0));
        let (a, _) = quadratic_real(0.0, 0.0, 1.0);
        assert!(a.is_nan());
        let (a, b) = quadratic_real(0.0, 2.0, -1.0);
        assert_eq!((a, b), (0.5, 0.5));
        let r = quadratic_complex(1.0, 0.0, 1.0);
        assert!((r[0].im.abs() - 1.0).abs() < 1e-15);
    }
}
