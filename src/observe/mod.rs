//! Observers: pure functions of (model, state) and the records they produce.

pub mod record;
