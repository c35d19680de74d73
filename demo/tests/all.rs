//! Every integration test of this crate in one test binary (`cargo test -p PACKAGE --test all`;
//! one module per file, `cargo test -p PACKAGE --test all MODULE::` runs one file's tests):
//! one link and one copy of the dependencies' generic code instead of one per file
//! (issue 41: the test build of `.ci/run`).
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

mod cluster_kit;
#[path = "../../server/tests/common/mod.rs"]
mod common;

mod cluster;
mod cluster_jobs;
mod cluster_trust;
mod crash_safe_cache;
mod demo;
mod deploy;
mod palette;
