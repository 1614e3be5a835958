//! Rigid links (DESIGN §6): the mid-point bar force of one link and its derivative, and
//! the augmented-Lagrangian multiplier update between solves of one step.

use crate::model::{Link, Mat3, Vec3};

/// Residual contribution of one bar on its node's `u` rows and its derivative.
pub(crate) struct BarTerms {
    /// Force on the node, `(λ + κ(g_n + g_{n+1})/2) (x_{n+½} − p)/ℓ²`.
    pub force: Vec3,
    /// `∂force/∂u` (not symmetric: `g_{n+1}` depends on the end point, the arm on the
    /// mid-point).
    pub stiffness: Mat3,
}

/// Bar terms for the node at `x_n` moved by the increment `u`, with multiplier `lambda`.
pub(crate) fn bar_terms(link: &Link, lambda: f64, x_n: &Vec3, u: &Vec3) -> BarTerms {
    let l2 = link.length * link.length;
    let x1 = x_n + u;
    let arm = (x_n + 0.5 * u - link.pivot) / l2;
    let s = lambda + 0.5 * link.penalty * (link.strain(x_n) + link.strain(&x1));
    BarTerms {
        force: s * arm,
        stiffness: Mat3::identity() * (0.5 * s / l2)
            + arm * ((x1 - link.pivot) / l2).transpose() * (0.5 * link.penalty),
    }
}

/// The multiplier iteration of one step. The first round is DESIGN §6's Uzawa update
/// `λ ← λ + (κ/2) g_{n+1}` (the factor ½ matches the mid-point average in the force, so a
/// fixed point has `g_{n+1} = 0`). It contracts by `k/(κ/2 + k)`, `k ≈ m/Δt²` the
/// inertia stiffness of the node, which is slow at small Δt (0.6 per round at Δt = 0.005,
/// κ = 1e5, m = 2). Later rounds therefore take the secant step through the last two
/// `(λ, g)` pairs of each link (the map λ ↦ g is smooth and monotone within a step), and
/// fall back to the Uzawa step when the secant slope has the wrong sign.
#[derive(Default)]
pub(crate) struct MultiplierIteration {
    prev: Option<(Vec<f64>, Vec<f64>)>,
}

impl MultiplierIteration {
    /// Updates `lambda` after a solve that left the bars at strains `g1`. Returns whether
    /// every bar was already within its tolerance (then nothing is changed).
    pub fn update(&mut self, links: &[Link], g1: &[f64], lambda: &mut [f64]) -> bool {
        if links.iter().zip(g1).all(|(l, g)| g.abs() <= l.tol) {
            return true;
        }
        let last = (lambda.to_vec(), g1.to_vec());
        for (i, l) in links.iter().enumerate() {
            let uzawa = 0.5 * l.penalty * g1[i];
            let step = match &self.prev {
                Some((lam0, g0)) if g0[i] != g1[i] => {
                    // Secant: g(λ) ≈ g1 + (λ − λ1)(g1 − g0)/(λ1 − λ0) = 0.
                    let slope = (g1[i] - g0[i]) / (lambda[i] - lam0[i]);
                    // Raising λ pulls the node toward the pivot: g falls (slope < 0).
                    if slope < 0.0 && slope.is_finite() {
                        -g1[i] / slope
                    } else {
                        uzawa
                    }
                }
                _ => uzawa,
            };
            lambda[i] += step;
        }
        self.prev = Some(last);
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link() -> Link {
        Link {
            node: 0,
            pivot: Vec3::new(0.1, -0.2, 0.3),
            length: 1.3,
            penalty: 1e3,
            tol: 1e-10,
        }
    }

    /// The bar's work over a step equals the change of its energy, exactly (the mid-point
    /// rule on a quadratic strain).
    #[test]
    fn work_equals_energy_change() {
        let l = link();
        let x = Vec3::new(0.4, 0.9, 1.1);
        let u = Vec3::new(0.05, -0.3, 0.2);
        let b = bar_terms(&l, 2.5, &x, &u);
        let de = l.energy(2.5, &(x + u)) - l.energy(2.5, &x);
        assert!((b.force.dot(&u) - de).abs() <= 1e-14 * de.abs().max(1.0));
    }

    #[test]
    fn stiffness_matches_finite_differences() {
        let l = link();
        let x = Vec3::new(0.4, 0.9, 1.1);
        let u = Vec3::new(0.05, -0.3, 0.2);
        let b = bar_terms(&l, -1.5, &x, &u);
        let h = 1e-6;
        for d in 0..3 {
            let mut e = Vec3::zeros();
            e[d] = h;
            let fd = (bar_terms(&l, -1.5, &x, &(u + e)).force
                - bar_terms(&l, -1.5, &x, &(u - e)).force)
                / (2.0 * h);
            for c in 0..3 {
                let k = b.stiffness[(c, d)];
                assert!(
                    (fd[c] - k).abs() <= 1e-7 * k.abs().max(1.0),
                    "({c},{d}) {k} vs {}",
                    fd[c]
                );
            }
        }
    }
}
