//! Time integration: one step is a Newton solve on the nodal increments
//! (DESIGN §3), with the dissipation treated by the staggered or monolithic strategy
//! (DESIGN §4).

pub mod dofs;
pub mod evaluate;
pub mod finite;
pub mod gen_alpha;
pub mod invariants;
mod links;
pub mod params;
pub mod record;
pub mod report;
pub mod run;
pub mod scaling;
mod simulation;
pub mod state;

pub use params::{IntegratorParams, NewtonVariant, Scheme, Strategy};
pub use report::{SolveTimers, StepFailure, StepReport};
pub use simulation::{ControlError, RotationCommand, Simulation, TranslationCommand};
