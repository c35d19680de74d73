//! crease-remote: a client of a crease server, shared by every program that talks to one (the
//! `crease` command, the capture bridges, `crease-bench`). It does not depend on the server.
//! [`percentile`] is the one percentile of the tree's latency summaries.
//!
//! Layout:
//! - [`client`]: the one gRPC `connect` (plain or TLS), a room's description, bearer tokens,
//!   the wire's capture clock.
//! - [`publish`]: the one publish loop (control frames out, acks in) every publisher runs
//!   through, with its source (a `Sink`), ack handler (`Acks`) and the
//!   seq -> time log round trips are measured with.
//! - [`mesh_stream`]: the one mesh-stream reader: subscribe, topology, decoding with the
//!   codec's `FrameDecoder`, positions in model order; palette streams too.
//! - [`control_file`]: control-frame files (CSV/JSON) read by `synth`, `stream` and
//!   `bench-net`, written by `retarget`.

pub mod client;
pub mod control_file;
pub mod mesh_stream;
pub mod publish;

pub use client::{MAX_RESPONSE_BYTES, authorized, connect, get_room, unix_us};

/// Percentile `p` (0..=100) of sorted values by nearest rank: the smallest value with at least
/// `p`% of the sample at or below it; the default value when empty.
pub fn percentile<T: Copy + Default>(sorted: &[T], p: f64) -> T {
    if sorted.is_empty() {
        return T::default();
    }
    let k = (p / 100.0 * sorted.len() as f64).ceil() as usize;
    sorted[k.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<u32> = (1..=100).collect();
        assert_eq!(percentile(&v, 50.0), 50);
        assert_eq!(percentile(&v, 99.0), 99);
        assert_eq!(percentile(&v, 100.0), 100);
        assert_eq!(percentile(&v, 0.0), 1);
        assert_eq!(percentile(&[7i64], 99.0), 7);
        assert_eq!(percentile::<u64>(&[], 50.0), 0);
        // Four values: the median is the second (half of them at or below it).
        assert_eq!(percentile(&[1, 2, 3, 4], 50.0), 2);
    }
}
