//! # cosserat
//!
//! Nonlinear dynamics of geometrically exact (Cosserat) rods, discretized with two-node
//! elements that interpolate the director fields directly, integrated in time with the
//! energy–momentum (EM) and energy-dissipative momentum-conserving (EDMC-1, EDMC-2) schemes
//! of Armero & Romero.
//!
//! Data flows one way:
//!
//! ```text
//! scene (TOML) ──► model ──► integrator (Newton on R^{6N}) ──► observers ──► outputs
//!   scene::          model::    integrator::  element::          observe::     output::
//! ```
//!
//! * [`scene`] parses and validates a scene file into a [`model::Model`] and
//!   [`integrator::params::IntegratorParams`]; it knows no physics.
//! * [`element`] is the only physics: strains, stresses, dissipation scalars, element
//!   residual and tangent at one element.
//! * [`integrator`] assembles element contributions, runs Newton ([`linsolve`] solves),
//!   applies the staggered or monolithic dissipation strategy and accepts or rejects steps.
//! * [`observe`] computes energies, momenta and accelerations from a state.
//! * [`output`] writes `history.csv`, `summary.json` and the PNG charts.
//! * [`study`] runs work–precision and stability studies over the schemes (including the
//!   mid-point and generalized-α baselines) and charts them.

// Index loops over element ends l, m and director indices α, β mirror the equations of
// DESIGN §2–4 term by term; iterator rewrites would hide that correspondence.
#![allow(clippy::needless_range_loop)]
// Every public item is documented (CI runs clippy with -D warnings and `cargo doc`).
#![warn(missing_docs)]

pub mod batch;
pub mod bench;
pub mod driver;
pub mod element;
pub mod gpu;
pub mod integrator;
pub mod linsolve;
pub mod math;
pub mod model;
pub mod observe;
pub mod obstacle;
pub mod output;
pub mod paths;
pub mod reproduce;
pub mod rod_contact;
pub mod scene;
pub mod scheme;
pub mod study;
pub mod sweep;
pub mod table;
