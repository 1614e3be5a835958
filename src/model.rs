//! The frozen problem a scene describes: mesh, section properties, supports, loads and
//! initial state. Built once by [`crate::scene`]; the integrator only reads it.
//!
//! Conventions (DESIGN §1–2): every node `A` carries a position and a rotation `Λ^A`
//! (identity in the reference configuration). Every element end `(e, l)` carries its own
//! reference triad `Λ_o^{(e)l}`, so the directors of that end are `d_i = Λ^A Λ_o^{(e)l} e_i`.
//! Two elements that meet at an angle (a rigid corner) share the node but keep their own
//! triads.

use nalgebra::{Matrix2, Matrix3, Vector3};

pub use crate::table::{Ramp, TimeTable};

/// 3-vector of `f64`.
pub type Vec3 = Vector3<f64>;
/// 3×3 matrix of `f64`.
pub type Mat3 = Matrix3<f64>;

/// Per-element constants of the continuum model, already multiplied out
/// (stiffnesses, inertias per unit reference length).
///
/// Generic over the element kernel's lane type (`ElementProps<F64x4>` holds four
/// elements' constants, one per lane: [`crate::math::lane`]); `ElementProps` is one element.
#[derive(Clone, Debug, PartialEq)]
pub struct ElementProps<T: nalgebra::Scalar = f64> {
    /// Reference length `h` of the element (the one-point quadrature weight).
    pub h: T,
    /// Mass per unit length `Aρ`.
    pub a_rho: T,
    /// Euler dyadic `Iρ^{αβ} = ρ ∫ ξ^α ξ^β dA` (α, β ∈ {1, 2}).
    pub i_rho: Matrix2<T>,
    /// Diagonal of `C_Γ = diag(G A1, G A2, E A)`.
    pub c_gamma: Vector3<T>,
    /// `C_Ω = [[E I11, E I12, 0], [E I12, E I22, 0], [0, 0, G J]]`.
    pub c_omega: Matrix3<T>,
    /// Kelvin–Voigt retardation time `η` (s): viscous stresses `η C ε̇`, entering a step
    /// as `½ β C Δε` with `β = 2η/Δt` (0: no material damping).
    pub damping: T,
    /// Drag per unit length `c` (N·s/m²): a force `−c (r_{n+1} − r_n)/Δt` on the
    /// centerline, through the consistent mass pattern (0: none).
    pub drag: T,
}

/// One two-node element.
#[derive(Clone, Debug, PartialEq)]
pub struct Element {
    /// Global node indices of the two ends (`l = 0, 1`).
    pub nodes: [usize; 2],
    /// Reference triad `Λ_o^{(e)l}` of each end (columns `d1°, d2°, d3°`).
    pub ref_triad: [Mat3; 2],
    /// Material and section constants.
    pub props: ElementProps,
    /// Index of the rod this element belongs to.
    pub rod: usize,
}

/// What is held fixed at a node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Support {
    /// Translation fixed (pin or clamp): the three `u` unknowns are removed.
    pub translation: bool,
    /// Rotation fixed (clamp): the three `θ` unknowns are removed.
    pub rotation: bool,
}

/// Prescribed motion of a supported node (a driven clamp or pin): relative to where the
/// node starts, its position follows `r(t) = r_0 + (s(t) − s(0)) displacement` and its
/// rotation `Λ(t) = exp((s(t) − s(0)) φ̂) Λ_0`, imposed exactly at every time level.
#[derive(Clone, Debug, PartialEq)]
pub struct SupportDrive {
    /// The node (its translation, and its rotation when `rotation` is nonzero, are held
    /// by a support).
    pub node: usize,
    /// Displacement at factor 1.
    pub displacement: Vec3,
    /// Rotation vector `φ` (axis × angle) at factor 1.
    pub rotation: Vec3,
    /// Motion factor `s(t)`.
    pub table: TimeTable,
    /// Interpolation of the table.
    pub ramp: Ramp,
}

impl SupportDrive {
    /// The motion factor at `t`.
    pub fn factor(&self, t: f64) -> f64 {
        self.table.eval_ramped(self.ramp, t)
    }

    /// The node's increment `(u, θ)` from `t0` to `t1`: `u = Δs displacement` and the
    /// Cayley increment `θ = cay⁻¹(exp(Δs φ̂))` (exact: the axis is fixed).
    pub fn increment(&self, t0: f64, t1: f64) -> (Vec3, Vec3) {
        let ds = self.factor(t1) - self.factor(t0);
        let phi = self.rotation * ds;
        let angle = phi.norm();
        // cay(θ) = exp(φ̂) for θ = 2 tan(|φ|/2) φ/|φ|.
        let theta = if angle > 0.0 {
            phi * (2.0 * (0.5 * angle).tan() / angle)
        } else {
            Vec3::zeros()
        };
        (self.displacement * ds, theta)
    }
}

/// A nodal force and/or moment scaled by a time table: `F(t) = f(t)·force`.
#[derive(Clone, Debug, PartialEq)]
pub struct NodalLoad {
    /// Node it acts on.
    pub node: usize,
    /// Force vector at factor 1.
    pub force: Vec3,
    /// Moment vector at factor 1.
    pub moment: Vec3,
    /// Time factor.
    pub table: TimeTable,
}

/// A distributed force and moment per unit reference length on a set of elements, scaled
/// by a time table: `f(t)·force`, `f(t)·moment`.
///
/// A dead load keeps its spatial direction and enters like gravity, through the
/// consistent load vector `∫ N_l f dS = f h/2` on each element end. A follower load is
/// given in the director frame (components along `d1, d2, d3`) and turns with the rod:
/// on each element end it is `(h/2) Σ_i f_i d_{i,n+½}`, the directors of that end at the
/// mid-step, so the work it does over a step is exactly the `F·u + M·θ` that enters the
/// energy balance.
#[derive(Clone, Debug, PartialEq)]
pub struct LineLoad {
    /// Elements it acts on.
    pub elements: Vec<usize>,
    /// Force per unit length at factor 1 (spatial; director components when `follower`).
    pub force: Vec3,
    /// Moment per unit length at factor 1 (spatial; director components when `follower`).
    pub moment: Vec3,
    /// Whether the load follows the directors.
    pub follower: bool,
    /// Time factor.
    pub table: TimeTable,
}

/// The coordinate plane a planar scene lives in, named by the axis normal to it.
///
/// A planar model keeps only the unknowns the plane can excite: the two in-plane
/// translations and the rotation about the normal (DESIGN §6: the arch and the
/// mechanism). The other three per node are removed from the Newton system, which is
/// exact (not an approximation) as long as the data are planar; the scene checks that.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plane {
    /// Index (0, 1, 2) of the coordinate axis normal to the plane.
    pub normal: usize,
}

impl Plane {
    /// Scene name of the plane (`"e2e3"` for normal `e1`, …).
    pub fn name(&self) -> &'static str {
        ["e2e3", "e1e3", "e1e2"][self.normal]
    }

    /// Whether translation component `c` is a planar unknown (in-plane).
    pub fn keeps_translation(&self, c: usize) -> bool {
        c != self.normal
    }

    /// Whether rotation component `c` is a planar unknown (about the normal).
    pub fn keeps_rotation(&self, c: usize) -> bool {
        c == self.normal
    }
}

/// A rigid link: a massless inextensible bar from a fixed pivot to a node, enforced by an
/// augmented Lagrangian on the Green strain `g = ½(|x − p|² − ℓ²)/ℓ²` (DESIGN §6).
///
/// The energy `λg + ½κg²` is quadratic in `x`, so its mid-point force
/// `(λ + κ(g_n + g_{n+1})/2) (x_{n+½} − p)/ℓ²` does exactly the work `Δ(λg + ½κg²)` and
/// the energy–momentum property survives the constraint.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    /// Node the bar holds.
    pub node: usize,
    /// Fixed pivot.
    pub pivot: Vec3,
    /// Bar length `ℓ` (the reference distance from pivot to node).
    pub length: f64,
    /// Penalty `κ` of the augmented Lagrangian.
    pub penalty: f64,
    /// Tolerance on `|g|` a step must reach before it is accepted.
    pub tol: f64,
}

impl Link {
    /// Green strain `g` of the bar with the node at `x`.
    pub fn strain(&self, x: &Vec3) -> f64 {
        let l2 = self.length * self.length;
        0.5 * ((x - self.pivot).norm_squared() - l2) / l2
    }

    /// Stored energy `λg + ½κg²` with the node at `x`.
    pub fn energy(&self, lambda: f64, x: &Vec3) -> f64 {
        let g = self.strain(x);
        lambda * g + 0.5 * self.penalty * g * g
    }
}

/// How a rod's elements measure their curvature and twist `Ω` from the relative turn of
/// their end triads (`[[rod]] curvature_measure`; docs/theory.md §2). For end triads
/// turned `δ` apart about a unit axis `e`, an element of length `h` has `Ω = f(δ) e / h`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CurvatureMeasure {
    /// `f(δ) = sin δ`: bilinear in the directors (the default). Its moment peaks at
    /// δ = π/4 and its energy is short by `1 − (sin δ/δ)² ≈ δ²/3`.
    #[default]
    Sine,
    /// `f(δ) = 3 sin δ / (2 + cos δ)`: the sine measure divided by the objective scalar
    /// `n = (2 + cos δ)/3 = ½ + ⅙ Σ_i d_i⁰·d_i¹`. Its moment peaks at δ = 1.42 rad and its
    /// energy is short by `δ⁴/90`. EM on the CPU 3D kernel only.
    Rational,
}

impl CurvatureMeasure {
    /// The scene-file name (`"sine"`, `"rational"`).
    pub fn name(self) -> &'static str {
        match self {
            CurvatureMeasure::Sine => "sine",
            CurvatureMeasure::Rational => "rational",
        }
    }
}

/// A rod as the scene declared it (for reports and output grouping).
#[derive(Clone, Debug, PartialEq)]
pub struct RodInfo {
    /// Name from the scene.
    pub name: String,
    /// Elements of this rod, in order along the rod.
    pub elements: std::ops::Range<usize>,
    /// How the rod's elements measure curvature and twist.
    pub curvature_measure: CurvatureMeasure,
}

/// The whole discretized problem.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Reference node positions.
    pub nodes: Vec<Vec3>,
    /// Elements.
    pub elements: Vec<Element>,
    /// Supports, one per node.
    pub supports: Vec<Support>,
    /// Point mass at each node (0 where none).
    pub point_mass: Vec<f64>,
    /// Nodal loads.
    pub loads: Vec<NodalLoad>,
    /// Gravity acceleration (acts on rods and point masses).
    pub gravity: Vec3,
    /// Initial translational velocity of each node.
    pub velocity0: Vec<Vec3>,
    /// Initial angular velocity of each node (directors start with `ω × d`).
    pub omega0: Vec<Vec3>,
    /// Rods in scene order.
    pub rods: Vec<RodInfo>,
    /// Rigid links (augmented Lagrangian bars to fixed pivots).
    pub links: Vec<Link>,
    /// The plane of a planar model (`None`: full 3D).
    pub planar: Option<Plane>,
    /// Where the initial state departs from the stress-free reference (initial
    /// positions and rotations, intrinsic curvature); the default is "none".
    pub shape: ShapeSetup,
    /// Distributed loads per unit length (`[[line_load]]`).
    pub line_loads: Vec<LineLoad>,
    /// Prescribed motion of supported nodes (driven clamps and pins).
    pub drives: Vec<SupportDrive>,
    /// Sliding clamps: clamped nodes that are free to translate along an axis (and
    /// optionally to turn about it).
    pub slides: Vec<Slide>,
    /// Rigid obstacles the rods' nodes can touch (`[[obstacle]]`).
    pub obstacles: Vec<crate::obstacle::Obstacle>,
    /// Contact between rods and of rods with themselves (`[[contact]]`).
    pub rod_contacts: Vec<crate::rod_contact::RodContact>,
}

/// A sliding clamp: the node's rotation and its translation across `axis` are held; the
/// translation along `axis` (and, with `spin`, the rotation about it) stays an unknown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slide {
    /// The node (marked clamped in [`Model::supports`]).
    pub node: usize,
    /// The unit axis it slides along.
    pub axis: Vec3,
    /// Whether the rotation about `axis` is free.
    pub spin: bool,
}

impl Slide {
    /// The coordinate axis (0, 1, 2) `axis` lies along, if it does (the other two
    /// components exactly zero): such a slide removes unknowns; any other axis constrains
    /// rows of the assembled system instead.
    pub fn coordinate_axis(&self) -> Option<usize> {
        (0..3).find(|&k| (0..3).all(|c| c == k || self.axis[c] == 0.0))
    }
}

/// How the initial configuration and the stress-free shape depart from the reference
/// polyline ([`Model::nodes`] with the element triads). Empty vectors mean "as the
/// reference": every node starts at its reference position with the identity rotation,
/// and every element is stress-free in its straight reference shape.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ShapeSetup {
    /// Initial position of every node (empty: the reference positions).
    pub positions: Vec<Vec3>,
    /// Initial rotation `Λ^A_0` of every node, carrying the reference triads to the
    /// initial directors `d = Λ^A_0 Λ_o^{(e)l}` (empty: identity).
    pub rotations: Vec<Mat3>,
    /// Intrinsic curvature and twist `[κ1, κ2, τ]` of every element (material components,
    /// per unit reference length), added to the reference strains `Ω°` (empty: none).
    pub curvature: Vec<Vec3>,
}

impl ShapeSetup {
    /// True when the initial state is the reference and there is no intrinsic curvature.
    pub fn is_reference(&self) -> bool {
        self.positions.is_empty() && self.rotations.is_empty() && self.curvature.is_empty()
    }
}

impl Model {
    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Initial position of node `a` (the reference position unless the scene gives an
    /// initial configuration).
    pub fn initial_position(&self, a: usize) -> Vec3 {
        self.shape
            .positions
            .get(a)
            .copied()
            .unwrap_or(self.nodes[a])
    }

    /// Initial rotation `Λ^A_0` of node `a` (identity unless the scene gives one).
    pub fn initial_rotation(&self, a: usize) -> Mat3 {
        self.shape
            .rotations
            .get(a)
            .copied()
            .unwrap_or_else(Mat3::identity)
    }

    /// Initial director triads of element `e`, per end: `Λ^A_0 Λ_o^{(e)l}`.
    pub fn initial_triads(&self, e: usize) -> [Mat3; 2] {
        let el = &self.elements[e];
        std::array::from_fn(|l| self.initial_rotation(el.nodes[l]) * el.ref_triad[l])
    }

    /// Intrinsic curvature of element `e` added to its reference `Ω°` (zero unless the
    /// scene gives one).
    pub fn intrinsic_curvature(&self, e: usize) -> Vec3 {
        self.shape
            .curvature
            .get(e)
            .copied()
            .unwrap_or_else(Vec3::zeros)
    }

    /// True when nothing holds or pushes the model: no supports, no loads, no gravity.
    /// Momenta are then conserved by every scheme.
    pub fn is_free_flight(&self) -> bool {
        self.supports.iter().all(|s| !s.translation && !s.rotation)
            && self.links.is_empty()
            && self.loads.is_empty()
            && self.line_loads.is_empty()
            && self.obstacles.is_empty()
            && self.gravity == Vec3::zeros()
            && !self.has_drag()
    }

    /// True when some element has Kelvin–Voigt material damping.
    pub fn has_material_damping(&self) -> bool {
        self.elements.iter().any(|e| e.props.damping != 0.0)
    }

    /// True when some element has drag.
    pub fn has_drag(&self) -> bool {
        self.elements.iter().any(|e| e.props.drag != 0.0)
    }

    /// The curvature measure of element `e` (its rod's).
    pub fn curvature_measure(&self, e: usize) -> CurvatureMeasure {
        self.rods
            .get(self.elements[e].rod)
            .map_or(CurvatureMeasure::Sine, |r| r.curvature_measure)
    }

    /// The first rod (index) with the rational curvature measure, if any.
    pub fn rational_curvature_rod(&self) -> Option<usize> {
        self.rods
            .iter()
            .position(|r| r.curvature_measure == CurvatureMeasure::Rational)
    }

    /// The first scene feature the GPU batch path does not implement, by name (`None`:
    /// the model runs there). The kernels evaluate the elements from per-node
    /// increments, which carry the prescribed motion of driven supports as well as the
    /// Newton unknowns; contact with obstacles has no GPU kernel yet.
    pub fn gpu_unsupported(&self) -> Option<&'static str> {
        if !self.obstacles.is_empty() {
            return Some("contact with obstacles ([[obstacle]])");
        }
        if !self.rod_contacts.is_empty() {
            return Some("contact between rods ([[contact]])");
        }
        if self.rational_curvature_rod().is_some() {
            return Some(
                "the rational curvature measure ([[rod]] curvature_measure = \"rational\")",
            );
        }
        None
    }

    /// True when some obstacle or rod contact has friction (its work is part of the
    /// dissipation D).
    pub fn has_friction(&self) -> bool {
        self.obstacles.iter().any(|o| o.friction > 0.0)
            || self.rod_contacts.iter().any(|c| c.friction > 0.0)
    }

    /// True when some line load follows the directors (its nodal values depend on the
    /// configuration: see [`Self::follower_loads`]).
    pub fn has_follower_loads(&self) -> bool {
        self.line_loads.iter().any(|l| l.follower)
    }

    /// Adds the nodal forces and moments of the follower line loads at time `t` for the
    /// per-element-end director triads `d` (`[e][l]`, the mid-step triads in a step).
    pub fn follower_loads(&self, t: f64, d: &[[Mat3; 2]], force: &mut [Vec3], moment: &mut [Vec3]) {
        for ll in self.line_loads.iter().filter(|l| l.follower) {
            let s = ll.table.eval(t);
            if s == 0.0 {
                continue;
            }
            for &e in &ll.elements {
                let el = &self.elements[e];
                let w = 0.5 * el.props.h * s;
                for l in 0..2 {
                    force[el.nodes[l]] += d[e][l] * ll.force * w;
                    moment[el.nodes[l]] += d[e][l] * ll.moment * w;
                }
            }
        }
    }

    /// External force and moment at node level at time `t` (nodal loads, dead line loads,
    /// and gravity on the consistent mass of the elements and on point masses; follower
    /// line loads are not included, see [`Self::follower_loads`]).
    pub fn external_loads(&self, t: f64, force: &mut [Vec3], moment: &mut [Vec3]) {
        force.iter_mut().for_each(|f| *f = Vec3::zeros());
        moment.iter_mut().for_each(|m| *m = Vec3::zeros());
        if self.gravity != Vec3::zeros() {
            for e in &self.elements {
                // ∫ N_l Aρ g dS = Aρ h / 2 g on each end.
                let w = 0.5 * e.props.a_rho * e.props.h;
                for &a in &e.nodes {
                    force[a] += self.gravity * w;
                }
            }
            for (a, &m) in self.point_mass.iter().enumerate() {
                force[a] += self.gravity * m;
            }
        }
        for load in &self.loads {
            let s = load.table.eval(t);
            force[load.node] += load.force * s;
            moment[load.node] += load.moment * s;
        }
        for ll in self.line_loads.iter().filter(|l| !l.follower) {
            let s = ll.table.eval(t);
            for &e in &ll.elements {
                let el = &self.elements[e];
                // ∫ N_l f dS = f h/2 on each end.
                let w = 0.5 * el.props.h * s;
                for &a in &el.nodes {
                    force[a] += ll.force * w;
                    moment[a] += ll.moment * w;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_interpolates_and_jumps() {
        let t = TimeTable {
            times: vec![0.0, 1000.0, 1000.0],
            values: vec![0.0, 2500.0, 0.0],
        };
        assert_eq!(t.eval(-1.0), 0.0);
        assert!((t.eval(500.0) - 1250.0).abs() < 1e-12);
        assert_eq!(t.eval(1000.0), 0.0);
        assert_eq!(t.eval(999.999_999), 2500.0 * 0.999_999_999);
        assert_eq!(t.eval(2000.0), 0.0);
    }
}
