//! Every integration test of this crate in one test binary (`cargo test -p PACKAGE --test all`;
//! one module per file, `cargo test -p PACKAGE --test all MODULE::` runs one file's tests):
//! one link and one copy of the dependencies' generic code instead of one per file
//! (issue 41: the test build of `.ci/run`).
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

mod common;
mod source_scan;

mod bridge_natnet_room;
mod bridge_vmc;
mod cli_bench_net;
mod cli_coverage;
mod cli_detail;
mod cli_fit;
mod cli_handgen;
mod cli_job;
mod cli_mocap;
mod cli_model;
mod cli_report;
mod cli_synth_gltf;
mod cli_synth_remote;
mod cli_take;
mod cli_watch;
mod crash_safe_files;
mod fuzz_regressions;
mod house_rules;
mod layouts;
mod module_cycles;
mod wire_shapes;
