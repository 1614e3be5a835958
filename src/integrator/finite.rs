//! The last acceptance test of a step: every value it produced is finite. Huge or
//! subnormal inputs that pass validation can overflow (an energy of 1e300² is `inf`) or
//! produce `0/0`; such a step is a failure with a reason naming the value, never a
//! completed step whose history row or summary holds NaN.

use super::report::{StepFailure, StepReport};
use super::state::State;
use crate::integrator::invariants::Invariants;
use crate::integrator::record::StepRecord;

/// The first non-finite value of a step's result, named, or `None`.
pub fn first_non_finite(state: &State, inv: &Invariants, rep: &StepReport) -> Option<String> {
    let scalars = [
        ("t", state.t),
        ("kinetic energy", inv.kinetic),
        ("stored energy", inv.potential),
        ("total energy", inv.total()),
        ("dissipation", rep.dissipation),
        ("external work", rep.external_work),
        ("translational acceleration norm", rep.acc_trans),
        ("director acceleration norm", rep.acc_rot),
        ("residual", rep.residual),
        ("link strain", rep.max_link_g),
    ];
    if let Some((name, x)) = scalars.iter().find(|(_, x)| !x.is_finite()) {
        return Some(format!("{name} = {x}"));
    }
    if let Some(c) = (0..3).find(|&c| !inv.l[c].is_finite()) {
        return Some(format!("linear momentum L[{c}] = {}", inv.l[c]));
    }
    if let Some(c) = (0..3).find(|&c| !inv.j[c].is_finite()) {
        return Some(format!("angular momentum J[{c}] = {}", inv.j[c]));
    }
    let bad3 = |v: &nalgebra::Vector3<f64>| v.iter().any(|x| !x.is_finite());
    if let Some(a) = state.r.iter().position(bad3) {
        return Some(format!("position of node {a}"));
    }
    if let Some(a) = state.v.iter().position(bad3) {
        return Some(format!("velocity of node {a}"));
    }
    if let Some(e) = state
        .d
        .iter()
        .position(|d| d.iter().any(|m| m.iter().any(|x| !x.is_finite())))
    {
        return Some(format!("directors of element {e}"));
    }
    if let Some(e) = state.vd.iter().position(|vd| vd.iter().flatten().any(bad3)) {
        return Some(format!("director velocities of element {e}"));
    }
    if let Some(e) = state
        .eps
        .iter()
        .position(|s| s.iter().any(|x| !x.is_finite()))
    {
        return Some(format!("strains of element {e}"));
    }
    if let Some(i) = state.lambda.iter().position(|x| !x.is_finite()) {
        return Some(format!("multiplier of link {i}"));
    }
    None
}

/// `Err` (a step failure naming the value) when a step's result holds a non-finite value.
pub fn check_step(state: &State, inv: &Invariants, rep: &StepReport) -> Result<(), StepFailure> {
    match first_non_finite(state, inv, rep) {
        None => Ok(()),
        Some(what) => Err(StepFailure {
            reason: format!(
                "non-finite value in the step's result ({what}): the inputs' magnitudes overflow or underflow f64"
            ),
            residuals: vec![rep.residual],
        }),
    }
}

/// The name of the first non-finite field of a history record, or `None`.
pub fn record_non_finite(r: &StepRecord) -> Option<&'static str> {
    let fields = [
        ("t", r.t),
        ("kinetic", r.kinetic),
        ("potential", r.potential),
        ("total", r.total),
        ("dissipation", r.dissipation),
        ("external_work", r.external_work),
        ("acc_trans", r.acc_trans),
        ("acc_rot", r.acc_rot),
        ("residual", r.residual),
        ("max_link_g", r.max_link_g),
    ];
    fields
        .iter()
        .find(|(_, x)| !x.is_finite())
        .map(|(n, _)| *n)
        .or_else(|| r.l.iter().any(|x| !x.is_finite()).then_some("L"))
        .or_else(|| r.j.iter().any(|x| !x.is_finite()).then_some("J"))
}
