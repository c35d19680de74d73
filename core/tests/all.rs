//! Every integration test of this crate in one test binary (`cargo test -p PACKAGE --test all`;
//! one module per file, `cargo test -p PACKAGE --test all MODULE::` runs one file's tests):
//! one link and one copy of the dependencies' generic code instead of one per file
//! (issue 41: the test build of `.ci/run`).
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

mod common;

mod codec;
mod fuzz_regressions;
mod mesh_examples;
mod mesh_io;
mod model_gltf;
mod model_rig_file;
mod refine;
mod skin_dqs;
mod skin_lbs;
mod skin_weights;
mod subdivision;
mod translations_solver;
