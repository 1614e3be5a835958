//! Element kernel.
