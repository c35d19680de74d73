//! Per-frame synthesis. Everything here writes into caller-provided buffers and allocates
//! nothing per frame.

pub mod skin;
