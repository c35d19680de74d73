//! One module per subcommand, plus the pieces they share.

pub mod bench_net;
pub mod bridge;
pub mod common;
pub mod decode_stream;
pub mod eval;
pub mod fit;
pub mod handgen;
pub mod job;
pub mod layers;
pub mod model;
pub mod remote_synth;
pub mod report;
pub mod retarget;
pub mod room;
pub mod stream;
pub mod synth;
pub mod take;
pub mod take_export;
pub mod train;
pub mod training_args;
pub mod watch;
