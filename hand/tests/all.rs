//! Every integration test of this crate in one test binary (`cargo test -p PACKAGE --test all`;
//! one module per file, `cargo test -p PACKAGE --test all MODULE::` runs one file's tests):
//! one link and one copy of the dependencies' generic code instead of one per file
//! (issue 41: the test build of `.ci/run`).
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

#[path = "../../core/tests/common/mod.rs"]
mod common;

mod fitted_maps;
mod joint_map;
mod mediapipe_map;
mod render;
mod subdivision_hand;
mod sweep_bind;
mod sweep_collide;
mod sweep_creases;
mod sweep_palm;
mod sweep_rig;
mod sweep_skeleton;
mod sweep_surface;
mod sweep_webxr;
mod vmc_map;
