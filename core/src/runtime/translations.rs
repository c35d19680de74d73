//! Poisson translation solver (FKY08 §5).
