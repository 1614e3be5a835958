//! Contact between rods and of a rod with itself, in one of three models.
//!
//! **Sphere chains** (`model = "spheres"`). Each rod of a `[[contact]]` carries sample
//! points at fixed places along its elements (the nodes and, where an element is longer
//! than the contact radius `ρ`, points in between, at most `ρ` apart), each the centre of
//! a sphere of radius `ρ`. A point's position is the linear interpolation of its
//! element's end nodes, `x = (1 − ξ) r₀ + ξ r₁`. Two points `i`, `j` (of different rods,
//! or of one rod and more than `2(ρᵢ + ρⱼ)` apart along it) store the penalty energy
//! `½ K (|d| − ρᵢ − ρⱼ)²` while `|d| < ρᵢ + ρⱼ`, `d = xᵢ − xⱼ`,
//! `K = k · min(spacingᵢ, spacingⱼ)` (`k` per unit length, N/m²).
//!
//! **Line contact** (`model = "line"`). The energy is a double integral over the two
//! rods' centrelines (piecewise linear) of a pair potential of the squared distance,
//!
//! ```text
//! V = ∫∫ c (R² − |x(s) − y(t)|²)²₊ ds dt,   c = k/(4π R⁴),   R = ρᵢ + ρⱼ,
//! ```
//!
//! evaluated by the midpoint rule with `m = ⌈n h/ρ⌉` points per element of length `h`
//! (`n` points per contact radius, weights `w = h/m`): every quadrature pair is a
//! fixed-`ξ` pair `W(s) = c wᵢ wⱼ (R² − s)²₊`, `s = |d|²`. Two straight rods crossing at
//! an angle `θ` with centrelines `h = R − g` apart press with `F = k h (R² − h²)²/(2 R⁴
//! sin θ) ≈ 2 k g²/R` wherever along their elements they cross (to the quadrature's
//! corrugation, which falls with `n`); the surface has no bumps at the sphere spacing.
//!
//! **Smooth contact** (`model = "smooth"`, [`smooth`]): line contact whose quadrature
//! points lie on a quadratic B-spline of each rod's nodes (each a fixed combination of
//! three nodes) instead of on its polyline.
//!
//! In all three, over a step a pair exerts the discrete gradient of its energy in `s` (a
//! quadratic function of the node positions):
//!
//! ```text
//! Fᵢ = −[W(s₁) − W(s₀)]/(s₁ − s₀) · 2 d_½,   Fⱼ = −Fᵢ
//! ```
//!
//! so the pair's work equals the drop of its energy exactly (EM keeps `H` to round-off),
//! the forces are equal and opposite (L is kept exactly) and act along the mid-point
//! connecting vector at the mid-point positions (J is kept exactly: the nodal forces
//! `wₐ Fᵢ` at `r_a,½` have the moment `xᵢ,½ × Fᵢ − xⱼ,½ × Fᵢ = d_½ × Fᵢ = 0`). The line
//! model's quotient is a polynomial, `c wᵢ wⱼ (s₀ + s₁ − 2R²)` while both ends are in
//! contact, so it carries no cancellation as `s₁ → s₀`.

use nalgebra::{Matrix3, Vector3};

use crate::obstacle::quotient_quadric;

pub mod smooth;
pub use smooth::smooth_points;

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

/// Most nodes a sample point's position combines (a cubic B-spline with corrected control
/// points: six; the smooth model's quadratic: three).
pub const MAX_STENCIL: usize = 6;

/// The fixed nodes and weights whose combination `x = Σ wₐ rₐ` is a sample point's
/// position (`Σ wₐ = 1`). Iterates over its `(node, weight)` pairs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stencil {
    entries: [(usize, f64); MAX_STENCIL],
    len: usize,
}

impl Stencil {
    /// The linear interpolation `(1 − ξ) r_{n₀} + ξ r_{n₁}` of an element's end nodes.
    pub fn linear(nodes: [usize; 2], xi: f64) -> Self {
        Self::from_pairs(&[(nodes[0], 1.0 - xi), (nodes[1], xi)])
    }

    /// From `(node, weight)` pairs, at most [`MAX_STENCIL`] (kept as given, zeros too).
    ///
    /// # Panics
    /// With more than [`MAX_STENCIL`] pairs.
    pub fn from_pairs(pairs: &[(usize, f64)]) -> Self {
        assert!(
            pairs.len() <= MAX_STENCIL,
            "a stencil of {} nodes",
            pairs.len()
        );
        let mut entries = [(0, 0.0); MAX_STENCIL];
        entries[..pairs.len()].copy_from_slice(pairs);
        Self {
            entries,
            len: pairs.len(),
        }
    }

    /// The `(node, weight)` pairs.
    pub fn iter(&self) -> std::slice::Iter<'_, (usize, f64)> {
        self.entries[..self.len].iter()
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True without nodes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The combination `Σ wₐ rₐ`.
    #[inline]
    pub fn at(&self, r: &[V3]) -> V3 {
        self.iter().fold(V3::zeros(), |x, &(a, w)| x + w * r[a])
    }
}

impl IntoIterator for Stencil {
    type Item = (usize, f64);
    type IntoIter = std::iter::Take<std::array::IntoIter<(usize, f64), MAX_STENCIL>>;
    fn into_iter(self) -> Self::IntoIter {
        self.entries.into_iter().take(self.len)
    }
}

impl<'a> IntoIterator for &'a Stencil {
    type Item = &'a (usize, f64);
    type IntoIter = std::slice::Iter<'a, (usize, f64)>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// A contact sphere's centre on an element (or a quadrature point of line contact).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplePoint {
    /// The element's end nodes.
    pub nodes: [usize; 2],
    /// Position along the element (for spheres and line contact `x = (1 − ξ) r₀ + ξ r₁`;
    /// for the smooth model the curve parameter within the element).
    pub xi: f64,
    /// The nodes and weights of the position (the linear interpolation above, or the
    /// smooth model's B-spline weights over up to six nodes).
    pub stencil: Stencil,
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
        self.stencil.at(r)
    }

    /// The nodes and weights of the position.
    #[inline]
    pub fn weights(&self) -> Stencil {
        self.stencil
    }
}

/// How a `[[contact]]` represents the rods' surfaces.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ContactModel {
    /// Chains of contact spheres (the pair energy `½ K (|d| − ρᵢ − ρⱼ)²`).
    #[default]
    Spheres,
    /// Line contact: a midpoint quadrature of a smooth pair potential along both rods.
    Line,
    /// Line contact along a smooth (C¹) contact curve per rod: a quadratic B-spline of the
    /// nodes, so that a load is carried alike wherever along an element it acts.
    Smooth,
}

impl ContactModel {
    /// The scene-file name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Spheres => "spheres",
            Self::Line => "line",
            Self::Smooth => "smooth",
        }
    }
}

/// The line model's discrete-gradient quotient of `W(s) = c (b − s)²₊` between `s0` and
/// `s1`, and its derivative in `s1`: `c (s₀ + s₁ − 2b)` while both are inside (no
/// cancellation), the difference quotient across the boundary.
pub(crate) fn quotient_quartic(c: f64, b: f64, s0: f64, s1: f64) -> (f64, f64) {
    match (s0 < b, s1 < b) {
        (true, true) => (c * (s0 + s1 - 2.0 * b), c),
        (false, false) => (0.0, 0.0),
        _ => {
            let w = |s: f64| if s < b { c * (b - s) * (b - s) } else { 0.0 };
            let d = s1 - s0;
            let q = (w(s1) - w(s0)) / d;
            let dw1 = if s1 < b { -2.0 * c * (b - s1) } else { 0.0 };
            (q, (dw1 - q) / d)
        }
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
    /// Sphere chains or line contact.
    pub model: ContactModel,
    /// The sample points (sphere centres, or the line model's quadrature points with
    /// their weights in `spacing`).
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
    /// positions `r` (sweep and prune along the axis of the points' largest extent; for
    /// line contact over the elements first, see [`Self::candidates_by_element`]).
    pub fn candidates(&self, r: &[V3], reach: f64) -> Vec<(usize, usize)> {
        match self.model {
            ContactModel::Line => return self.candidates_by_element(r, reach),
            ContactModel::Smooth => return self.candidates_by_bounds(r, reach),
            ContactModel::Spheres => {}
        }
        let x: Vec<V3> = self.points.iter().map(|p| p.at(r)).collect();
        let Some(first) = x.first() else {
            return Vec::new();
        };
        let (lo, hi) = x
            .iter()
            .fold((*first, *first), |(lo, hi), v| (lo.inf(v), hi.sup(v)));
        let ax = (hi - lo).imax();
        let mut order: Vec<usize> = (0..x.len()).collect();
        order.sort_unstable_by(|&a, &b| x[a][ax].total_cmp(&x[b][ax]));
        let rmax = self.max_radius();
        let mut out = Vec::new();
        for (k, &i) in order.iter().enumerate() {
            // No point farther along the axis than `ρᵢ + ρ_max + reach` can touch `i`
            // (its distance is at least its distance along the axis).
            let window = self.points[i].radius + rmax + reach;
            for &j in &order[k + 1..] {
                if x[j][ax] - x[i][ax] >= window {
                    break;
                }
                let (a, b) = (i.min(j), i.max(j));
                let lim = self.points[a].radius + self.points[b].radius + reach;
                if (x[a] - x[b]).norm_squared() < lim * lim && self.allowed(a, b) {
                    out.push((a, b));
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// The runs of points on one element: `(first, end)` index ranges.
    pub(crate) fn elements(&self) -> Vec<(usize, usize)> {
        let mut out: Vec<(usize, usize)> = Vec::new();
        for (i, p) in self.points.iter().enumerate() {
            match out.last_mut() {
                Some(last) if self.points[last.0].nodes == p.nodes && last.1 == i => last.1 += 1,
                _ => out.push((i, i + 1)),
            }
        }
        out
    }

    /// Line contact's pair search: elements whose mid-points are within their half-lengths
    /// plus `2 ρ_max + reach` (a uniform grid over the elements), then the points of each
    /// within `2 ρ_max + reach` of the other element, then the pairs of those points that
    /// are allowed and closer than `ρᵢ + ρⱼ + reach`. Two points that close lie each
    /// within that distance of the other's element, so the search misses none.
    pub fn candidates_by_element(&self, r: &[V3], reach: f64) -> Vec<(usize, usize)> {
        let els = self.elements();
        let lim = 2.0 * self.max_radius() + reach;
        let seg: Vec<(V3, V3, V3, f64)> = els
            .iter()
            .map(|&(a, _)| {
                let [n0, n1] = self.points[a].nodes;
                let (p0, p1) = (r[n0], r[n1]);
                (p0, p1, 0.5 * (p0 + p1), 0.5 * (p1 - p0).norm())
            })
            .collect();
        let half_max = seg.iter().fold(0.0f64, |m, s| m.max(s.3));
        let cell = 2.0 * half_max + lim;
        let key = |v: &V3| -> [i64; 3] { std::array::from_fn(|c| (v[c] / cell).floor() as i64) };
        let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> =
            std::collections::HashMap::new();
        for (e, s) in seg.iter().enumerate() {
            grid.entry(key(&s.2)).or_default().push(e);
        }
        let x: Vec<V3> = self.points.iter().map(|p| p.at(r)).collect();
        // Points of element `e` within `lim` of element `f`'s segment.
        let near = |e: usize, f: usize| -> Vec<usize> {
            let (p0, p1, _, _) = seg[f];
            let u = p1 - p0;
            let uu = u.norm_squared();
            (els[e].0..els[e].1)
                .filter(|&i| {
                    let w = x[i] - p0;
                    let t = if uu > 0.0 {
                        (w.dot(&u) / uu).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    (w - t * u).norm_squared() < lim * lim
                })
                .collect()
        };
        let mut out = Vec::new();
        for (e, se) in seg.iter().enumerate() {
            let k = key(&se.2);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                            continue;
                        };
                        for &f in list {
                            if f < e {
                                continue;
                            }
                            let two_rods = !self.is_self();
                            if two_rods && (els[e].0 < self.split) == (els[f].0 < self.split) {
                                continue;
                            }
                            let sf = &seg[f];
                            let gap = (se.2 - sf.2).norm() - se.3 - sf.3;
                            if gap >= lim {
                                continue;
                            }
                            let (a, b) = (near(e, f), near(f, e));
                            for &i in &a {
                                for &j in &b {
                                    let (i, j) = (i.min(j), i.max(j));
                                    if i == j || !self.allowed(i, j) {
                                        continue;
                                    }
                                    let l = self.points[i].radius + self.points[j].radius + reach;
                                    if (x[i] - x[j]).norm_squared() < l * l {
                                        out.push((i, j));
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The pair's energy `W(s)` at squared distance `s`.
    fn pair_w(&self, i: usize, j: usize, s: f64) -> f64 {
        let (a, b) = (&self.points[i], &self.points[j]);
        let reach = a.radius + b.radius;
        match self.model {
            ContactModel::Spheres => {
                let dist = s.sqrt();
                if dist < reach {
                    0.5 * self.stiffness * a.spacing.min(b.spacing) * (dist - reach).powi(2)
                } else {
                    0.0
                }
            }
            ContactModel::Line | ContactModel::Smooth => {
                let b2 = reach * reach;
                if s < b2 {
                    self.line_c(i, j) * (b2 - s) * (b2 - s)
                } else {
                    0.0
                }
            }
        }
    }

    /// The line model's pair coefficient `c wᵢ wⱼ`, `c = k/(4π R⁴)`.
    fn line_c(&self, i: usize, j: usize) -> f64 {
        let (a, b) = (&self.points[i], &self.points[j]);
        let reach = a.radius + b.radius;
        self.stiffness * a.spacing * b.spacing / (4.0 * std::f64::consts::PI * reach.powi(4))
    }

    /// The discrete-gradient quotient `[W(s₁) − W(s₀)]/(s₁ − s₀)` of pair `(i, j)` and its
    /// derivative in `s₁`.
    fn quotient(&self, i: usize, j: usize, s0: f64, s1: f64) -> (f64, f64) {
        let (a, b) = (&self.points[i], &self.points[j]);
        let reach = a.radius + b.radius;
        match self.model {
            ContactModel::Spheres => {
                quotient_quadric(self.stiffness * a.spacing.min(b.spacing), reach, s0, s1)
            }
            ContactModel::Line | ContactModel::Smooth => {
                quotient_quartic(self.line_c(i, j), reach * reach, s0, s1)
            }
        }
    }

    /// Penalty energy of pair `(i, j)` at node positions `r`.
    pub fn pair_energy(&self, i: usize, j: usize, r: &[V3]) -> f64 {
        let s = (self.points[i].at(r) - self.points[j].at(r)).norm_squared();
        self.pair_w(i, j, s)
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
        let (pi, pj) = (&self.points[i], &self.points[j]);
        let d0 = pi.at(r0) - pj.at(r0);
        let d1 = pi.at(r1) - pj.at(r1);
        let (q, dq) = self.quotient(i, j, d0.norm_squared(), d1.norm_squared());
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
        let d0 = pi.at(r0) - pj.at(r0);
        let d1 = pi.at(r1) - pj.at(r1);
        let (q, _) = self.quotient(i, j, d0.norm_squared(), d1.norm_squared());
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
            stencil: Stencil::linear(nodes, xi),
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
            model: ContactModel::Spheres,
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

    /// Line contact between chains of elements (`chains[0]` on one rod, `chains[1]` on
    /// the other; one chain for self-contact), `n` points per contact radius `rho`, as the
    /// scene builder lays them out.
    fn line_contact(chains: &[Vec<usize>], r: &[V3], rho: f64, n: f64, k: f64) -> RodContact {
        let mut points = Vec::new();
        let mut split = 0;
        for (c, chain) in chains.iter().enumerate() {
            let mut arc = 0.0;
            for w in chain.windows(2) {
                let h = (r[w[1]] - r[w[0]]).norm();
                let m = (n * h / rho).ceil().max(1.0) as usize;
                for s in 0..m {
                    let xi = (s as f64 + 0.5) / m as f64;
                    points.push(SamplePoint {
                        nodes: [w[0], w[1]],
                        xi,
                        stencil: Stencil::linear([w[0], w[1]], xi),
                        radius: rho,
                        spacing: h / m as f64,
                        arc: arc + h * xi,
                    });
                }
                arc += h;
            }
            if c == 0 {
                split = points.len();
            }
        }
        RodContact {
            rods: vec!["a".into(), "b".into()],
            stiffness: k,
            friction: 0.0,
            slip: 1e-3,
            model: ContactModel::Line,
            split: if chains.len() == 1 {
                points.len()
            } else {
                split
            },
            points,
        }
    }

    /// Work, force sum and moment about the origin of all pairs' nodal forces over the
    /// step `r0 → r1`, each relative to the sum of its terms' magnitudes.
    pub(super) fn step_sums(c: &RodContact, r0: &[V3], r1: &[V3]) -> (f64, f64, f64) {
        let (mut work, mut f_sum, mut moment) = (0.0, V3::zeros(), V3::zeros());
        let (mut f_abs, mut m_abs) = (0.0, 0.0);
        for &(i, j) in &c.candidates(r0, 0.02) {
            let f = c.pair_force(i, j, r0, r1, false).force;
            for (p, sign) in [(i, 1.0), (j, -1.0)] {
                for (node, w) in c.points[p].weights() {
                    let fa = sign * w * f;
                    work += fa.dot(&(r1[node] - r0[node]));
                    f_sum += fa;
                    let m = (0.5 * (r0[node] + r1[node])).cross(&fa);
                    moment += m;
                    f_abs += fa.norm();
                    m_abs += m.norm();
                }
            }
        }
        (
            work,
            f_sum.norm() / f_abs.max(1e-300),
            moment.norm() / m_abs.max(1e-300),
        )
    }

    /// Over 200 random steps from `r0` (each node moved up to 0.2 ρ per axis, `seed`):
    /// the steps in contact, and the worst |W + ΔV| relative to V, force sum and moment
    /// ([`step_sums`]).
    pub(super) fn random_steps(
        c: &RodContact,
        r0: &[V3],
        rho: f64,
        mut seed: u64,
    ) -> (usize, f64, f64, f64) {
        let (mut worst_e, mut worst_l, mut worst_j) = (0.0f64, 0.0f64, 0.0f64);
        let mut touching = 0;
        for _ in 0..200 {
            let r1: Vec<V3> = r0
                .iter()
                .map(|x| x + 0.2 * rho * V3::new(rng(&mut seed), rng(&mut seed), rng(&mut seed)))
                .collect();
            let (work, f_sum, moment) = step_sums(c, r0, &r1);
            let (e0, e1) = (c.energy(r0), c.energy(&r1));
            let scale = e0.max(e1);
            if scale == 0.0 {
                continue;
            }
            touching += 1;
            worst_e = worst_e.max((work + e1 - e0).abs() / scale);
            worst_l = worst_l.max(f_sum);
            worst_j = worst_j.max(moment);
        }
        (touching, worst_e, worst_l, worst_j)
    }

    /// A small deterministic generator (xorshift) for the random steps.
    pub(super) fn rng(state: &mut u64) -> f64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }

    #[test]
    fn line_contact_work_equals_energy_change_and_keeps_momenta() {
        // Rod A along e1 (nodes 0-2), rod B (nodes 3-5) crossing it at 60° from above,
        // pressed in by 0.4 ρ; 200 random steps of up to 0.2 ρ per node component.
        let rho = 0.01;
        let r0 = vec![
            V3::new(0.0, 0.0, 0.0),
            V3::new(0.04, 0.0, 0.0),
            V3::new(0.08, 0.0, 0.0),
            V3::new(0.04 - 0.02, -0.0346, 0.016),
            V3::new(0.04 + 0.003, 0.0052, 0.0161),
            V3::new(0.04 + 0.02, 0.0346, 0.016),
        ];
        let c = line_contact(&[vec![0, 1, 2], vec![3, 4, 5]], &r0, rho, 16.0, 1e5);
        let (touching, worst_e, worst_l, worst_j) = random_steps(&c, &r0, rho, 0x9e3779b97f4a7c15);
        eprintln!(
            "line contact over {touching} random steps: |W + ΔV| {worst_e:.1e} of V, force sum {worst_l:.1e}, moment {worst_j:.1e} (relative)"
        );
        assert!(touching > 100, "only {touching} steps in contact");
        // Measured 6.8e-15 (of V), 5.2e-18 and 8.3e-17 (of the sums of the magnitudes).
        assert!(worst_e <= 3e-14, "work vs ΔV {worst_e:e}");
        assert!(worst_l <= 1e-15, "force sum {worst_l:e}");
        assert!(worst_j <= 1e-15, "moment {worst_j:e}");
    }

    #[test]
    fn line_pair_jacobian_matches_finite_differences() {
        let rho = 0.01;
        let r0 = vec![
            V3::new(0.0, 0.0, 0.0),
            V3::new(0.04, 0.0, 0.0),
            V3::new(0.02, -0.03, 0.017),
            V3::new(0.025, 0.03, 0.017),
        ];
        let c = line_contact(&[vec![0, 1], vec![2, 3]], &r0, rho, 8.0, 1e5);
        let mut r1 = r0.clone();
        r1[2] += V3::new(0.001, 0.002, -0.004);
        r1[3] += V3::new(-0.001, 0.001, -0.003);
        let mut checked = 0;
        let mut worst = 0.0f64;
        for &(i, j) in &c.candidates(&r0, 0.01) {
            let f = c.pair_force(i, j, &r0, &r1, true);
            if f.jacobian == M3::zeros() {
                continue;
            }
            checked += 1;
            // Node 2 carries weight w of point j, which feels −F: ∂Fᵢ/∂r₂ = −w ∂F/∂d₁.
            let w = c.points[j]
                .weights()
                .iter()
                .find(|(n, _)| *n == 2)
                .map_or(0.0, |x| x.1);
            let h = 1e-8;
            for col in 0..3 {
                let (mut rp, mut rm) = (r1.clone(), r1.clone());
                rp[2][col] += h;
                rm[2][col] -= h;
                let fd = (c.pair_force(i, j, &r0, &rp, false).force
                    - c.pair_force(i, j, &r0, &rm, false).force)
                    / (2.0 * h);
                let an = -w * f.jacobian.column(col);
                let scale = f.jacobian.amax().max(1e-300);
                worst = worst.max((fd - an).amax() / scale);
            }
        }
        eprintln!("line pair jacobian vs FD over {checked} pairs: {worst:.1e}");
        assert!(checked > 10, "only {checked} pairs in contact");
        // Measured 4.6e-10 (central differences, h = 1e-8).
        assert!(worst <= 3e-9, "jacobian vs FD {worst:e}");
    }

    /// The vertical force between two straight rods crossing at right angles, centrelines
    /// `h` apart, with rod B crossing rod A's elements at `t` (fraction of an element)
    /// and rod A crossing B's at `0.37 t + 0.21`.
    fn crossing_force(model: ContactModel, h: f64, t: f64) -> f64 {
        let (rho, el) = (0.005, 0.02);
        let mut r: Vec<V3> = (0..9)
            .map(|a| V3::new(-0.08 + el * a as f64, 0.0, 0.0))
            .collect();
        let ty = 0.37 * t + 0.21;
        r.extend((0..9).map(|a| V3::new(el * t, -0.08 + el * (a as f64 - ty), h)));
        let chains = [(0..9).collect::<Vec<_>>(), (9..18).collect()];
        let c = match model {
            ContactModel::Line => line_contact(&chains, &r, rho, 16.0, 1e6),
            ContactModel::Smooth => {
                let mut c = line_contact(&chains, &r, rho, 16.0, 1e6);
                let h = vec![el; 8];
                c.points = smooth_points(&chains[0], &h, rho, 16.0);
                c.split = c.points.len();
                c.points.extend(smooth_points(&chains[1], &h, rho, 16.0));
                c.model = ContactModel::Smooth;
                c
            }
            ContactModel::Spheres => {
                let mut c = line_contact(&chains, &r, rho, 1.0, 1e6);
                c.model = ContactModel::Spheres;
                c
            }
        };
        // Force on rod B along e3.
        c.candidates(&r, 0.0)
            .into_iter()
            .map(|(i, j)| -c.pair_force(i, j, &r, &r, false).force.z)
            .sum()
    }

    #[test]
    fn crossing_rods_press_alike_wherever_they_cross() {
        let r_sum: f64 = 0.01;
        for g in [2e-5, 4e-5, 1e-4] {
            let h = r_sum - g;
            let law = 1e6 * h * (r_sum * r_sum - h * h).powi(2) / (2.0 * r_sum.powi(4));
            let mut line = Vec::new();
            let mut spheres = Vec::new();
            let mut smooth = Vec::new();
            for k in 0..=40 {
                let t = k as f64 / 40.0;
                line.push(crossing_force(ContactModel::Line, h, t));
                smooth.push(crossing_force(ContactModel::Smooth, h, t));
                spheres.push(crossing_force(ContactModel::Spheres, h, t));
            }
            let spread = |v: &[f64]| {
                let (lo, hi) = v
                    .iter()
                    .fold((f64::MAX, f64::MIN), |m, &x| (m.0.min(x), m.1.max(x)));
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                ((hi - lo) / mean, mean)
            };
            let (sl, ml) = spread(&line);
            let (ss, ms) = spread(&spheres);
            let (so, mo) = spread(&smooth);
            eprintln!("smooth: force {mo:.3e} N, spread {so:.1e}");
            assert!(so <= 0.08, "smooth contact's force varies by {so:e}");
            assert!(
                (mo / law - 1.0).abs() <= 0.01,
                "smooth force {mo:e} vs law {law:e}"
            );
            eprintln!(
                "crossing at overlap {g:.0e}: line force {ml:.3e} N (law {law:.3e}), spread {sl:.1e}; spheres {ms:.3e} N, spread {ss:.1e}"
            );
            // Measured (16 points per radius): spread 6.4e-2, 1.8e-2, 8.1e-3 and the mean
            // within 3.6e-3 of the law; the spheres' force spreads by 29, 16, 4.9 times
            // its mean.
            assert!(sl <= 0.08, "line contact's force varies by {sl:e}");
            assert!(ss > 1.0, "the spheres' force should be corrugated ({ss:e})");
            assert!(
                (ml / law - 1.0).abs() <= 0.01,
                "line force {ml:e} vs law {law:e}"
            );
        }
    }

    #[test]
    fn line_pair_search_finds_every_pair_in_reach() {
        // A rod folded back on itself (self contact) and brute force over all pairs.
        let r: Vec<V3> = (0..24)
            .map(|a| {
                let t = a as f64 * 0.3;
                V3::new(0.05 * t.cos(), 0.05 * t.sin(), 0.0015 * t)
            })
            .collect();
        let c = line_contact(&[(0..24).collect()], &r, 0.006, 4.0, 1e5);
        assert!(c.is_self());
        for reach in [0.0, 0.003] {
            let found = c.candidates(&r, reach);
            let mut brute = Vec::new();
            for i in 0..c.points.len() {
                for j in i + 1..c.points.len() {
                    let l = c.points[i].radius + c.points[j].radius + reach;
                    if c.allowed(i, j) && (c.points[i].at(&r) - c.points[j].at(&r)).norm() < l {
                        brute.push((i, j));
                    }
                }
            }
            assert!(!brute.is_empty());
            assert_eq!(found, brute, "reach {reach}");
        }
    }

    #[test]
    fn sphere_pair_search_finds_every_pair_in_reach() {
        // A rod coiled on itself (self contact, one sphere per node and two between) and
        // brute force over all pairs.
        let r: Vec<V3> = (0..60)
            .map(|a| {
                let t = a as f64 * 0.35;
                V3::new(0.03 * t.cos(), 0.03 * t.sin(), 0.0008 * t)
            })
            .collect();
        let mut points = Vec::new();
        for e in 0..59 {
            for k in 0..3 {
                points.push(SamplePoint {
                    nodes: [e, e + 1],
                    xi: k as f64 / 3.0,
                    stencil: Stencil::linear([e, e + 1], k as f64 / 3.0),
                    radius: 0.004,
                    spacing: 0.0035,
                    arc: 0.0105 * (e as f64 + k as f64 / 3.0),
                });
            }
        }
        let c = RodContact {
            rods: vec!["a".into()],
            stiffness: 1e5,
            friction: 0.0,
            slip: 1e-3,
            model: ContactModel::Spheres,
            split: points.len(),
            points,
        };
        for reach in [0.0, 0.002, 0.02] {
            let found = c.candidates(&r, reach);
            let mut brute = Vec::new();
            for i in 0..c.points.len() {
                for j in i + 1..c.points.len() {
                    let l = c.points[i].radius + c.points[j].radius + reach;
                    let d = c.points[i].at(&r) - c.points[j].at(&r);
                    if c.allowed(i, j) && d.norm_squared() < l * l {
                        brute.push((i, j));
                    }
                }
            }
            assert!(!brute.is_empty());
            assert_eq!(found, brute, "reach {reach}");
        }
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
