//! The WebXR generic hand bound to the sweeps. Being written.
