//! Small fixed-size algebra.
