//! VMC messages out of OSC datagrams (`rosc`): a datagram is one OSC packet, a message or a
//! bundle of packets (bundles nest). The messages the bridge reads:
//!
//! | address | arguments |
//! | --- | --- |
//! | `/VMC/Ext/Bone/Pos` | name, px, py, pz, qx, qy, qz, qw (local to the parent bone) |
//! | `/VMC/Ext/Root/Pos` | name, px, py, pz, qx, qy, qz, qw (global), optionally 3 scale + 3 offset (VMC 2.1) |
//! | `/VMC/Ext/Tra/Pos` | serial, px, py, pz, qx, qy, qz, qw (global) |
//! | `/VMC/Ext/OK` | loaded, ... (any) |
//! | `/VMC/Ext/T` | time, seconds (float) |
//!
//! Numbers may come as OSC floats, doubles or ints. Every other address is ignored. A datagram
//! that is not OSC, has bytes past its packet, or holds one of these messages with the wrong
//! argument count or types, or a non-finite value, is malformed: the whole datagram is refused
//! ([`decode`] returns why) and nothing of it is applied.

use rosc::{OscPacket, OscType};

use super::skeleton::Pose;

/// One VMC message the bridge uses, its pose already mirrored into the right-handed frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Vmc {
    /// `/VMC/Ext/Bone/Pos`: a bone's pose local to its parent.
    Bone {
        /// The HumanBodyBones name.
        name: String,
        /// Local to the parent bone.
        pose: Pose,
    },
    /// `/VMC/Ext/Root/Pos`: the avatar root's global pose.
    Root {
        /// Global.
        pose: Pose,
    },
    /// `/VMC/Ext/Tra/Pos`: a tracker's global pose.
    Tracker {
        /// The tracker's serial (its marker name).
        serial: String,
        /// Global.
        pose: Pose,
    },
    /// `/VMC/Ext/OK`: the sender's end-of-frame status message.
    Ok,
    /// `/VMC/Ext/T`: the sender's clock, seconds.
    Time(f64),
}

/// A decoded datagram: its VMC messages in order, and whether it was a bundle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Datagram {
    /// The messages the bridge reads, in order (nested bundles flattened).
    pub messages: Vec<Vmc>,
    /// A bundle (a frame by itself), or a loose message.
    pub bundle: bool,
    /// OSC messages in it that the bridge ignores (other addresses).
    pub ignored: usize,
}

/// Decodes one datagram.
///
/// # Errors
/// Why the datagram is malformed (module docs).
pub fn decode(bytes: &[u8]) -> Result<Datagram, String> {
    let (rest, packet) = rosc::decoder::decode_udp(bytes).map_err(|e| format!("not OSC: {e}"))?;
    if !rest.is_empty() {
        return Err(format!("{} bytes past the OSC packet", rest.len()));
    }
    let mut out = Datagram {
        bundle: matches!(packet, OscPacket::Bundle(_)),
        ..Datagram::default()
    };
    walk(&packet, &mut out)?;
    Ok(out)
}

fn walk(packet: &OscPacket, out: &mut Datagram) -> Result<(), String> {
    match packet {
        OscPacket::Bundle(b) => b.content.iter().try_for_each(|p| walk(p, out)),
        OscPacket::Message(m) => {
            let args = &m.args;
            let msg = match m.addr.as_str() {
                "/VMC/Ext/Bone/Pos" => {
                    let (name, pose) = named_pose(&m.addr, args, &[8])?;
                    Vmc::Bone { name, pose }
                }
                "/VMC/Ext/Root/Pos" => {
                    let (_, pose) = named_pose(&m.addr, args, &[8, 14])?;
                    Vmc::Root { pose }
                }
                "/VMC/Ext/Tra/Pos" => {
                    let (serial, pose) = named_pose(&m.addr, args, &[8])?;
                    Vmc::Tracker { serial, pose }
                }
                "/VMC/Ext/OK" => Vmc::Ok,
                "/VMC/Ext/T" => {
                    if args.len() != 1 {
                        return Err(format!("{}: {} arguments, expected 1", m.addr, args.len()));
                    }
                    let t = number(&args[0])
                        .filter(|t| t.is_finite())
                        .ok_or_else(|| format!("{}: {:?} is not a finite time", m.addr, args[0]))?;
                    Vmc::Time(t)
                }
                _ => {
                    out.ignored += 1;
                    return Ok(());
                }
            };
            out.messages.push(msg);
            Ok(())
        }
    }
}

fn number(a: &OscType) -> Option<f64> {
    match a {
        OscType::Float(v) => Some(f64::from(*v)),
        OscType::Double(v) => Some(*v),
        OscType::Int(v) => Some(f64::from(*v)),
        _ => None,
    }
}

/// A name and a pose (3 position, 4 quaternion xyzw); `counts` are the argument counts allowed
/// (extra arguments past the eighth are checked to be numbers and otherwise unused).
fn named_pose(addr: &str, args: &[OscType], counts: &[usize]) -> Result<(String, Pose), String> {
    if !counts.contains(&args.len()) {
        let want: Vec<String> = counts.iter().map(usize::to_string).collect();
        return Err(format!(
            "{addr}: {} arguments, expected {} (name, 3 position, 4 rotation{})",
            args.len(),
            want.join(" or "),
            if counts.len() > 1 {
                ", optionally 3 scale and 3 offset"
            } else {
                ""
            }
        ));
    }
    let OscType::String(name) = &args[0] else {
        return Err(format!(
            "{addr}: argument 0 is {:?}, expected a name",
            args[0]
        ));
    };
    let mut v = [0f32; 7];
    for (i, a) in args[1..].iter().enumerate() {
        let x = number(a).filter(|x| x.is_finite()).ok_or_else(|| {
            format!(
                "{addr} {name}: argument {} is {a:?}, expected a finite number",
                i + 1
            )
        })?;
        if i < 7 {
            v[i] = x as f32;
        }
    }
    let pose = Pose::from_unity([v[0], v[1], v[2]], [v[3], v[4], v[5], v[6]])
        .ok_or_else(|| format!("{addr} {name}: the rotation is not a quaternion (zero length)"))?;
    Ok((name.clone(), pose))
}

#[cfg(test)]
mod tests {
    use rosc::{OscBundle, OscMessage, OscTime};

    use super::*;

    fn msg(addr: &str, args: Vec<OscType>) -> OscPacket {
        OscPacket::Message(OscMessage {
            addr: addr.into(),
            args,
        })
    }

    fn bone(name: &str, p: [f32; 3], q: [f32; 4]) -> OscPacket {
        let mut args = vec![OscType::String(name.into())];
        args.extend(p.iter().chain(q.iter()).map(|v| OscType::Float(*v)));
        msg("/VMC/Ext/Bone/Pos", args)
    }

    fn bundle(content: Vec<OscPacket>) -> OscPacket {
        OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content,
        })
    }

    fn enc(p: &OscPacket) -> Vec<u8> {
        rosc::encoder::encode(p).unwrap()
    }

    #[test]
    fn nested_bundles_flatten_in_order_and_mirror() {
        let p = bundle(vec![
            bone("RightHand", [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]),
            bundle(vec![
                msg(
                    "/VMC/Ext/Blend/Val",
                    vec![OscType::String("A".into()), OscType::Float(1.0)],
                ),
                msg("/VMC/Ext/T", vec![OscType::Float(1.5)]),
            ]),
            msg("/VMC/Ext/OK", vec![OscType::Int(1)]),
        ]);
        let d = decode(&enc(&p)).unwrap();
        assert!(d.bundle);
        assert_eq!(d.ignored, 1);
        assert_eq!(d.messages.len(), 3);
        let Vmc::Bone { name, pose } = &d.messages[0] else {
            panic!("{:?}", d.messages[0])
        };
        assert_eq!(name, "RightHand");
        assert_eq!(pose.position.to_array(), [1.0, 2.0, -3.0]);
        assert_eq!(d.messages[1], Vmc::Time(1.5));
        assert_eq!(d.messages[2], Vmc::Ok);
    }

    #[test]
    fn malformed_datagrams_say_why() {
        assert!(decode(b"hello, not osc").is_err());
        assert!(decode(&[]).is_err());
        let short = msg(
            "/VMC/Ext/Bone/Pos",
            vec![OscType::String("RightHand".into()), OscType::Float(0.0)],
        );
        assert!(decode(&enc(&short)).unwrap_err().contains("2 arguments"));
        let mut args = vec![OscType::Int(3)];
        args.extend([0.0f32; 7].iter().map(|v| OscType::Float(*v)));
        let no_name = msg("/VMC/Ext/Bone/Pos", args);
        assert!(
            decode(&enc(&no_name))
                .unwrap_err()
                .contains("expected a name")
        );
        let nan = bone("RightHand", [f32::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]);
        assert!(
            decode(&enc(&bundle(vec![nan])))
                .unwrap_err()
                .contains("finite")
        );
        let zero = bone("RightHand", [0.0; 3], [0.0; 4]);
        assert!(decode(&enc(&zero)).unwrap_err().contains("quaternion"));
        let mut trailing = enc(&bone("RightHand", [0.0; 3], [0.0, 0.0, 0.0, 1.0]));
        trailing.extend_from_slice(&[0, 0, 0, 0]);
        assert!(decode(&trailing).is_err());
        // A loose message, ints as numbers.
        let mut args = vec![OscType::String("root".into())];
        args.extend([0, 0, 0, 0, 0, 0, 1].iter().map(|v| OscType::Int(*v)));
        let d = decode(&enc(&msg("/VMC/Ext/Root/Pos", args))).unwrap();
        assert!(!d.bundle);
        assert!(matches!(d.messages[0], Vmc::Root { .. }));
    }
}
