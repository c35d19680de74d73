//! NatNet datagrams (the `crease bridge natnet` decoder): the first byte picks the stream's
//! version (3.0, 3.1, 4.0, 4.1, 2.10), the rest is the datagram.
#![no_main]
use crease_bridge::natnet::wire::{Version, decode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&v, datagram)) = data.split_first() else {
        return;
    };
    let version = match v % 5 {
        0 => Version::new(3, 0),
        1 => Version::new(3, 1),
        2 => Version::new(4, 0),
        3 => Version::new(4, 1),
        _ => Version::new(2, 10),
    };
    let _ = decode(datagram, version);
});
