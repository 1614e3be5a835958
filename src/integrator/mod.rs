//! Time integration: one step is a Newton solve on the nodal increments
//! (DESIGN §3), with the dissipation treated by the staggered or monolithic strategy
//! (DESIGN §4).

pub mod backend;
pub mod dofs;
pub mod finite;
pub mod gen_alpha;
mod links;
pub mod params;
pub mod run;
pub mod scaling;
pub mod state;
pub mod system;

pub use params::{IntegratorParams, Scheme, Strategy};
pub use system::{Simulation, SolveTimers, StepFailure, StepReport};
