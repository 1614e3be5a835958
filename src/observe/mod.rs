//! Observers: pure functions of (model, state) and the records they produce. They read
//! what the integrator produces and never the reverse: the energies and momenta the
//! step's acceptance also needs ([`invariants`]) and the record types the run fills
//! ([`record`]) live in [`crate::integrator`] and are re-exported here.

pub mod balance;
pub mod probe;
pub mod report;

pub use crate::integrator::invariants::{acceleration_norms, invariants, Invariants};
pub use crate::integrator::record;
