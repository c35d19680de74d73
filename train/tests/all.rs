//! Every integration test of this crate in one test binary (`cargo test -p PACKAGE --test all`;
//! one module per file, `cargo test -p PACKAGE --test all MODULE::` runs one file's tests):
//! one link and one copy of the dependencies' generic code instead of one per file
//! (issue 41: the test build of `.ci/run`).
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

mod common;

mod bones_fit;
mod controls_auto;
mod coverage;
mod detail_extract;
mod detail_hand;
mod detail_layers;
mod detail_regress;
mod detail_split;
mod edge_vectors_fit;
mod edges_fit;
mod geodesic_paths;
mod kcca_regression;
mod mirror;
mod pipeline_cactus;
