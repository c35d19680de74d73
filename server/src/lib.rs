//! crease-server: hosts live rooms on loaded models and streams encoded frames (gRPC via tonic,
//! HTTP + WebSocket via axum) — built by issue 6. Today this crate only fixes its place in the
//! workspace and its dependency rule: `crease-core` + `crease-proto`, nothing else of ours.
