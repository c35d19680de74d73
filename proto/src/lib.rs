//! crease-proto: the one wire contract, `proto/crease/v1/crease.proto` (package `crease.v1`),
//! compiled from `build.rs` with protox + tonic-prost-build, plus every `From`/`TryFrom` between
//! wire and core types. Built by issue 6; today the crate only holds its place.
