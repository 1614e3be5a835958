//! Sparse linear solves.
