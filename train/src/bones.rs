//! Proxy bones.
