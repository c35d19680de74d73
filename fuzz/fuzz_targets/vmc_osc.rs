//! VMC over OSC datagrams (the `crease bridge vmc` decoder), each applied to a bridge of the
//! right hand as the UDP loop does. The input is several datagrams, each prefixed by a
//! little-endian `u16` length.
#![no_main]
use crease_bridge::vmc::frames::Bridge;
use crease_bridge::vmc::osc::decode;
use crease_bridge::vmc::skeleton::{Hand, TipLengths};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let declared: Vec<String> = [
        "RightHand",
        "RightIndexProximal",
        "RightIndexTip",
        "tracker-7",
    ]
    .iter()
    .map(|s| (*s).to_owned())
    .collect();
    let mut bridge =
        Bridge::new("room", Hand::Right, TipLengths::default(), &declared).expect("a bridge");
    let mut rest = data;
    let mut t = 0i64;
    while let Some((len, tail)) = rest.split_first_chunk::<2>() {
        let len = usize::from(u16::from_le_bytes(*len)).min(tail.len());
        let (datagram, tail) = tail.split_at(len);
        rest = tail;
        if let Ok(d) = decode(datagram) {
            t += 16_000;
            if let Some(frame) = bridge.apply(&d, t).frame {
                assert_eq!(frame.markers.len(), 3 * declared.len());
            }
        }
    }
});
