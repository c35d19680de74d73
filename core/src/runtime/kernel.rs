//! Regression kernels (FKY08 §4.2).
