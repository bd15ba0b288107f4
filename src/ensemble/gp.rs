//! A small Gaussian-process surrogate and expected-improvement search for calibration (b): inputs in
//! the unit cube, a squared-exponential kernel with one length scale, a little noise, outputs
//! standardised. Plain Rust (a Cholesky factorisation), since the problems are tiny (tens of
//! evaluations, tens of dimensions).
//!
//! **Owns:** the surrogate and the choice of the next point. **Does not:** know what is optimised
//! (`calibrate`).

use crate::rng::SplitMix64;

/// A fitted GP over points in [0, 1]^d.
#[derive(Clone, Debug)]
pub struct Gp {
    xs: Vec<Vec<f64>>,
    alpha: Vec<f64>,
    chol: Vec<Vec<f64>>,
    mean: f64,
    scale: f64,
    length: f64,
}

fn kernel(a: &[f64], b: &[f64], length: f64) -> f64 {
    let d2: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    (-0.5 * d2 / (length * length)).exp()
}

/// Lower-triangular L with L Lᵀ = m, or `None` if m is not positive definite.
fn cholesky(m: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = m.len();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let v = m[i][i] - s;
                if v <= 0.0 || !v.is_finite() {
                    return None;
                }
                l[i][j] = v.sqrt();
            } else {
                l[i][j] = (m[i][j] - s) / l[j][j];
            }
        }
    }
    Some(l)
}

/// Solves L y = b (forward) then Lᵀ x = y (backward).
fn solve(l: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut y = vec![0.0; n];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    x
}

impl Gp {
    /// Fits the GP to `(xs, ys)` with length scale `length` (noise 1e-6, raised until the kernel matrix
    /// factorises).
    pub fn fit(xs: &[Vec<f64>], ys: &[f64], length: f64) -> Option<Gp> {
        let n = xs.len();
        if n == 0 {
            return None;
        }
        let mean = ys.iter().sum::<f64>() / n as f64;
        let var = ys.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / n as f64;
        let scale = if var > 1e-18 { var.sqrt() } else { 1.0 };
        let z: Vec<f64> = ys.iter().map(|y| (y - mean) / scale).collect();
        let mut noise = 1e-6;
        loop {
            let k: Vec<Vec<f64>> = (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| kernel(&xs[i], &xs[j], length) + if i == j { noise } else { 0.0 })
                        .collect()
                })
                .collect();
            if let Some(chol) = cholesky(&k) {
                let alpha = solve(&chol, &z);
                return Some(Gp {
                    xs: xs.to_vec(),
                    alpha,
                    chol,
                    mean,
                    scale,
                    length,
                });
            }
            noise *= 10.0;
            if noise > 1.0 {
                return None;
            }
        }
    }

    /// Posterior mean and standard deviation at `x` (in the units of the fitted ys).
    pub fn predict(&self, x: &[f64]) -> (f64, f64) {
        let k: Vec<f64> = self.xs.iter().map(|p| kernel(p, x, self.length)).collect();
        let mu: f64 = k.iter().zip(&self.alpha).map(|(a, b)| a * b).sum();
        // v = L⁻¹ k; σ² = 1 − vᵀv.
        let n = k.len();
        let mut v = vec![0.0; n];
        for i in 0..n {
            v[i] = (k[i] - (0..i).map(|j| self.chol[i][j] * v[j]).sum::<f64>()) / self.chol[i][i];
        }
        let var = (1.0 - v.iter().map(|a| a * a).sum::<f64>()).max(0.0);
        (self.mean + self.scale * mu, self.scale * var.sqrt())
    }
}

/// Standard normal density and distribution function (Abramowitz–Stegun 7.1.26 for erf).
fn phi(z: f64) -> f64 {
    (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

fn big_phi(z: f64) -> f64 {
    let x = z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.3275911 * x.abs());
    let y = 1.0
        - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t
            + 0.254829592)
            * t
            * (-x * x).exp();
    0.5 * (1.0 + if x >= 0.0 { y } else { -y })
}

/// Expected improvement over `best` of a prediction (mean, sd), for maximisation.
pub fn expected_improvement(mean: f64, sd: f64, best: f64) -> f64 {
    if sd <= 1e-12 {
        return (mean - best).max(0.0);
    }
    let z = (mean - best) / sd;
    (mean - best) * big_phi(z) + sd * phi(z)
}

/// The next point to evaluate: among `candidates` random points (half uniform in the cube, half near
/// the best point so far, Gaussian steps of 0.1 clipped to the cube), the one of largest expected
/// improvement. Seeded by `rng`.
pub fn next_point(
    gp: &Gp,
    best_x: &[f64],
    best_y: f64,
    candidates: usize,
    rng: &mut SplitMix64,
) -> Vec<f64> {
    let d = best_x.len();
    let mut top: Option<(f64, Vec<f64>)> = None;
    for c in 0..candidates.max(1) {
        let x: Vec<f64> = if c % 2 == 0 {
            (0..d).map(|_| rng.next_f64()).collect()
        } else {
            best_x
                .iter()
                .map(|&b| {
                    // Box–Muller from two uniforms.
                    let (u1, u2) = (rng.next_f64().max(1e-12), rng.next_f64());
                    let g = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
                    (b + 0.1 * g).clamp(0.0, 1.0)
                })
                .collect()
        };
        let (m, s) = gp.predict(&x);
        let ei = expected_improvement(m, s, best_y);
        if top.as_ref().is_none_or(|t| ei > t.0) {
            top = Some((ei, x));
        }
    }
    top.map(|t| t.1).unwrap_or_else(|| best_x.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gp_interpolates_and_ei_finds_the_maximum_of_a_bump() {
        let f = |x: &[f64]| -((x[0] - 0.7).powi(2) + (x[1] - 0.3).powi(2));
        let mut rng = SplitMix64::new(5);
        let mut xs: Vec<Vec<f64>> = (0..4)
            .map(|_| vec![rng.next_f64(), rng.next_f64()])
            .collect();
        let mut ys: Vec<f64> = xs.iter().map(|x| f(x)).collect();
        for _ in 0..25 {
            let gp = Gp::fit(&xs, &ys, 0.3).unwrap();
            let (i, &by) = ys
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .unwrap();
            let x = next_point(&gp, &xs[i].clone(), by, 256, &mut rng);
            ys.push(f(&x));
            xs.push(x);
        }
        let gp = Gp::fit(&xs, &ys, 0.3).unwrap();
        let (m, s) = gp.predict(&xs[0]);
        assert!((m - ys[0]).abs() < 1e-3 && s < 1e-2, "{m} {s}");
        let best = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(best > -0.005, "{best}");
        assert!((big_phi(0.0) - 0.5).abs() < 1e-7 && (big_phi(1.96) - 0.975).abs() < 1e-3);
    }
}
