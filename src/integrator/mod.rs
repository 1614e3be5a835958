//! Time integration: one step is a Newton solve on the nodal increments.

pub mod params;
