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
//!
//! The **elastic-stick** law ([`FrictionLaw::Stick`]) holds without creep instead: a node in
//! contact carries an [`Anchor`] (a point and the obstacle's normal `n_a` there, in the
//! obstacle's frame) and the stick energy `E = ½ k_t ℓ |P_a(x − a)|²` (`P_a = I − n_a n_aᵀ`),
//! part of the contact energy. With the spring force `s = k_t ℓ P_a(x − a)` at the start of
//! the step (`s₀`) and its end-of-step trial `s_tr = k_t ℓ P_a(x₁ − a₀)`, the end force is
//! `s₁ = s_tr` while `|s_tr| ≤ R = max(μN, −s₀·t̂)` (`t̂ = s_tr/|s_tr|`, `N` the step's normal
//! force), else `s₁ = R t̂` with the anchor moved by `Δa = (|s_tr| − R)/(k_t ℓ) t̂` (return
//! map). The node feels `−½(s₀ + s₁)`, whose work plus `ΔE` is `−D_f`,
//! `D_f = ½(s₀ + s₁)·Δa = ½|Δa|(s₀·t̂ + R) ≥ 0` by the choice of `R`.

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

/// How an obstacle's friction acts (with `friction` > 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrictionLaw {
    /// Regularized Coulomb on the mean tangential velocity (regularization speed
    /// [`Obstacle::slip`]): a node below its slip load creeps at a speed of order `ε`.
    Regularized,
    /// Elastic stick: a tangential spring of stiffness `stiffness` (N/m², per unit rod
    /// length, as the penalty) to an anchor that slips when the spring force exceeds `μN`.
    Stick {
        /// Tangential stiffness `k_t` per unit rod length.
        stiffness: f64,
    },
}

/// The stick point of a contact node under the elastic-stick law, in the obstacle's frame
/// (positions relative to its offset `p(t)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Anchor {
    /// The anchor point (on the obstacle's surface when placed).
    pub point: V3,
    /// The obstacle's unit normal there: the spring acts in the plane normal to it.
    pub normal: V3,
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
    /// Regularization speed `ε` (m/s) of the regularized friction law: below it friction
    /// is viscous.
    pub slip: f64,
    /// The friction law.
    pub law: FrictionLaw,
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
    /// The node's anchor after the step (elastic-stick law; `None` otherwise or out of
    /// contact).
    pub anchor: Option<Anchor>,
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

    /// Whether this obstacle keeps anchors (elastic-stick law with friction).
    pub fn has_anchors(&self) -> bool {
        self.friction > 0.0 && matches!(self.law, FrictionLaw::Stick { .. })
    }

    /// Unit outward normal of the surface at `x` (obstacle frame): the gap's gradient.
    pub fn normal_at(&self, x: &V3) -> V3 {
        let g = match &self.shape {
            Shape::Plane { normal, .. } => return *normal,
            Shape::Sphere { center, .. } => x - center,
            Shape::Cylinder { point, axis, .. } => {
                let d = x - point;
                d - axis * axis.dot(&d)
            }
        };
        let n = g.norm();
        if n > 0.0 {
            g / n
        } else {
            V3::zeros()
        }
    }

    /// A fresh anchor for node `n` at `x` (obstacle frame): the surface point below it
    /// and the normal there (zero stick energy).
    pub fn anchor_at(&self, n: &ContactNode, x: &V3) -> Anchor {
        let m = self.normal_at(x);
        Anchor {
            point: x - m * (self.gap(n, x) + n.radius),
            normal: m,
        }
    }

    /// Anchors of the nodes in contact or on the surface (gap below `1e-6 ρ`, the scene
    /// check's tolerance) at positions `r` and time `t` (the initial state's): a rod laid
    /// on an obstacle sticks from its first step. Empty unless the obstacle keeps anchors.
    pub fn initial_anchors(&self, r: &[V3], t: f64) -> Vec<Option<Anchor>> {
        if !self.has_anchors() {
            return Vec::new();
        }
        let p = self.offset(t);
        self.nodes
            .iter()
            .map(|n| {
                let x = r[n.node] - p;
                (self.gap(n, &x) < 1e-6 * n.radius).then(|| self.anchor_at(n, &x))
            })
            .collect()
    }

    /// Tangential stiffness `k_t ℓ` of node `n` (zero without the stick law).
    fn stick_stiffness(&self, n: &ContactNode) -> f64 {
        match self.law {
            FrictionLaw::Stick { stiffness } => stiffness * n.length,
            FrictionLaw::Regularized => 0.0,
        }
    }

    /// Stick energy `½ k_t ℓ |P_a(x − a)|²` of node `n` at `x` (obstacle frame).
    pub fn stick_energy_at(&self, n: &ContactNode, x: &V3, a: &Anchor) -> f64 {
        let d = x - a.point;
        let t = d - a.normal * a.normal.dot(&d);
        0.5 * self.stick_stiffness(n) * t.norm_squared()
    }

    /// Total stick energy of the obstacle's anchored nodes at positions `r`, time `t`
    /// (`anchors` per contact node; missing entries hold none).
    pub fn stick_energy(&self, r: &[V3], t: f64, anchors: &[Option<Anchor>]) -> f64 {
        if anchors.is_empty() {
            return 0.0;
        }
        let p = self.offset(t);
        self.nodes
            .iter()
            .zip(anchors)
            .filter_map(|(n, a)| {
                a.as_ref()
                    .map(|a| self.stick_energy_at(n, &(r[n.node] - p), a))
            })
            .sum()
    }

    /// Force of the obstacle on node `n` over the step `x0 → x1` of length `dt`, with its
    /// Jacobian with respect to `x1` when `jacobian` is set. `anchor` is the node's anchor
    /// at the start of the step (elastic-stick law only).
    pub fn node_force(
        &self,
        n: &ContactNode,
        x0: &V3,
        x1: &V3,
        dt: f64,
        jacobian: bool,
        anchor: Option<&Anchor>,
    ) -> NodeContact {
        let c = self.stiffness * n.length;
        let mut out = NodeContact {
            force: V3::zeros(),
            jacobian: M3::zeros(),
            friction_work: 0.0,
            anchor: None,
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
        if self.has_anchors() {
            self.stick_force(n, x0, x1, jacobian, anchor, (q, dq, g, dg), &mut out);
            return out;
        }
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

    /// The normal force and the elastic-stick friction of [`Self::node_force`]: `normal`
    /// is `(q, ∂q/∂x₁, G, ∂G/∂x₁)` of the normal force `−q G`.
    #[allow(clippy::too_many_arguments)]
    fn stick_force(
        &self,
        n: &ContactNode,
        x0: &V3,
        x1: &V3,
        jacobian: bool,
        anchor: Option<&Anchor>,
        normal: (f64, nalgebra::RowVector3<f64>, V3, M3),
        out: &mut NodeContact,
    ) {
        let (q, dq, g, dg) = normal;
        if q != 0.0 {
            out.force = -q * g;
            if jacobian {
                out.jacobian = -(g * dq) - q * dg;
            }
        }
        let in_contact = self.gap(n, x1) < 0.0;
        let Some(a) = anchor else {
            // A node that comes into contact is anchored where it lands (no friction over
            // the step that brings it).
            out.anchor = in_contact.then(|| self.anchor_at(n, x1));
            return;
        };
        let ct = self.stick_stiffness(n);
        let m = a.normal;
        let p = M3::identity() - m * m.transpose();
        // Normal force magnitude N = −q|G| and its derivative.
        let gn = g.norm();
        let (big_n, dn) = if q < 0.0 && gn > 0.0 {
            let mg = g / gn;
            (-q * gn, -gn * dq - q * (mg.transpose() * dg))
        } else {
            (0.0, nalgebra::RowVector3::zeros())
        };
        let mu = self.friction;
        let s0 = ct * (p * (x0 - a.point));
        let s_tr = ct * (p * (x1 - a.point));
        let str_n = s_tr.norm();
        // (s1, ∂s1/∂x1, Δa, D_f = ½(s₀ + s₁)·Δa = ½|Δa|(R + s₀·t̂), in the form that is
        // ≥ 0 in floating point too.)
        let (s1, ds1, da, d_f) = {
            let t = if str_n > 0.0 {
                s_tr / str_n
            } else {
                V3::zeros()
            };
            let back = -s0.dot(&t);
            let radius = (mu * big_n).max(back);
            if str_n <= radius {
                (s_tr, ct * p, V3::zeros(), 0.0)
            } else {
                // Return map: the end force on the slip radius along the trial.
                let pt = M3::identity() - t * t.transpose();
                let dt_dx = pt * p * (ct / str_n);
                let dr = if mu * big_n >= back {
                    mu * dn
                } else {
                    -(s0.transpose() * dt_dx)
                };
                let ds = t * dr + radius * dt_dx;
                let lam = (str_n - radius) / ct;
                (radius * t, ds, t * lam, 0.5 * lam * (radius - back))
            }
        };
        out.force -= 0.5 * (s0 + s1);
        if jacobian {
            out.jacobian -= 0.5 * ds1;
        }
        out.friction_work = d_f;
        if !in_contact {
            // The node leaves: its anchor is dropped with the spring's energy.
            out.friction_work += 0.5 * s1.norm_squared() / ct;
            return;
        }
        if da == V3::zeros() {
            out.anchor = Some(*a);
            return;
        }
        // A slipped anchor is carried to the surface below the node, in the plane of the
        // normal there, with the spring force turned into that plane at its magnitude: the
        // stick energy is unchanged. (A spring force turned by more than 60° in one step,
        // which no resolved slide produces, keeps the anchor's plane instead.)
        let m1 = self.normal_at(x1);
        let turned = s1 - m1 * m1.dot(&s1);
        let tn = turned.norm();
        let (m1, s1n) = if tn > 0.5 * s1.norm() && tn > 0.0 {
            (m1, turned * (s1.norm() / tn))
        } else if s1 == V3::zeros() {
            (m1, s1)
        } else {
            (m, s1)
        };
        out.anchor = Some(Anchor {
            point: x1 - s1n / ct - m1 * (self.gap(n, x1) + n.radius),
            normal: m1,
        });
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
            law: FrictionLaw::Regularized,
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
                let f = o.node_force(&n, &x0, &x1, 0.01, false, None);
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
                let f = o.node_force(&n, &x0, &x1, 0.01, true, None);
                let scale = f.jacobian.amax().max(1e-300);
                let h = 1e-7;
                let mut worst: f64 = 0.0;
                for j in 0..3 {
                    let (mut xp, mut xm) = (x1, x1);
                    xp[j] += h;
                    xm[j] -= h;
                    let fd = (o.node_force(&n, &x0, &xp, 0.01, false, None).force
                        - o.node_force(&n, &x0, &xm, 0.01, false, None).force)
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

    /// The three shapes with μ = 0.4 under the elastic-stick law (`k_t` = 3e4 N/m²).
    fn stick_obstacles() -> Vec<Obstacle> {
        obstacles()
            .into_iter()
            .filter(|o| o.friction > 0.0)
            .map(|o| Obstacle {
                law: FrictionLaw::Stick { stiffness: 3e4 },
                ..o
            })
            .collect()
    }

    /// The point at gap `g` nearest `x` (Newton on the gap).
    fn at_gap(o: &Obstacle, g: f64, x: V3) -> V3 {
        let n = &o.nodes[0];
        let mut x = x;
        for _ in 0..50 {
            let m = o.normal_at(&x);
            x -= m * (o.gap(n, &x) - g);
        }
        x
    }

    /// A deterministic stream of numbers in [−1, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
        fn v3(&mut self, scale: f64) -> V3 {
            V3::new(self.next(), self.next(), self.next()) * scale
        }
    }

    /// Random stick-law steps: `(x0, x1, anchor at x0)`, the start spring from nothing to
    /// beyond the slip radius, the end in contact or leaving it, the tangential move from
    /// 1e-5 to 1e-2 m; every fifth a reversal past the anchor.
    fn stick_steps(o: &Obstacle, count: usize, seed: u64) -> Vec<(V3, V3, Anchor)> {
        let n = &o.nodes[0];
        let mut rng = Lcg(seed);
        let base = V3::new(0.12, 0.05, 0.0);
        (0..count)
            .map(|k| {
                let x0 = at_gap(
                    o,
                    -0.002 - 0.008 * (0.5 + 0.5 * rng.next()),
                    base + rng.v3(0.02),
                );
                // The anchor somewhere near: its spring up to ~1.5 μN.
                let off = 10f64.powf(-5.0 + 2.8 * (0.5 + 0.5 * rng.next()));
                let a = o.anchor_at(n, &at_gap(o, 0.0, x0 + rng.v3(off)));
                let g1 = if k % 7 == 6 {
                    0.004
                } else {
                    -0.002 - 0.008 * (0.5 + 0.5 * rng.next())
                };
                let mv = 10f64.powf(-5.0 + 3.0 * (0.5 + 0.5 * rng.next()));
                let x1 = if k % 5 == 4 {
                    // A reversal: past the anchor to the other side (with a start spring
                    // beyond μN, the reversal radius −s₀·t̂ > μN).
                    let a = o.anchor_at(n, &at_gap(o, 0.0, x0 + rng.v3(6e-3)));
                    let d = x0 - a.point;
                    let d = d - a.normal * a.normal.dot(&d);
                    return (x0, at_gap(o, g1, x0 - 2.1 * d + rng.v3(1e-4)), a);
                } else {
                    at_gap(o, g1, x0 + rng.v3(mv))
                };
                (x0, x1, a)
            })
            .collect()
    }

    #[test]
    fn stick_friction_closes_the_energy_balance_and_only_dissipates() {
        for o in stick_obstacles() {
            let n = o.nodes[0];
            let (mut sticks, mut slips, mut leaves, mut backs) = (0, 0, 0, 0);
            let mut worst: f64 = 0.0;
            for (x0, x1, a) in stick_steps(&o, 400, 7) {
                let f = o.node_force(&n, &x0, &x1, 0.01, false, Some(&a));
                let e0 = o.energy_at(&n, &x0) + o.stick_energy_at(&n, &x0, &a);
                let e1 = o.energy_at(&n, &x1)
                    + f.anchor.map_or(0.0, |a1| o.stick_energy_at(&n, &x1, &a1));
                let work = f.force.dot(&(x1 - x0));
                let miss = work + (e1 - e0) + f.friction_work;
                let scale = e0.max(e1).max(f.friction_work).max(1e-30);
                worst = worst.max(miss.abs() / scale);
                assert!(
                    // Measured ≤ 2.3e-13 relative (sphere).
                    miss.abs() <= 1e-12 * scale,
                    "{}: work {work:e}, ΔE {:e}, D {:e}",
                    o.shape.name(),
                    e1 - e0,
                    f.friction_work
                );
                assert!(f.friction_work >= 0.0, "{}: D < 0", o.shape.name());
                match f.anchor {
                    None => leaves += 1,
                    Some(a1) if a1 == a => sticks += 1,
                    Some(_) => {
                        slips += 1;
                        // On the reversal radius −s₀·t̂ > μN?
                        let ct = o.stick_stiffness(&n);
                        let pm = M3::identity() - a.normal * a.normal.transpose();
                        let (s0, s_tr) = (ct * (pm * (x0 - a.point)), ct * (pm * (x1 - a.point)));
                        let bare = Obstacle {
                            friction: 0.0,
                            ..o.clone()
                        };
                        let big_n = bare
                            .node_force(&n, &x0, &x1, 0.01, false, None)
                            .force
                            .norm();
                        if -s0.dot(&s_tr.normalize()) > o.friction * big_n {
                            backs += 1;
                        }
                    }
                }
            }
            eprintln!(
                "{}: stick {sticks}, slip {slips} ({backs} on the reversal radius), leave {leaves}; balance {worst:.1e}",
                o.shape.name()
            );
            assert!(
                sticks > 20 && slips > 20 && leaves > 20 && backs > 0,
                "{sticks} {slips} {leaves} {backs}"
            );
        }
    }

    #[test]
    fn stick_friction_end_force_is_on_the_coulomb_radius_when_slipping() {
        for o in stick_obstacles() {
            let n = o.nodes[0];
            let base = V3::new(0.12, 0.05, 0.0);
            let x0 = at_gap(&o, -0.005, base);
            let a = o.anchor_at(&n, &x0);
            // A long slide: the end force is μN along the trial, N the step's normal force.
            let x1 = at_gap(&o, -0.005, x0 + V3::new(0.03, -0.01, 0.0));
            let f = o.node_force(&n, &x0, &x1, 0.01, false, Some(&a));
            let frictionless = Obstacle {
                friction: 0.0,
                ..o.clone()
            };
            let fn_ = frictionless
                .node_force(&n, &x0, &x1, 0.01, false, None)
                .force;
            let a1 = f.anchor.unwrap();
            let s1 = (2.0 * o.stick_energy_at(&n, &x1, &a1) * o.stick_stiffness(&n)).sqrt();
            let rel = (s1 - o.friction * fn_.norm()).abs() / (o.friction * fn_.norm());
            eprintln!("{}: |s1|/μN − 1 = {rel:.1e}", o.shape.name());
            assert!(rel < 1e-12, "{}: {rel:e}", o.shape.name());
        }
    }

    #[test]
    fn stick_friction_jacobian_matches_finite_differences() {
        for o in stick_obstacles() {
            let n = o.nodes[0];
            let mut worst_case: f64 = 0.0;
            let mut checked = 0;
            for (x0, x1, a) in stick_steps(&o, 200, 11) {
                let f = o.node_force(&n, &x0, &x1, 0.01, true, Some(&a));
                let h = 1e-8;
                let scale = f.jacobian.amax().max(1e-300);
                let fd_col = |j: usize, h: f64| {
                    let (mut xp, mut xm) = (x1, x1);
                    xp[j] += h;
                    xm[j] -= h;
                    let fp = o.node_force(&n, &x0, &xp, 0.01, false, Some(&a));
                    let fm = o.node_force(&n, &x0, &xm, 0.01, false, Some(&a));
                    // Both sides on the same branch (stick/slip, in/out of contact).
                    let same = |g: &NodeContact| {
                        (g.anchor == Some(a), g.anchor.is_some())
                            == (f.anchor == Some(a), f.anchor.is_some())
                    };
                    (same(&fp) && same(&fm)).then(|| (fp.force - fm.force) / (2.0 * h))
                };
                let mut worst: f64 = 0.0;
                let mut smooth = true;
                for j in 0..3 {
                    match fd_col(j, h) {
                        Some(fd) => worst = worst.max((fd - f.jacobian.column(j)).amax()),
                        None => smooth = false,
                    }
                }
                if !smooth {
                    continue;
                }
                checked += 1;
                worst_case = worst_case.max(worst / scale);
                assert!(
                    // Measured ≤ 4.8e-8 (central differences at h = 1e-8).
                    worst <= 5e-7 * scale,
                    "{}: jacobian off by {:e} (anchor {:?} → {:?})",
                    o.shape.name(),
                    worst / scale,
                    a,
                    f.anchor
                );
            }
            eprintln!(
                "{}: stick-law jacobian vs FD {worst_case:.1e} over {checked} steps",
                o.shape.name()
            );
            assert!(checked > 150);
        }
    }
}
