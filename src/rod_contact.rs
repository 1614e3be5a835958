//! Contact between rods and of a rod with itself: a chain of contact spheres per rod.
//!
//! Each rod of a `[[contact]]` carries sample points at fixed places along its elements
//! (the nodes and, where an element is longer than the contact radius `ρ`, points in
//! between, at most `ρ` apart), each the centre of a sphere of radius `ρ`. A point's
//! position is the linear interpolation of its element's end nodes, `x = (1 − ξ) r₀ + ξ r₁`.
//! Two points `i`, `j` (of different rods, or of one rod and more than `2(ρᵢ + ρⱼ)` apart
//! along it) store the penalty energy `½ K (|d| − ρᵢ − ρⱼ)²` while `|d| < ρᵢ + ρⱼ`,
//! `d = xᵢ − xⱼ`, `K = k · min(spacingᵢ, spacingⱼ)` (`k` per unit length, N/m²).
//!
//! Over a step the pair exerts the discrete gradient of that energy in `s = |d|²` (a
//! quadratic function of the node positions):
//!
//! ```text
//! Fᵢ = −[W(s₁) − W(s₀)]/(s₁ − s₀) · 2 d_½,   Fⱼ = −Fᵢ
//! ```
//!
//! so the pair's work equals the drop of its energy exactly (EM keeps `H` to round-off),
//! the forces are equal and opposite (L is kept exactly) and act along the mid-point
//! connecting vector at the mid-point positions (J is kept exactly: the nodal forces
//! `wₐ Fᵢ` at `r_a,½` have the moment `xᵢ,½ × Fᵢ − xⱼ,½ × Fᵢ = d_½ × Fᵢ = 0`).

use nalgebra::{Matrix3, Vector3};

use crate::obstacle::quotient_quadric;

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

/// A contact sphere's centre on an element.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplePoint {
    /// The element's end nodes.
    pub nodes: [usize; 2],
    /// Position along the element, `x = (1 − ξ) r₀ + ξ r₁`.
    pub xi: f64,
    /// Contact radius `ρ`.
    pub radius: f64,
    /// Distance to the neighbouring sample points along the rod (reference).
    pub spacing: f64,
    /// Arc length along its rod (reference), for the self-contact exclusion.
    pub arc: f64,
}

impl SamplePoint {
    /// Position at node positions `r`.
    #[inline]
    pub fn at(&self, r: &[V3]) -> V3 {
        (1.0 - self.xi) * r[self.nodes[0]] + self.xi * r[self.nodes[1]]
    }

    /// The nodes and weights of the interpolation.
    #[inline]
    pub fn weights(&self) -> [(usize, f64); 2] {
        [(self.nodes[0], 1.0 - self.xi), (self.nodes[1], self.xi)]
    }
}

/// Contact between two rods (`points[..split]` on one, `points[split..]` on the other), or
/// of one rod with itself (`split == points.len()`).
#[derive(Clone, Debug, PartialEq)]
pub struct RodContact {
    /// The rods' names, for messages (one name for self-contact).
    pub rods: Vec<String>,
    /// Penalty stiffness `k` per unit length (N/m²).
    pub stiffness: f64,
    /// Coulomb friction coefficient `μ` between the spheres (0: frictionless).
    pub friction: f64,
    /// Regularization speed `ε` (m/s) of the friction law.
    pub slip: f64,
    /// The sample points.
    pub points: Vec<SamplePoint>,
    /// Where the second rod's points start (`points.len()` for self-contact).
    pub split: usize,
}

/// The friction of one contact pair over a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairFriction {
    /// Force on sphere `i` (sphere `j` feels its opposite), at the centres.
    pub force: V3,
    /// Moment on each of the two spheres (the same on both): `−½ d_½ × force`, so the
    /// pair's forces and moments have no resultant moment.
    pub moment: V3,
    /// Energy removed over the step (≥ 0).
    pub work: f64,
}

/// The force of one contact pair over a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairForce {
    /// Force on point `i` (point `j` feels its opposite).
    pub force: V3,
    /// `∂force/∂d₁` (`d₁ = xᵢ − xⱼ` at the end of the step).
    pub jacobian: M3,
}

impl RodContact {
    /// True for contact of a rod with itself.
    pub fn is_self(&self) -> bool {
        self.split == self.points.len()
    }

    /// Whether points `i < j` may touch: on different rods, or on one rod farther apart
    /// along it than twice their contact diameters (neighbours along a rod always
    /// overlap).
    pub fn allowed(&self, i: usize, j: usize) -> bool {
        let (a, b) = (&self.points[i], &self.points[j]);
        if self.is_self() {
            (a.arc - b.arc).abs() > 2.0 * (a.radius + b.radius)
        } else {
            (i < self.split) != (j < self.split)
        }
    }

    /// Largest contact radius.
    pub fn max_radius(&self) -> f64 {
        self.points.iter().fold(0.0, |m, p| m.max(p.radius))
    }

    /// Pairs `(i, j)`, `i < j`, allowed to touch and closer than `ρᵢ + ρⱼ + reach` at node
    /// positions `r` (a uniform grid of cell `2 ρ_max + reach`).
    pub fn candidates(&self, r: &[V3], reach: f64) -> Vec<(usize, usize)> {
        let cell = 2.0 * self.max_radius() + reach;
        let x: Vec<V3> = self.points.iter().map(|p| p.at(r)).collect();
        let key = |v: &V3| -> [i64; 3] { std::array::from_fn(|c| (v[c] / cell).floor() as i64) };
        let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> =
            std::collections::HashMap::new();
        for (i, v) in x.iter().enumerate() {
            grid.entry(key(v)).or_default().push(i);
        }
        let mut out = Vec::new();
        for (i, v) in x.iter().enumerate() {
            let k = key(v);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                            continue;
                        };
                        for &j in list {
                            if j <= i || !self.allowed(i, j) {
                                continue;
                            }
                            let lim = self.points[i].radius + self.points[j].radius + reach;
                            if (x[i] - x[j]).norm_squared() < lim * lim {
                                out.push((i, j));
                            }
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    fn pair_constants(&self, i: usize, j: usize) -> (f64, f64) {
        let (a, b) = (&self.points[i], &self.points[j]);
        (
            self.stiffness * a.spacing.min(b.spacing),
            a.radius + b.radius,
        )
    }

    /// Penalty energy of pair `(i, j)` at node positions `r`.
    pub fn pair_energy(&self, i: usize, j: usize, r: &[V3]) -> f64 {
        let (k, reach) = self.pair_constants(i, j);
        let dist = (self.points[i].at(r) - self.points[j].at(r)).norm();
        if dist < reach {
            0.5 * k * (dist - reach) * (dist - reach)
        } else {
            0.0
        }
    }

    /// Total penalty energy at node positions `r`.
    pub fn energy(&self, r: &[V3]) -> f64 {
        self.candidates(r, 0.0)
            .into_iter()
            .map(|(i, j)| self.pair_energy(i, j, r))
            .sum()
    }

    /// The force of pair `(i, j)` over the step from node positions `r0` to `r1`, with
    /// its Jacobian when `jacobian` is set.
    pub fn pair_force(
        &self,
        i: usize,
        j: usize,
        r0: &[V3],
        r1: &[V3],
        jacobian: bool,
    ) -> PairForce {
        let (k, reach) = self.pair_constants(i, j);
        let (pi, pj) = (&self.points[i], &self.points[j]);
        let d0 = pi.at(r0) - pj.at(r0);
        let d1 = pi.at(r1) - pj.at(r1);
        let (q, dq) = quotient_quadric(k, reach, d0.norm_squared(), d1.norm_squared());
        let dm = 0.5 * (d0 + d1);
        let force = -2.0 * q * dm;
        let jac = if jacobian && q != 0.0 {
            // ∂(−2 q d_½)/∂d₁ = −2 d_½ (∂q/∂s₁ · 2 d₁)ᵀ − q I.
            -4.0 * dq * dm * d1.transpose() - q * M3::identity()
        } else {
            M3::zeros()
        };
        PairForce {
            force,
            jacobian: jac,
        }
    }
}

impl RodContact {
    /// Friction of pair `(i, j)` over the step from `r0` to `r1`, the node rotation
    /// increments (Cayley vectors) `theta` interpolated at the spheres, over `dt`: the slip
    /// of the contact point `δ = Δxᵢ − Δxⱼ + ½ d_½ × (θᵢ + θⱼ)` (the relative motion of
    /// the two sphere surfaces at the mid-point between the centres), its part across the
    /// normal `δ_t`, and `f = −μ N δ_t/√(|δ_t|² + (ε Δt)²)` with `N` the pair's normal
    /// force. The work `f·δ_t ≤ 0` is what the force at the centres and the two moments
    /// do together. `None` out of contact or without friction.
    pub fn pair_friction(
        &self,
        i: usize,
        j: usize,
        r0: &[V3],
        r1: &[V3],
        theta: &dyn Fn(usize) -> V3,
        dt: f64,
    ) -> Option<PairFriction> {
        if self.friction == 0.0 {
            return None;
        }
        let (pi, pj) = (&self.points[i], &self.points[j]);
        let (k, reach) = self.pair_constants(i, j);
        let d0 = pi.at(r0) - pj.at(r0);
        let d1 = pi.at(r1) - pj.at(r1);
        let (q, _) = quotient_quadric(k, reach, d0.norm_squared(), d1.norm_squared());
        let dm = 0.5 * (d0 + d1);
        let len = dm.norm();
        if q >= 0.0 || len == 0.0 {
            return None;
        }
        let n = dm / len;
        let normal = -2.0 * q * len;
        let th = |p: &SamplePoint| p.weights().iter().map(|&(a, w)| w * theta(a)).sum::<V3>();
        let delta = (d1 - d0) + 0.5 * dm.cross(&(th(pi) + th(pj)));
        let dt_slip = delta - n * n.dot(&delta);
        let eps = self.slip * dt;
        let sn = (dt_slip.norm_squared() + eps * eps).sqrt();
        let force = -self.friction * normal * dt_slip / sn;
        Some(PairFriction {
            force,
            moment: -0.5 * dm.cross(&force),
            work: self.friction * normal * dt_slip.norm_squared() / sn,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_rods() -> (RodContact, Vec<V3>) {
        // Rod A: nodes 0-1-2 along e1; rod B: nodes 3-4 crossing above it along e2.
        let r = vec![
            V3::new(0.0, 0.0, 0.0),
            V3::new(0.1, 0.0, 0.0),
            V3::new(0.2, 0.0, 0.0),
            V3::new(0.1, -0.1, 0.015),
            V3::new(0.1, 0.1, 0.015),
        ];
        let pt = |nodes: [usize; 2], xi: f64, arc: f64| SamplePoint {
            nodes,
            xi,
            radius: 0.01,
            spacing: 0.01,
            arc,
        };
        let mut points = Vec::new();
        for k in 0..10 {
            points.push(pt([0, 1], k as f64 / 10.0, 0.01 * k as f64));
            points.push(pt([1, 2], k as f64 / 10.0, 0.1 + 0.01 * k as f64));
        }
        let split = points.len();
        for k in 0..=20 {
            points.push(pt([3, 4], k as f64 / 20.0, 0.01 * k as f64));
        }
        let c = RodContact {
            rods: vec!["a".into(), "b".into()],
            stiffness: 1e5,
            friction: 0.0,
            slip: 1e-3,
            points,
            split,
        };
        (c, r)
    }

    #[test]
    fn pair_work_equals_energy_change_and_keeps_momenta() {
        let (c, r0) = two_rods();
        let mut r1 = r0.clone();
        r1[3] += V3::new(0.004, 0.002, -0.006);
        r1[4] += V3::new(-0.003, 0.001, -0.004);
        r1[1] += V3::new(0.0, 0.001, 0.003);
        let pairs = c.candidates(&r0, 0.02);
        assert!(!pairs.is_empty());
        let (mut work, mut f_sum, mut moment) = (0.0, V3::zeros(), V3::zeros());
        for &(i, j) in &pairs {
            let f = c.pair_force(i, j, &r0, &r1, false).force;
            for (p, sign) in [(i, 1.0), (j, -1.0)] {
                for (node, w) in c.points[p].weights() {
                    let fa = sign * w * f;
                    work += fa.dot(&(r1[node] - r0[node]));
                    f_sum += fa;
                    moment += (0.5 * (r0[node] + r1[node])).cross(&fa);
                }
            }
        }
        let (e0, e1) = (c.energy(&r0), c.energy(&r1));
        eprintln!(
            "pair work vs ΔV {:.1e}, force sum {:.1e}, moment {:.1e}",
            (work + e1 - e0).abs() / e1,
            f_sum.norm() / work.abs(),
            moment.norm() / (work.abs() / 0.01)
        );
        assert!(e1 > 0.0, "no contact at the end");
        assert!(
            // Measured 2.9e-17, 2.9e-15 and 3.2e-18 (relative).
            (work + e1 - e0).abs() <= 3e-16 * e1,
            "work {work:e} vs ΔV {:e}",
            e1 - e0
        );
        assert!(f_sum.norm() <= 3e-14 * work.abs().max(1e-300));
        assert!(moment.norm() <= 3e-17 * (work.abs() / 0.01));
    }

    #[test]
    fn pair_jacobian_matches_finite_differences() {
        let (c, r0) = two_rods();
        let mut r1 = r0.clone();
        r1[3] += V3::new(0.001, 0.002, -0.008);
        for &(i, j) in &c.candidates(&r0, 0.02) {
            let f = c.pair_force(i, j, &r0, &r1, true);
            if f.force == V3::zeros() {
                continue;
            }
            // Move node 3 (weight w on point j, which feels −F): ∂F_i/∂r₃ = −w ∂F/∂d₁.
            let w = c.points[j]
                .weights()
                .iter()
                .find(|(n, _)| *n == 3)
                .map_or(0.0, |x| x.1);
            let h = 1e-8;
            for col in 0..3 {
                let (mut rp, mut rm) = (r1.clone(), r1.clone());
                rp[3][col] += h;
                rm[3][col] -= h;
                let fd = (c.pair_force(i, j, &r0, &rp, false).force
                    - c.pair_force(i, j, &r0, &rm, false).force)
                    / (2.0 * h);
                let an = -w * f.jacobian.column(col);
                let scale = f.jacobian.amax().max(1e-300);
                eprintln!("pair jacobian vs FD {:.1e}", (fd - an).amax() / scale);
                assert!(
                    // Measured ≤ 2.0e-10 (central differences, h = 1e-8).
                    (fd - an).amax() <= 2e-9 * scale,
                    "pair ({i}, {j}) column {col}: {fd:?} vs {an:?}"
                );
            }
        }
    }

    #[test]
    fn friction_work_is_what_its_forces_and_moments_do_and_never_negative() {
        let (mut c, r0) = two_rods();
        c.friction = 0.4;
        let mut r1 = r0.clone();
        r1[3] += V3::new(0.004, 0.002, -0.008);
        r1[4] += V3::new(0.003, -0.001, -0.007);
        let theta = |a: usize| V3::new(0.01 * a as f64, -0.02, 0.015 * (a as f64 - 2.0));
        let mut found = 0;
        for &(i, j) in &c.candidates(&r0, 0.02) {
            let Some(f) = c.pair_friction(i, j, &r0, &r1, &theta, 1e-3) else {
                continue;
            };
            found += 1;
            let (pi, pj) = (&c.points[i], &c.points[j]);
            let th = |p: &SamplePoint| p.weights().iter().map(|&(a, w)| w * theta(a)).sum::<V3>();
            let dxi = pi.at(&r1) - pi.at(&r0);
            let dxj = pj.at(&r1) - pj.at(&r0);
            let work = f.force.dot(&(dxi - dxj)) + f.moment.dot(&(th(pi) + th(pj)));
            assert!(f.work > 0.0);
            eprintln!("friction work {:.1e}", (work + f.work).abs() / f.work);
            assert!(
                // Measured 0 (the same products in the same order).
                (work + f.work).abs() <= 1e-15 * f.work,
                "{work:e} vs {:e}",
                f.work
            );
            // No resultant moment about the origin at the mid-point centres.
            let xi = 0.5 * (pi.at(&r0) + pi.at(&r1));
            let xj = 0.5 * (pj.at(&r0) + pj.at(&r1));
            let m = xi.cross(&f.force) - xj.cross(&f.force) + 2.0 * f.moment;
            assert!(
                m.norm() <= 1e-15 * f.force.norm().max(1e-300) * 10.0,
                "{m:?}"
            );
        }
        assert!(found > 0, "no pair in contact");
    }

    #[test]
    fn self_contact_skips_neighbours_along_the_rod() {
        let (mut c, r) = two_rods();
        c.points.truncate(c.split);
        c.split = c.points.len();
        assert!(c.is_self());
        // Rod A is straight: no pair of it is both allowed and touching.
        assert!(c.candidates(&r, 0.0).is_empty());
        assert!(!c.allowed(0, 2) && c.allowed(0, 10));
    }
}
