//! A controller in the loop: nodal loads and the motion of driven supports set between
//! steps. Nothing here changes how a step is computed: a load lives in
//! [`Model::loads`], which the step reads at `t_{n+½}` ([`Simulation::mid_step_loads`]), so
//! its work enters `W` like any load's; a commanded support motion only replaces the
//! prescribed increment of its node over the coming steps, whose work the step already
//! books as support work ([`super::drive`]). A run whose loads are changed between steps
//! therefore closes `ΔH = W − D` as a scene with those loads in its time tables does.
//!
//! A support can be commanded only when its node is *driven* (its removed unknowns take a
//! prescribed increment; with translational dissipation it keeps its velocity unknowns):
//! a moving support of the scene, or a fixed one made drivable with
//! [`Model::control_support`] before the simulation is built.

use super::Simulation;
use crate::math::{cay, cay_inv};
use crate::model::{Mat3, Model, NodalLoad, Ramp, SupportDrive, TimeTable, Vec3};

/// A command refused by [`Simulation::set_load`], [`Simulation::add_load`],
/// [`Simulation::set_support_motion`] or [`Model::control_support`]: what it was about
/// (`load 2`, `node 7`, …) and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{what}: {reason}")]
pub struct ControlError {
    /// The load or support the command named.
    pub what: String,
    /// Why it was refused.
    pub reason: String,
}

fn refuse(what: impl Into<String>, reason: impl Into<String>) -> ControlError {
    ControlError {
        what: what.into(),
        reason: reason.into(),
    }
}

/// How a commanded support translates over the coming steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TranslationCommand {
    /// Constant velocity (m/s) from the current level on, until commanded again.
    Velocity(Vec3),
    /// Reach this position at the next level (linearly over the step), then hold it.
    Position(Vec3),
}

/// How a commanded clamp turns over the coming steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RotationCommand {
    /// Constant spatial angular velocity (rad/s) from the current level on:
    /// `Λ(t) = exp((t − t_n) ω̂) Λ_n`.
    AngularVelocity(Vec3),
    /// Reach this node rotation `Λ` (the node's directors are `Λ` times its reference
    /// triads) at the next level, turning about a fixed axis, then hold it. Less than a
    /// half turn away from the current rotation.
    Rotation(Mat3),
}

/// A commanded motion of one component (translation or rotation) of a driven node: the
/// vector (displacement, or rotation vector about a fixed spatial axis) it adds over
/// `[from, until]` at a constant rate, nothing outside.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Segment {
    /// `rate` per unit time from `from` on.
    Rate { from: f64, rate: Vec3 },
    /// `total` spread evenly over `[from, from + dt]`.
    Move { from: f64, dt: f64, total: Vec3 },
}

impl Segment {
    /// The vector the segment adds over `[t, t + dt]` (exactly `total` over the step it
    /// was commanded for, whatever the rounding of `t + dt`).
    fn over(&self, t: f64, dt: f64) -> Vec3 {
        match *self {
            Segment::Rate { from, rate } => {
                let span = if t >= from {
                    dt
                } else {
                    (t + dt - from).max(0.0)
                };
                rate * span
            }
            Segment::Move {
                from,
                dt: len,
                total,
            } => {
                if t == from && dt == len {
                    return total;
                }
                let (a, b) = (t.max(from), (t + dt).min(from + len));
                total * ((b - a).max(0.0) / len)
            }
        }
    }
}

/// The commands of one driven node: translation and rotation, each `None` while the
/// node follows its scene table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct NodeCommand {
    node: usize,
    translation: Option<Segment>,
    rotation: Option<Segment>,
}

/// The Cayley increment of the rotation vector `phi` (`cay(θ) = exp(φ̂)`).
fn cayley_of(phi: &Vec3) -> Vec3 {
    let angle = phi.norm();
    if angle > 0.0 {
        phi * (2.0 * (0.5 * angle).tan() / angle)
    } else {
        Vec3::zeros()
    }
}

/// The rotation vector `φ` (axis × angle) of a rotation `r` less than a half turn (NaN
/// at a half turn), through the inverse Cayley map: `|cay⁻¹(r)| = 2 tan(|φ|/2)`.
fn rotation_vector(r: &Mat3) -> Vec3 {
    let theta = cay_inv(r);
    if (cay(&theta) - r).amax().is_nan() || (cay(&theta) - r).amax() > 1e-9 {
        return Vec3::repeat(f64::NAN);
    }
    let n = theta.norm();
    if n > 0.0 {
        theta * (2.0 * (0.5 * n).atan() / n)
    } else {
        Vec3::zeros()
    }
}

fn finite(what: &str, key: &str, v: &Vec3) -> Result<(), ControlError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(refuse(
            what,
            format!("{key}: not finite ({:?})", v.as_slice()),
        ))
    }
}

impl Model {
    /// Makes the support at `node` drivable from a controller
    /// ([`Simulation::set_support_motion`]): a fixed clamp or pin becomes a moving support
    /// whose scene motion is none (it holds until commanded). A moving support is left as
    /// it is. Call it before building the simulation (it adds the node's velocity unknowns
    /// under translational dissipation, as for every driven support). Refused for a node
    /// without a support and for a sliding clamp.
    pub fn control_support(&mut self, node: usize) -> Result<(), ControlError> {
        let what = format!("node {node}");
        let Some(s) = self.supports.get(node) else {
            return Err(refuse(
                what,
                format!("no such node (the model has {})", self.n_nodes()),
            ));
        };
        if !s.translation {
            return Err(refuse(
                what,
                "not a support: only a [[clamp]] or [[pin]] can be driven",
            ));
        }
        if self.slides.iter().any(|sl| sl.node == node) {
            return Err(refuse(
                what,
                "a sliding clamp cannot be driven by a controller",
            ));
        }
        if !self.drives.iter().any(|d| d.node == node) {
            self.drives.push(SupportDrive {
                node,
                displacement: Vec3::zeros(),
                rotation: Vec3::zeros(),
                table: TimeTable {
                    times: vec![0.0],
                    values: vec![0.0],
                },
                ramp: Ramp::Linear,
            });
        }
        Ok(())
    }
}

impl Simulation {
    /// Sets nodal load `index` ([`Model::loads`], scene order of `[[load]]`, then those
    /// added by [`Self::add_load`]) to a constant force and moment from the current level
    /// on: the next step and every later one apply them (at `t_{n+½}`, like every load)
    /// until set again. A part not given keeps its value at the current level `t_n`.
    pub fn set_load(
        &mut self,
        index: usize,
        force: Option<Vec3>,
        moment: Option<Vec3>,
    ) -> Result<(), ControlError> {
        let what = format!("load {index}");
        let count = self.model.loads.len();
        let t = self.state.t;
        let Some(load) = self.model.loads.get_mut(index) else {
            return Err(refuse(
                what,
                format!("no such load (the model has {count})"),
            ));
        };
        for (key, v) in [("force", &force), ("moment", &moment)] {
            if let Some(v) = v {
                finite(&what, key, v)?;
            }
        }
        let s = load.table.eval(t);
        load.force = force.unwrap_or(load.force * s);
        load.moment = moment.unwrap_or(load.moment * s);
        load.table = TimeTable::constant_one();
        Ok(())
    }

    /// Adds a constant nodal force and moment at `node` from the current level on;
    /// returns its index for [`Self::set_load`].
    pub fn add_load(
        &mut self,
        node: usize,
        force: Vec3,
        moment: Vec3,
    ) -> Result<usize, ControlError> {
        let what = format!("node {node}");
        if node >= self.model.n_nodes() {
            return Err(refuse(
                what,
                format!("no such node (the model has {})", self.model.n_nodes()),
            ));
        }
        finite(&what, "force", &force)?;
        finite(&what, "moment", &moment)?;
        self.model.loads.push(NodalLoad {
            node,
            force,
            moment,
            table: TimeTable::constant_one(),
        });
        Ok(self.model.loads.len() - 1)
    }

    /// The current rotation `Λ` of node `a` (its directors are `Λ` times the reference
    /// triads of the elements that meet there; identity for a node outside every
    /// element).
    pub fn node_rotation(&self, a: usize) -> Mat3 {
        for (e, el) in self.model.elements.iter().enumerate() {
            if let Some(l) = el.nodes.iter().position(|&n| n == a) {
                return self.state.d[e][l] * el.ref_triad[l].transpose();
            }
        }
        Mat3::identity()
    }

    /// Commands the motion of the driven support at `node` from the current level on
    /// (`None`: that part keeps its current command, or its scene motion). A position or
    /// rotation is reached at the next level and then held; a velocity holds until
    /// commanded again. The support's work enters `W` as for a scene's moving support.
    /// Refused for a node that is not driven (see [`Model::control_support`]), a rotation
    /// of a pin, a motion out of a planar model's plane, a rotation target half a turn or
    /// more away, and the generalized-α baseline (no moving supports).
    pub fn set_support_motion(
        &mut self,
        node: usize,
        translation: Option<TranslationCommand>,
        rotation: Option<RotationCommand>,
    ) -> Result<(), ControlError> {
        let what = format!("support at node {node}");
        if node >= self.model.n_nodes() {
            return Err(refuse(
                what,
                format!("no such node (the model has {})", self.model.n_nodes()),
            ));
        }
        if self.gen_alpha.is_some() {
            return Err(refuse(
                what,
                "gen-alpha does not support moving supports; use em, edmc1, edmc2 or midpoint",
            ));
        }
        if !self.model.drives.iter().any(|d| d.node == node) {
            return Err(refuse(
                what,
                "not a driven support: make it drivable before the simulation is built (Model::control_support; `controlled=` in Python)",
            ));
        }
        let (t, dt) = (self.state.t, self.params.dt);
        let plane = self.model.planar;
        let translation = match translation {
            None => None,
            Some(TranslationCommand::Velocity(v)) => {
                finite(&what, "velocity", &v)?;
                Some(Segment::Rate { from: t, rate: v })
            }
            Some(TranslationCommand::Position(p)) => {
                finite(&what, "position", &p)?;
                Some(Segment::Move {
                    from: t,
                    dt,
                    total: p - self.state.r[node],
                })
            }
        };
        let rotation = match rotation {
            None => None,
            Some(_) if !self.model.supports[node].rotation => {
                return Err(refuse(
                    what,
                    "a pin leaves the rotation free: only a clamp can be turned",
                ))
            }
            Some(RotationCommand::AngularVelocity(w)) => {
                finite(&what, "angular velocity", &w)?;
                Some(Segment::Rate { from: t, rate: w })
            }
            Some(RotationCommand::Rotation(r)) => {
                if !r.iter().all(|x| x.is_finite())
                    || (r.transpose() * r - Mat3::identity()).amax() > 1e-9
                    || r.determinant() < 0.0
                {
                    return Err(refuse(
                        what,
                        "rotation: not a rotation matrix (orthonormal, determinant +1)",
                    ));
                }
                let phi = rotation_vector(&(r * self.node_rotation(node).transpose()));
                if phi.norm().is_nan() || phi.norm() >= 0.99 * std::f64::consts::PI {
                    return Err(refuse(
                        what,
                        format!(
                            "rotation: {:.3} rad from the current rotation; a step turns less than half a turn (command it over several steps)",
                            phi.norm()
                        ),
                    ));
                }
                Some(Segment::Move {
                    from: t,
                    dt,
                    total: phi,
                })
            }
        };
        if let Some(p) = plane {
            let leaves = |s: &Option<Segment>, keep: &dyn Fn(usize) -> bool| {
                let v = match s {
                    Some(Segment::Rate { rate, .. }) => *rate,
                    Some(Segment::Move { total, .. }) => *total,
                    None => return false,
                };
                let scale = v.amax();
                (0..3).any(|c| !keep(c) && v[c].abs() > 1e-12 * scale)
            };
            if leaves(&translation, &|c| p.keeps_translation(c)) {
                return Err(refuse(
                    what,
                    format!("a planar model moves only in its plane {}", p.name()),
                ));
            }
            if leaves(&rotation, &|c| p.keeps_rotation(c)) {
                return Err(refuse(
                    what,
                    format!(
                        "a planar model turns only about the normal of its plane {}",
                        p.name()
                    ),
                ));
            }
        }
        // Round-off across the plane is dropped (those unknowns stay removed).
        let in_plane = |s: Option<Segment>, keep: &dyn Fn(usize) -> bool| {
            let clean = |v: Vec3| Vec3::from_fn(|c, _| if keep(c) { v[c] } else { 0.0 });
            s.map(|s| match s {
                Segment::Rate { from, rate } => Segment::Rate {
                    from,
                    rate: clean(rate),
                },
                Segment::Move { from, dt, total } => Segment::Move {
                    from,
                    dt,
                    total: clean(total),
                },
            })
        };
        let (translation, rotation) = match plane {
            Some(p) => (
                in_plane(translation, &|c| p.keeps_translation(c)),
                in_plane(rotation, &|c| p.keeps_rotation(c)),
            ),
            None => (translation, rotation),
        };
        let i = match self.commands.iter().position(|c| c.node == node) {
            Some(i) => i,
            None => {
                self.commands.push(NodeCommand {
                    node,
                    translation: None,
                    rotation: None,
                });
                self.commands.len() - 1
            }
        };
        let c = &mut self.commands[i];
        if translation.is_some() {
            c.translation = translation;
        }
        if rotation.is_some() {
            c.rotation = rotation;
        }
        Ok(())
    }

    /// Replaces the prescribed increments of commanded nodes over `[t, t + dt]` (after
    /// the scene's drives wrote theirs).
    pub(super) fn commanded_increments(&mut self, t: f64, dt: f64) {
        for c in &self.commands {
            if let Some(s) = &c.translation {
                self.prescribed[c.node][0] = s.over(t, dt);
            }
            if let Some(s) = &c.rotation {
                self.prescribed[c.node][1] = cayley_of(&s.over(t, dt));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_move_adds_its_total_over_its_step_and_nothing_outside() {
        let v = Vec3::new(1.0, -2.0, 0.5);
        let s = Segment::Move {
            from: 0.3,
            dt: 0.1,
            total: v,
        };
        assert_eq!(s.over(0.3, 0.1), v);
        assert_eq!(s.over(0.4, 0.1), Vec3::zeros());
        assert_eq!(s.over(0.1, 0.1), Vec3::zeros());
        // Two half steps (a cut-back) add the whole move.
        let halves = s.over(0.3, 0.05) + s.over(0.35, 0.05);
        assert!((halves - v).amax() <= 4.0 * f64::EPSILON * v.amax());
        let r = Segment::Rate { from: 1.0, rate: v };
        assert_eq!(r.over(1.0, 0.25), v * 0.25);
        assert_eq!(r.over(0.5, 0.25), Vec3::zeros());
    }
}
