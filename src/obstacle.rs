//! Rigid obstacles (planes, spheres, cylinders) and the contact of rod nodes with them.
//!
//! Each contact node `a` (tributary length `ℓ`, contact radius `ρ`) has a gap `g(x)` to
//! the obstacle's surface — `n·(x − p) − ρ` for a plane, `|x − c| − (R + ρ)` for a sphere,
//! `|P(x − c)| − (R + ρ)` for a cylinder (`P = I − a aᵀ`) — and the penalty energy
//! `V = ½ k ℓ g²` while `g < 0` (zero otherwise). Over a step `x_n → x_{n+1}` the node
//! feels the **discrete gradient** of `V` in the variable it is quadratic in: the plane's
//! `g` is linear in `x`, the sphere's and cylinder's `s = (x − c)ᵀQ(x − c)` quadratic, so
//!
//! ```text
//! plane:    F = −[V(g₁) − V(g₀)]/(g₁ − g₀) n
//! quadric:  F = −[W(s₁) − W(s₀)]/(s₁ − s₀) · 2Q(x_½ − c)        (W(s) = V(√s − R − ρ))
//! ```
//!
//! and `F·(x₁ − x₀) = −(V₁ − V₀)` exactly: the contact is energy-consistent for every
//! scheme of the family, so EM conserves `K + V_strain + V_contact` to round-off. Both
//! quotients have closed forms without cancellation (both ends in contact:
//! `½kℓ(g₀ + g₁)` and `½kℓ(1 − 2R'/(√s₀ + √s₁))`).
//!
//! Friction is a regularized Coulomb law on the node's mean tangential velocity
//! `v_t = (I − m mᵀ) (x₁ − x₀)/Δt` (`m` the contact normal at the mid-point):
//! `f = −μ N v_t / √(|v_t|² + ε²)`, `N = |F|`. Its work over the step is
//! `−μ N Δt |v_t|²/√(|v_t|² + ε²) ≤ 0`: friction only ever removes energy.

use nalgebra::{Matrix3, Vector3};

use crate::table::{Ramp, TimeTable};

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

/// The surface of a rigid obstacle. Rods touch it from outside (the side `normal` points
/// to, for a plane).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// The plane through `point` with unit `normal` (pointing to the free side).
    Plane {
        /// A point of the plane.
        point: V3,
        /// Unit normal, towards the free side.
        normal: V3,
    },
    /// A solid sphere.
    Sphere {
        /// Centre.
        center: V3,
        /// Radius.
        radius: f64,
    },
    /// A solid, infinitely long circular cylinder.
    Cylinder {
        /// A point of the axis.
        point: V3,
        /// Unit axis direction.
        axis: V3,
        /// Radius.
        radius: f64,
    },
}

impl Shape {
    /// The shape's name as the scene format spells it.
    pub fn name(&self) -> &'static str {
        match self {
            Shape::Plane { .. } => "plane",
            Shape::Sphere { .. } => "sphere",
            Shape::Cylinder { .. } => "cylinder",
        }
    }
}

/// One rod node that can touch an obstacle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactNode {
    /// Node index.
    pub node: usize,
    /// Contact radius `ρ` of the rod at the node (the largest of its elements').
    pub radius: f64,
    /// Tributary length `ℓ` (half of each adjacent element's length).
    pub length: f64,
}

/// A prescribed translation of an obstacle: `p(t) = (s(t) − s(0)) · displacement`.
#[derive(Clone, Debug, PartialEq)]
pub struct ObstacleMotion {
    /// Displacement at factor 1.
    pub displacement: V3,
    /// Factor table `s(t)`.
    pub table: TimeTable,
    /// Interpolation of the table.
    pub ramp: Ramp,
}

/// A rigid obstacle (fixed, or translated by a time table) and the nodes that can touch
/// it.
#[derive(Clone, Debug, PartialEq)]
pub struct Obstacle {
    /// Geometry.
    pub shape: Shape,
    /// Penalty stiffness `k` per unit rod length (N/m²): the contact line pressure is
    /// `k` times the penetration.
    pub stiffness: f64,
    /// Coulomb friction coefficient `μ` (0: frictionless).
    pub friction: f64,
    /// Regularization speed `ε` (m/s) of the friction law: below it friction is viscous.
    pub slip: f64,
    /// Nodes that can touch it.
    pub nodes: Vec<ContactNode>,
    /// Its prescribed translation (`None`: fixed).
    pub motion: Option<ObstacleMotion>,
}

/// The force of one obstacle on one node over a step and its derivative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeContact {
    /// Total force (normal + friction) on the node.
    pub force: V3,
    /// `∂force/∂x₁` (zero when not requested).
    pub jacobian: M3,
    /// Energy the friction removed over the step (≥ 0).
    pub friction_work: f64,
}

/// `(value, ∂value/∂y₁)` of the difference quotient `[V(y₁) − V(y₀)]/(y₁ − y₀)` of the
/// penalty `V(y) = ½ c y²` for `y < 0`.
fn quotient_linear(c: f64, y0: f64, y1: f64) -> (f64, f64) {
    let v = |y: f64| if y < 0.0 { 0.5 * c * y * y } else { 0.0 };
    match (y0 < 0.0, y1 < 0.0) {
        (true, true) => (0.5 * c * (y0 + y1), 0.5 * c),
        (false, false) => (0.0, 0.0),
        _ => {
            let d = y1 - y0;
            let q = (v(y1) - v(y0)) / d;
            let dv1 = if y1 < 0.0 { c * y1 } else { 0.0 };
            (q, (dv1 - q) / d)
        }
    }
}

/// `(value, ∂value/∂s₁)` of `[W(s₁) − W(s₀)]/(s₁ − s₀)` for `W(s) = ½ c (√s − R)²` while
/// `√s < R`.
pub(crate) fn quotient_quadric(c: f64, r: f64, s0: f64, s1: f64) -> (f64, f64) {
    let (a0, a1) = (s0.max(0.0).sqrt(), s1.max(0.0).sqrt());
    let w = |a: f64| {
        if a < r {
            0.5 * c * (a - r) * (a - r)
        } else {
            0.0
        }
    };
    match (a0 < r, a1 < r) {
        (true, true) => {
            let sum = a0 + a1;
            let q = 0.5 * c * (1.0 - 2.0 * r / sum);
            // ∂/∂s₁ = c R/(a₀ + a₁)² · ∂a₁/∂s₁.
            let dq = if a1 > 0.0 {
                c * r / (sum * sum) / (2.0 * a1)
            } else {
                0.0
            };
            (q, dq)
        }
        (false, false) => (0.0, 0.0),
        _ => {
            let d = s1 - s0;
            let q = (w(a1) - w(a0)) / d;
            let dw1 = if a1 < r && a1 > 0.0 {
                0.5 * c * (a1 - r) / a1
            } else {
                0.0
            };
            (q, (dw1 - q) / d)
        }
    }
}

impl Obstacle {
    /// How far the obstacle has moved at time `t` (zero when fixed). The shape's
    /// coordinates are those at `s(0)`; a moving obstacle's geometry is the shape shifted
    /// by this offset, so a node at `x` sees the fixed shape at `x − p(t)`.
    pub fn offset(&self, t: f64) -> V3 {
        self.motion.as_ref().map_or_else(V3::zeros, |m| {
            m.displacement * (m.table.eval_ramped(m.ramp, t) - m.table.eval_ramped(m.ramp, 0.0))
        })
    }

    /// Penalty energy of node `n` at position `x` (relative to the obstacle's current
    /// place).
    pub fn energy_at(&self, n: &ContactNode, x: &V3) -> f64 {
        let c = self.stiffness * n.length;
        let g = self.gap(n, x);
        if g < 0.0 {
            0.5 * c * g * g
        } else {
            0.0
        }
    }

    /// Gap `g(x)` of node `n` at `x` (negative: penetrating).
    pub fn gap(&self, n: &ContactNode, x: &V3) -> f64 {
        match &self.shape {
            Shape::Plane { point, normal } => normal.dot(&(x - point)) - n.radius,
            Shape::Sphere { center, radius } => (x - center).norm() - (radius + n.radius),
            Shape::Cylinder {
                point,
                axis,
                radius,
            } => {
                let d = x - point;
                (d - axis * axis.dot(&d)).norm() - (radius + n.radius)
            }
        }
    }

    /// Total penalty energy of the obstacle's nodes at positions `r` and time `t`.
    pub fn energy(&self, r: &[V3], t: f64) -> f64 {
        let p = self.offset(t);
        self.nodes
            .iter()
            .map(|n| self.energy_at(n, &(r[n.node] - p)))
            .sum()
    }

    /// `(Q, c)` of a quadric obstacle (`s = (x − c)ᵀ Q (x − c)`), `None` for a plane.
    fn quadric(&self) -> Option<(M3, V3, f64)> {
        match &self.shape {
            Shape::Plane { .. } => None,
            Shape::Sphere { center, radius } => Some((M3::identity(), *center, *radius)),
            Shape::Cylinder {
                point,
                axis,
                radius,
            } => Some((M3::identity() - axis * axis.transpose(), *point, *radius)),
        }
    }

    /// Force of the obstacle on node `n` over the step `x0 → x1` of length `dt`, with its
    /// Jacobian with respect to `x1` when `jacobian` is set.
    pub fn node_force(
        &self,
        n: &ContactNode,
        x0: &V3,
        x1: &V3,
        dt: f64,
        jacobian: bool,
    ) -> NodeContact {
        let c = self.stiffness * n.length;
        let mut out = NodeContact {
            force: V3::zeros(),
            jacobian: M3::zeros(),
            friction_work: 0.0,
        };
        // Normal part: F = −q G, with G the gradient of the invariant at the mid-point.
        // `dq` is ∂q/∂x₁ (a row), `dg` = ∂G/∂x₁.
        let (q, dq, g, dg) = match self.quadric() {
            None => {
                let Shape::Plane { point, normal } = &self.shape else {
                    unreachable!()
                };
                let y = |x: &V3| normal.dot(&(x - point)) - n.radius;
                let (q, dq1) = quotient_linear(c, y(x0), y(x1));
                (q, normal.transpose() * dq1, *normal, M3::zeros())
            }
            Some((qm, center, radius)) => {
                let s = |x: &V3| (x - center).dot(&(qm * (x - center)));
                let (q, dq1) = quotient_quadric(c, radius + n.radius, s(x0), s(x1));
                let xm = 0.5 * (x0 + x1);
                let ds1 = 2.0 * (qm * (x1 - center));
                (q, ds1.transpose() * dq1, 2.0 * (qm * (xm - center)), qm)
            }
        };
        if q == 0.0 {
            return out;
        }
        out.force = -q * g;
        if jacobian {
            out.jacobian = -(g * dq) - q * dg;
        }
        if self.friction == 0.0 {
            return out;
        }
        // Friction on the mean tangential velocity.
        let gn = g.norm();
        if gn == 0.0 {
            return out;
        }
        let m = g / gn;
        let big_n = -q * gn; // q ≤ 0 in contact
        if big_n <= 0.0 {
            return out;
        }
        let v = (x1 - x0) / dt;
        let vt = v - m * m.dot(&v);
        let eps = self.slip;
        let sn = (vt.norm_squared() + eps * eps).sqrt();
        let w = vt / sn;
        let mu = self.friction;
        let ft = -mu * big_n * w;
        out.force += ft;
        out.friction_work = mu * big_n * dt * vt.norm_squared() / sn;
        if jacobian {
            // ∂N/∂x₁ = −|G| ∂q − q mᵀ ∂G;  ∂m/∂x₁ = (I − m mᵀ) ∂G/|G|.
            let dn = -gn * dq - q * (m.transpose() * dg);
            let dm = (M3::identity() - m * m.transpose()) * dg / gn;
            let dvt = M3::identity() / dt
                - dm * m.dot(&v)
                - m * (v.transpose() * dm + m.transpose() / dt);
            let dw = (M3::identity() - w * w.transpose()) * dvt / sn;
            out.jacobian += -mu * (w * dn + big_n * dw);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obstacles() -> Vec<Obstacle> {
        let nodes = vec![ContactNode {
            node: 0,
            radius: 0.05,
            length: 0.2,
        }];
        let mk = |shape: Shape, friction: f64| Obstacle {
            shape,
            stiffness: 3e4,
            friction,
            slip: 0.05,
            nodes: nodes.clone(),
            motion: None,
        };
        let mut out = Vec::new();
        for mu in [0.0, 0.4] {
            out.push(mk(
                Shape::Plane {
                    point: V3::new(0.1, -0.2, 0.3),
                    normal: V3::new(0.2, 0.3, 1.0).normalize(),
                },
                mu,
            ));
            out.push(mk(
                Shape::Sphere {
                    center: V3::new(0.1, 0.0, -1.0),
                    radius: 1.0,
                },
                mu,
            ));
            out.push(mk(
                Shape::Cylinder {
                    point: V3::new(0.0, 0.3, -0.5),
                    axis: V3::new(1.0, 0.2, 0.1).normalize(),
                    radius: 0.5,
                },
                mu,
            ));
        }
        out
    }

    /// Start and end points in contact, entering, leaving and apart.
    fn steps(o: &Obstacle) -> Vec<(V3, V3)> {
        let n = &o.nodes[0];
        // A point at gap g along the contact normal near a base point.
        let base = V3::new(0.12, 0.05, 0.0);
        let project = |g: f64, t: V3| -> V3 {
            let mut x = base + t;
            for _ in 0..50 {
                let h = 1e-7;
                let gr = V3::from_fn(|i, _| {
                    let mut xp = x;
                    xp[i] += h;
                    (o.gap(n, &xp) - o.gap(n, &x)) / h
                });
                x -= gr * (o.gap(n, &x) - g) / gr.norm_squared();
            }
            x
        };
        let t1 = V3::new(0.01, -0.02, 0.005);
        vec![
            (project(-0.01, V3::zeros()), project(-0.004, t1)),
            (project(0.003, V3::zeros()), project(-0.008, t1)),
            (project(-0.006, V3::zeros()), project(0.002, t1)),
            (project(0.01, V3::zeros()), project(0.02, t1)),
            (project(-0.005, V3::zeros()), project(-0.005, V3::zeros())),
        ]
    }

    #[test]
    fn contact_work_equals_the_energy_change_and_friction_only_dissipates() {
        for o in obstacles() {
            let n = o.nodes[0];
            for (x0, x1) in steps(&o) {
                let f = o.node_force(&n, &x0, &x1, 0.01, false);
                let (e0, e1) = (o.energy_at(&n, &x0), o.energy_at(&n, &x1));
                let work = f.force.dot(&(x1 - x0));
                let miss = work + (e1 - e0) + f.friction_work;
                let scale = e0.max(e1).max(1e-30);
                eprintln!(
                    "{}: work balance {:.1e}",
                    o.shape.name(),
                    miss.abs() / scale
                );
                assert!(
                    // Measured ≤ 4.3e-14.
                    miss.abs() <= 4e-13 * scale,
                    "{} μ={}: work {work:e}, ΔV {:e}, friction {:e}",
                    o.shape.name(),
                    o.friction,
                    e1 - e0,
                    f.friction_work
                );
                assert!(f.friction_work >= 0.0);
                if o.friction > 0.0 && e0 + e1 > 0.0 && x1 != x0 {
                    assert!(f.friction_work > 0.0, "{}: no friction", o.shape.name());
                }
            }
        }
    }

    #[test]
    fn contact_jacobian_matches_finite_differences() {
        for o in obstacles() {
            let n = o.nodes[0];
            for (k, (x0, x1)) in steps(&o).into_iter().enumerate() {
                let f = o.node_force(&n, &x0, &x1, 0.01, true);
                let scale = f.jacobian.amax().max(1e-300);
                let h = 1e-7;
                let mut worst: f64 = 0.0;
                for j in 0..3 {
                    let (mut xp, mut xm) = (x1, x1);
                    xp[j] += h;
                    xm[j] -= h;
                    let fd = (o.node_force(&n, &x0, &xp, 0.01, false).force
                        - o.node_force(&n, &x0, &xm, 0.01, false).force)
                        / (2.0 * h);
                    worst = worst.max((fd - f.jacobian.column(j)).amax());
                }
                if f.force == V3::zeros() {
                    assert_eq!(f.jacobian, M3::zeros());
                    continue;
                }
                eprintln!("{}: jacobian vs FD {:.1e}", o.shape.name(), worst / scale);
                assert!(
                    // Measured ≤ 2.0e-8 (forward-difference truncation at the kinks).
                    worst <= 2e-7 * scale,
                    "{} μ={} step {k}: Jacobian off by {:e}",
                    o.shape.name(),
                    o.friction,
                    worst / scale
                );
            }
        }
    }
}
