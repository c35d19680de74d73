//! `crease bridge vmc` up to the ControlFrames it publishes: OSC decoding (datagrams built by
//! `rosc` here, and by a third-party sender, python-osc, in `tests/python/vmc_sender.py`),
//! forward kinematics against a chain computed by hand, the fingertips, the left- to
//! right-handed mirror, validity, and the UDP receive loop surviving junk, against a channel;
//! and the `crease bridge vmc` command end to end into a retargeting room of a server running
//! in this process, with a subscriber checking that the room's mesh follows the curl.

use crate::common;

use std::f32::consts::FRAC_1_SQRT_2 as H;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crease_bridge::vmc::frames::{Bridge, LoopOptions, Stats, receive_loop};
use crease_bridge::vmc::osc::decode;
use crease_bridge::vmc::skeleton::{Hand, TipLengths};
use crease_proto::{v1, valid_bit};
use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};

const ID: [f32; 4] = [0.0, 0.0, 0.0, 1.0];
/// 90 degrees about Unity's Y and Z.
const RY90: [f32; 4] = [0.0, H, 0.0, H];
const RZ90: [f32; 4] = [0.0, 0.0, H, H];

fn pose_msg(addr: &str, name: &str, p: [f32; 3], q: [f32; 4]) -> OscPacket {
    let mut args = vec![OscType::String(name.into())];
    args.extend(p.iter().chain(q.iter()).map(|v| OscType::Float(*v)));
    OscPacket::Message(OscMessage {
        addr: addr.into(),
        args,
    })
}

fn bone(name: &str, p: [f32; 3], q: [f32; 4]) -> OscPacket {
    pose_msg("/VMC/Ext/Bone/Pos", name, p, q)
}

fn ok() -> OscPacket {
    OscPacket::Message(OscMessage {
        addr: "/VMC/Ext/OK".into(),
        args: vec![OscType::Int(1)],
    })
}

fn bundle(content: Vec<OscPacket>) -> Vec<u8> {
    rosc::encoder::encode(&OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content,
    }))
    .unwrap()
}

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| (*s).to_owned()).collect()
}

/// The frame's marker `i`, or `None` when invalid.
fn marker(f: &v1::ControlFrame, i: usize) -> Option<[f32; 3]> {
    valid_bit(&f.markers_valid, i)
        .then(|| [f.markers[3 * i], f.markers[3 * i + 1], f.markers[3 * i + 2]])
}

fn assert_near(got: Option<[f32; 3]>, want: [f32; 3], what: &str) {
    let got = got.unwrap_or_else(|| panic!("{what}: invalid, expected {want:?}"));
    let d = (0..3)
        .map(|k| (got[k] - want[k]).abs())
        .fold(0.0f32, f32::max);
    assert!(
        d < 1e-5,
        "{what}: got {got:?}, expected {want:?} (off by {d})"
    );
}

/// The chain, computed by hand in Unity's frame (left-handed; quaternions rotate vectors by
/// the usual formula, so Ry(90) takes +X to -Z and Rz(90) takes +X to +Y):
/// - Hips at (0, 1, 0), identity;
/// - RightUpperArm at (0.2, 0.4, 0) local, Ry(90): global (0.2, 1.4, 0), rotation Ry(90);
/// - (RightShoulder, RightLowerArm not sent: the chain skips them)
/// - RightHand at (0.3, 0, 0) local: global (0.2, 1.4, 0) + Ry(90) (0.3, 0, 0) = (0.2, 1.4, -0.3);
/// - RightIndexProximal at (0.1, 0, 0), Rz(90): (0.2, 1.4, -0.4), rotation Ry(90) Rz(90);
/// - RightIndexIntermediate at (0.04, 0, 0), Rz(90): + Ry(90) Rz(90) (0.04, 0, 0) = + (0, 0.04, 0)
///   -> (0.2, 1.44, -0.4), rotation Ry(90) Rz(180);
/// - RightIndexDistal at (0.03, 0, 0), identity: + Ry(90) Rz(180) (0.03, 0, 0) = + (0, 0, 0.03)
///   -> (0.2, 1.44, -0.37), rotation Ry(90) Rz(180);
/// - RightIndexTip: + Ry(90) Rz(180) (0.8 x 0.03, 0, 0) = + (0, 0, 0.024) -> (0.2, 1.44, -0.346).
///
/// Right-handed (Z negated): hand (0.2, 1.4, 0.3), proximal (0.2, 1.4, 0.4), intermediate
/// (0.2, 1.44, 0.4), distal (0.2, 1.44, 0.37), tip (0.2, 1.44, 0.346).
fn analytic_chain(extra: Vec<OscPacket>) -> Vec<u8> {
    let mut content = vec![
        bone("Hips", [0.0, 1.0, 0.0], ID),
        bone("RightUpperArm", [0.2, 0.4, 0.0], RY90),
        bone("RightHand", [0.3, 0.0, 0.0], ID),
        bone("RightIndexProximal", [0.1, 0.0, 0.0], RZ90),
        bone("RightIndexIntermediate", [0.04, 0.0, 0.0], RZ90),
        bone("RightIndexDistal", [0.03, 0.0, 0.0], ID),
    ];
    content.extend(extra);
    bundle(content)
}

const DECLARED: [&str; 7] = [
    "RightHand",
    "RightIndexProximal",
    "RightIndexIntermediate",
    "RightIndexDistal",
    "RightIndexTip",
    "RightThumbTip",
    "Hips",
];

#[test]
fn forward_kinematics_matches_a_chain_computed_by_hand() {
    let mut b = Bridge::new("r", Hand::Right, TipLengths::default(), &names(&DECLARED)).unwrap();
    let d = decode(&analytic_chain(vec![ok()])).unwrap();
    let f = b
        .apply(&d, 42)
        .frame
        .expect("a bundle with hand bones is a frame");
    assert_eq!((f.room.as_str(), f.seq, f.capture_time_us), ("r", 0, 42));
    assert!(f.positions.is_empty() && f.markers.len() == 3 * DECLARED.len());
    assert_near(marker(&f, 0), [0.2, 1.4, 0.3], "RightHand");
    assert_near(marker(&f, 1), [0.2, 1.4, 0.4], "RightIndexProximal");
    assert_near(marker(&f, 2), [0.2, 1.44, 0.4], "RightIndexIntermediate");
    assert_near(marker(&f, 3), [0.2, 1.44, 0.37], "RightIndexDistal");
    assert_near(marker(&f, 4), [0.2, 1.44, 0.346], "RightIndexTip");
    assert_eq!(marker(&f, 5), None, "the thumb was not sent");
    assert_near(marker(&f, 6), [0.0, 1.0, 0.0], "Hips");

    // A root pose moves everything; a tip length from --bones replaces the ratio.
    let tips = TipLengths::parse("[tip_length]\nIndex = 0.01\n").unwrap();
    let mut b = Bridge::new("r", Hand::Right, tips, &names(&DECLARED)).unwrap();
    let root = pose_msg("/VMC/Ext/Root/Pos", "root", [1.0, 0.0, 2.0], ID);
    let mut with_root = vec![root];
    with_root.extend(decode_content(&analytic_chain(vec![])));
    let f = b
        .apply(&decode(&bundle(with_root)).unwrap(), 0)
        .frame
        .unwrap();
    assert_near(marker(&f, 0), [1.2, 1.4, -1.7], "RightHand under the root");
    assert_near(marker(&f, 4), [1.2, 1.44, -1.64], "RightIndexTip, 1 cm");

    // The next bundle without the distal: the distal and its tip are invalid, the rest
    // follows the new hand pose.
    let next = bundle(vec![
        bone("RightHand", [0.3, 0.1, 0.0], ID),
        bone("RightIndexProximal", [0.1, 0.0, 0.0], RZ90),
        bone("RightIndexIntermediate", [0.04, 0.0, 0.0], RZ90),
    ]);
    let f = b.apply(&decode(&next).unwrap(), 1).frame.unwrap();
    assert_eq!(f.seq, 1);
    assert_near(marker(&f, 0), [1.2, 1.5, -1.7], "RightHand moved");
    assert_eq!(marker(&f, 3), None, "the distal was not in this bundle");
    assert_eq!(marker(&f, 4), None, "nor its tip");
    assert_eq!(marker(&f, 6), None, "nor the hips");
}

fn decode_content(bytes: &[u8]) -> Vec<OscPacket> {
    match rosc::decoder::decode_udp(bytes).unwrap().1 {
        OscPacket::Bundle(b) => b.content,
        p => vec![p],
    }
}

#[test]
fn a_hand_subtree_alone_makes_the_hand_the_root_and_left_hands_mirror() {
    let declared = names(&["LeftHand", "LeftIndexProximal", "LeftIndexTip"]);
    let mut b = Bridge::new("r", Hand::Left, TipLengths::default(), &declared).unwrap();
    let d = bundle(vec![
        bone("LeftHand", [0.0, 0.0, 0.5], RY90),
        bone("LeftIndexProximal", [-0.1, 0.0, 0.0], ID),
        bone("LeftIndexIntermediate", [-0.04, 0.0, 0.0], ID),
        bone("LeftIndexDistal", [-0.03, 0.0, 0.0], ID),
    ]);
    let f = b.apply(&decode(&d).unwrap(), 0).frame.unwrap();
    // Unity: hand (0, 0, 0.5); Ry(90) takes -X to +Z: proximal (0, 0, 0.6), tip
    // (0, 0, 0.6 + 0.04 + 0.03 + 0.024). Mirrored: z negated.
    assert_near(marker(&f, 0), [0.0, 0.0, -0.5], "LeftHand");
    assert_near(marker(&f, 1), [0.0, 0.0, -0.6], "LeftIndexProximal");
    assert_near(marker(&f, 2), [0.0, 0.0, -0.694], "LeftIndexTip");
}

#[test]
fn loose_messages_make_a_frame_at_ok_and_bundles_without_hand_bones_make_none() {
    let declared = names(&["RightHand", "tracker-7"]);
    let mut b = Bridge::new("r", Hand::Right, TipLengths::default(), &declared).unwrap();
    assert_eq!(b.missing_trackers(), vec!["tracker-7"]);
    let enc = |p: &OscPacket| rosc::encoder::encode(p).unwrap();
    let hand = enc(&bone("RightHand", [0.1, 0.2, 0.3], ID));
    assert!(b.apply(&decode(&hand).unwrap(), 0).frame.is_none());
    let tra = enc(&pose_msg(
        "/VMC/Ext/Tra/Pos",
        "tracker-7",
        [1.0, 2.0, 3.0],
        ID,
    ));
    assert!(b.apply(&decode(&tra).unwrap(), 0).frame.is_none());
    let f = b
        .apply(&decode(&enc(&ok())).unwrap(), 5)
        .frame
        .expect("OK closes the loose frame");
    assert_near(marker(&f, 0), [0.1, 0.2, -0.3], "RightHand");
    assert_near(marker(&f, 1), [1.0, 2.0, -3.0], "tracker-7");
    assert!(b.missing_trackers().is_empty());
    // OK alone again: nothing new.
    assert!(b.apply(&decode(&enc(&ok())).unwrap(), 6).frame.is_none());
    // A bundle of body bones and a tracker only: no frame.
    let body = bundle(vec![
        bone("Hips", [0.0, 1.0, 0.0], ID),
        pose_msg("/VMC/Ext/Tra/Pos", "tracker-7", [0.0; 3], ID),
    ]);
    assert!(b.apply(&decode(&body).unwrap(), 7).frame.is_none());
    // The next hand bundle: the tracker of the bundle before is not fresh.
    let f = b
        .apply(
            &decode(&bundle(vec![bone("RightHand", [0.0; 3], ID)])).unwrap(),
            8,
        )
        .frame
        .unwrap();
    assert_eq!(f.seq, 1);
    assert_eq!(marker(&f, 1), None);
}

#[test]
fn both_hands_of_one_skeleton_go_to_their_actors_in_one_frame() {
    // A room of actors (issue 38): the right hand drives actor "r", the left actor "l"; each
    // actor's part of a frame is what a one-hand bridge of that side makes of the same bundle.
    let right = names(&["RightHand", "RightIndexProximal", "RightIndexTip", "Hips"]);
    let left = names(&["LeftHand", "LeftIndexProximal", "LeftIndexTip"]);
    let actors = vec![
        ("r".to_owned(), Hand::Right, right.clone()),
        ("l".to_owned(), Hand::Left, left.clone()),
    ];
    let mut both = Bridge::actors("room", &actors, TipLengths::default()).unwrap();
    let mut one_right = Bridge::new("room", Hand::Right, TipLengths::default(), &right).unwrap();
    let mut one_left = Bridge::new("room", Hand::Left, TipLengths::default(), &left).unwrap();
    let skeleton = |extra: Vec<OscPacket>| {
        let mut content = vec![
            bone("Hips", [0.0, 1.0, 0.0], ID),
            bone("RightUpperArm", [0.2, 0.4, 0.0], RY90),
            bone("LeftUpperArm", [-0.2, 0.4, 0.0], RZ90),
        ];
        content.extend(extra);
        decode(&bundle(content)).unwrap()
    };
    let hands = skeleton(vec![
        bone("RightHand", [0.3, 0.0, 0.0], ID),
        bone("RightIndexProximal", [0.1, 0.0, 0.0], RZ90),
        bone("RightIndexIntermediate", [0.04, 0.0, 0.0], RZ90),
        bone("RightIndexDistal", [0.03, 0.0, 0.0], ID),
        bone("LeftHand", [-0.3, 0.0, 0.0], RY90),
        bone("LeftIndexProximal", [-0.1, 0.0, 0.0], ID),
        bone("LeftIndexIntermediate", [-0.04, 0.0, 0.0], RZ90),
        bone("LeftIndexDistal", [-0.03, 0.0, 0.0], ID),
    ]);
    let f = both.apply(&hands, 7).frame.expect("a frame");
    assert!(
        f.markers.is_empty(),
        "a room of actors' frame carries its actors' parts"
    );
    assert_eq!((f.seq, f.capture_time_us), (0, 7));
    let parts: Vec<&str> = f.actors.iter().map(|a| a.actor.as_str()).collect();
    assert_eq!(parts, ["r", "l"]);
    let alone = [
        one_right.apply(&hands, 7).frame.unwrap(),
        one_left.apply(&hands, 7).frame.unwrap(),
    ];
    for (part, alone) in f.actors.iter().zip(&alone) {
        assert_eq!(part.markers, alone.markers, "actor {}", part.actor);
        assert_eq!(
            part.markers_valid, alone.markers_valid,
            "actor {}",
            part.actor
        );
    }
    // The hands sit apart, as the skeleton has them (the left arm turned the other way).
    assert_near(
        Some([
            part_marker(&f, 0, 0),
            part_marker(&f, 0, 1),
            part_marker(&f, 0, 2),
        ]),
        [0.2, 1.4, 0.3],
        "RightHand",
    );
    assert!((part_marker(&f, 1, 0) - part_marker(&f, 0, 0)).abs() > 0.3);
    // A bundle that moves the left hand only: a frame of the left actor alone (the right
    // holds its pose in the room).
    let f = both
        .apply(&skeleton(vec![bone("LeftHand", [-0.3, 0.0, 0.0], ID)]), 8)
        .frame
        .unwrap();
    let parts: Vec<&str> = f.actors.iter().map(|a| a.actor.as_str()).collect();
    assert_eq!((f.seq, parts), (1, vec!["l"]));
    // Two actors of one hand, and an actor declaring the other hand's bones, are named.
    let twice = vec![
        ("a".to_owned(), Hand::Right, right.clone()),
        ("b".to_owned(), Hand::Right, right.clone()),
    ];
    let e = Bridge::actors("room", &twice, TipLengths::default()).unwrap_err();
    assert!(
        e.to_string()
            .contains("\"a\" and \"b\" are both the right hand"),
        "{e}"
    );
    let crossed = vec![("l".to_owned(), Hand::Left, right)];
    let e = Bridge::actors("room", &crossed, TipLengths::default()).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("room \"room\" (actor \"l\") declares marker \"RightHand\""),
        "{e}"
    );
}

/// Coordinate `k` of the first marker of the frame's actor part `a`.
fn part_marker(f: &v1::ControlFrame, a: usize, k: usize) -> f32 {
    f.actors[a].markers[k]
}

#[test]
fn declared_names_the_stream_cannot_carry_are_errors_naming_them() {
    let e = Bridge::new(
        "r",
        Hand::Right,
        TipLengths::default(),
        &names(&["LeftIndexTip"]),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("\"LeftIndexTip\"") && e.contains("--hand"),
        "{e}"
    );
    assert!(
        e.contains("RightIndexTip") && e.contains("RightLittleDistal"),
        "lists what it carries: {e}"
    );
    let e = Bridge::new(
        "r",
        Hand::Right,
        TipLengths::default(),
        &names(&["LeftFoot"]),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("\"LeftFoot\""), "{e}");
}

/// Runs the receive loop on a loopback socket while `send` sends to its port; returns the
/// frames, the loop's stats and the bridge.
fn run_loop(
    declared: &[String],
    warn_after: Duration,
    send: impl FnOnce(u16) + Send + 'static,
) -> (anyhow::Result<Bridge>, Vec<v1::ControlFrame>, Stats) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let stats = Stats::default();
    let bridge = Bridge::new("r", Hand::Right, TipLengths::default(), declared).unwrap();
    let (tx, mut rx) = tokio::sync::mpsc::channel(100_000);
    let result = rt.block_on(async {
        let socket = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let port = socket.local_addr().unwrap().port();
        let sender = std::thread::spawn(move || send(port));
        let opts = LoopOptions {
            warn_after,
            idle_exit: Some(Duration::from_millis(1500)),
            summary_every: Some(Duration::from_secs(1)),
            listen: format!("127.0.0.1:{port}"),
        };
        let r = tokio::time::timeout(
            Duration::from_secs(60),
            receive_loop(socket, bridge, tx, &stats, &opts),
        )
        .await
        .expect("the loop ends within 60 s");
        sender.join().unwrap();
        r
    });
    let mut frames = Vec::new();
    while let Ok(f) = rx.try_recv() {
        frames.push(f);
    }
    (result, frames, stats)
}

fn count(c: &std::sync::atomic::AtomicU64) -> u64 {
    c.load(std::sync::atomic::Ordering::Relaxed)
}

#[test]
fn the_receive_loop_counts_and_survives_junk() {
    let declared = names(&["RightHand", "RightIndexTip"]);
    let (r, frames, stats) = run_loop(&declared, Duration::from_secs(30), |port| {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let to = ("127.0.0.1", port);
        for k in 0..20 {
            s.send_to(&analytic_chain(vec![ok()]), to).unwrap();
            if k % 4 == 0 {
                s.send_to(b"junk", to).unwrap();
                s.send_to(
                    &bundle(vec![bone("RightHand", [f32::INFINITY, 0.0, 0.0], ID)]),
                    to,
                )
                .unwrap();
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    });
    r.unwrap();
    assert_eq!(frames.len(), 20, "{}", stats.summary(false));
    assert_eq!(count(&stats.dropped), 10);
    assert_eq!(
        count(&stats.bundles),
        20,
        "malformed bundles are not counted as bundles"
    );
    assert_eq!(count(&stats.published), 20);
    assert!(frames.iter().enumerate().all(|(i, f)| f.seq == i as u64));
    assert_near(marker(&frames[19], 1), [0.2, 1.44, 0.346], "RightIndexTip");
}

#[test]
fn a_declared_tracker_that_never_comes_is_an_error_listing_the_stream() {
    let declared = names(&["RightHand", "LHR-MISSING"]);
    let (r, _, _) = run_loop(&declared, Duration::from_millis(300), |port| {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        for _ in 0..60 {
            s.send_to(&analytic_chain(vec![]), ("127.0.0.1", port))
                .unwrap();
            std::thread::sleep(Duration::from_millis(10));
        }
    });
    let e = r.unwrap_err().to_string();
    assert!(
        e.contains("\"LHR-MISSING\"") && e.contains("RightHand") && e.contains("trackers: none"),
        "{e}"
    );
}

// ---- The third-party sender (python-osc) ----

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// python-osc in a venv under target/ (made once); `Err` says why not.
fn python_osc() -> Result<PathBuf, String> {
    crease_testkit::python::python_osc(&repo())
}

/// The sender's motion (tests/python/vmc_sender.py's docstring), recomputed: Unity positions of
/// a finger's joints and tip at curl `theta`, hand at `hand`.
fn curled(hand: [f32; 3], base: [f32; 3], seg: [f32; 2], theta: f32) -> [[f32; 3]; 4] {
    let p = [hand[0] + base[0], hand[1] + base[1], hand[2] + base[2]];
    let step = |from: [f32; 3], len: f32, angle: f32| {
        [
            from[0] + len * angle.cos(),
            from[1] + len * angle.sin(),
            from[2],
        ]
    };
    let i = step(p, seg[0], theta);
    let d = step(i, seg[1], 2.0 * theta);
    let t = step(d, 0.8 * seg[1], 3.0 * theta);
    [p, i, d, t]
}

#[test]
fn python_osc_bundles_each_make_a_frame_that_follows_the_curl() {
    let python = match python_osc() {
        Ok(p) => p,
        Err(why) => {
            println!("skipped: no python-osc venv ({why})");
            return;
        }
    };
    const FINGERS: [&str; 5] = ["Thumb", "Index", "Middle", "Ring", "Little"];
    const BASE: [[f32; 3]; 5] = [
        [0.03, -0.01, 0.04],
        [0.09, 0.0, 0.03],
        [0.095, 0.0, 0.01],
        [0.09, 0.0, -0.01],
        [0.08, 0.0, -0.03],
    ];
    const SEG: [[f32; 2]; 5] = [
        [0.035, 0.03],
        [0.045, 0.025],
        [0.05, 0.03],
        [0.045, 0.028],
        [0.035, 0.022],
    ];
    let mut declared = vec!["frame-counter".to_owned(), "RightHand".to_owned()];
    for f in FINGERS {
        for s in ["Proximal", "Intermediate", "Distal", "Tip"] {
            declared.push(format!("Right{f}{s}"));
        }
    }
    let script = repo().join("tests/python/vmc_sender.py");
    let (tx, rx) = std::sync::mpsc::channel();
    let (r, frames, stats) = run_loop(&declared, Duration::from_secs(30), move |port| {
        let out = Command::new(&python)
            .arg(&script)
            .args([
                "--port",
                &port.to_string(),
                "--seconds",
                "2",
                "--rate",
                "60",
            ])
            .output()
            .unwrap();
        tx.send(out).unwrap();
    });
    let out = rx.recv().unwrap();
    assert!(
        out.status.success(),
        "vmc_sender.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sent: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let bundles = sent["bundles"].as_u64().unwrap();
    let junk = sent["junk"].as_u64().unwrap();
    r.unwrap();
    println!("sender: {sent}; bridge: {}", stats.summary(false));
    assert_eq!(bundles, 120);
    assert_eq!(frames.len() as u64, bundles, "every bundle yields a frame");
    assert_eq!(
        count(&stats.dropped),
        junk,
        "every junk datagram is counted"
    );
    assert!(junk >= 5, "the sender sent junk of every kind");
    assert_eq!(count(&stats.datagrams), bundles + junk);
    let hand = [0.5 + 0.35, 1.0 + 0.45, 0.25 + 0.05];
    let mut tip_y = Vec::new();
    for (n, f) in frames.iter().enumerate() {
        assert!(f.markers_valid.is_empty(), "frame {n}: every marker valid");
        let k = (marker(f, 0).unwrap()[0] * 1000.0).round() as usize;
        assert_eq!(k, n, "frames in bundle order");
        let theta = std::f32::consts::FRAC_PI_2 * k as f32 / (bundles - 1) as f32;
        assert_near(marker(f, 1), [hand[0], hand[1], -hand[2]], "RightHand");
        for (d, finger) in FINGERS.iter().enumerate() {
            let want = curled(hand, BASE[d], SEG[d], theta);
            for (j, s) in ["Proximal", "Intermediate", "Distal", "Tip"]
                .iter()
                .enumerate()
            {
                let w = want[j];
                assert_near(
                    marker(f, 2 + 4 * d + j),
                    [w[0], w[1], -w[2]],
                    &format!("bundle {k}: Right{finger}{s}"),
                );
            }
        }
        tip_y.push(marker(f, 2 + 4 + 3).unwrap()[1]);
    }
    // The index tip rises as the finger curls (up to 3 x 90 degrees of the last segment, so
    // not monotonic to the end: it peaks, then comes back over the top).
    let (first, top) = (tip_y[0], tip_y.iter().copied().fold(f32::MIN, f32::max));
    assert!(
        top > first + 0.05,
        "the index tip moved up {} m",
        top - first
    );
}

// ---- End to end: `crease bridge vmc` into a retargeting room ----

/// A bundle of the right hand with every finger curled by `theta` (the sender's motion).
fn curl_bundle(k: usize, theta: f32) -> Vec<u8> {
    let (s, c) = (theta / 2.0).sin_cos();
    let q = [0.0, 0.0, s, c];
    let mut content = vec![bone("RightHand", [0.35, 1.45, 0.05], ID)];
    for (f, z) in ["Thumb", "Index", "Middle", "Ring", "Little"]
        .iter()
        .zip([0.04, 0.03, 0.01, -0.01, -0.03])
    {
        content.push(bone(&format!("Right{f}Proximal"), [0.09, 0.0, z], q));
        content.push(bone(&format!("Right{f}Intermediate"), [0.045, 0.0, 0.0], q));
        content.push(bone(&format!("Right{f}Distal"), [0.028, 0.0, 0.0], q));
    }
    content.push(pose_msg(
        "/VMC/Ext/Tra/Pos",
        "frame-counter",
        [k as f32, 0.0, 0.0],
        ID,
    ));
    content.push(ok());
    bundle(content)
}

/// Runs `crease bridge vmc` into `room` until idle, sends `bundles` to it at 60 Hz (junk after
/// every `junk_every`-th, counted as malformed), and returns its exit status and stderr.
async fn run_bridge(
    addr: std::net::SocketAddr,
    room: &str,
    token: &str,
    bundles: Vec<Vec<u8>>,
    junk_every: usize,
) -> (std::process::ExitStatus, String) {
    use std::io::BufRead;
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut child = common::crease()
        .args([
            "bridge",
            "vmc",
            "--server",
            &format!("http://{addr}"),
            "--room",
            room,
        ])
        .args(["--listen", &format!("127.0.0.1:{port}"), "--token", token])
        .args(["--idle-exit", "1", "--summary-every", "1"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (lines_tx, lines_rx) = std::sync::mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            if lines_tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut log = Vec::new();
    loop {
        let line = lines_rx
            .recv_timeout(Duration::from_secs(30))
            .expect("the bridge starts");
        let ready = line.contains("listening on");
        log.push(line);
        if ready {
            break;
        }
    }
    let sent = tokio::task::spawn_blocking(move || {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let start = std::time::Instant::now();
        for (k, b) in bundles.iter().enumerate() {
            s.send_to(b, ("127.0.0.1", port)).unwrap();
            if k % junk_every == 7 {
                s.send_to(b"\x00\x01junk", ("127.0.0.1", port)).unwrap();
            }
            let next = start + Duration::from_secs_f64((k + 1) as f64 / 60.0);
            std::thread::sleep(next.saturating_duration_since(std::time::Instant::now()));
        }
    });
    sent.await.unwrap();
    let status = tokio::task::spawn_blocking(move || child.wait().unwrap())
        .await
        .unwrap();
    while let Ok(line) = lines_rx.recv_timeout(Duration::from_secs(5)) {
        log.push(line);
    }
    let log = log.join("\n");
    println!("{log}");
    (status, log)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn crease_bridge_vmc_publishes_every_bundle_into_a_retargeting_room() {
    let tmp = tempfile::tempdir().unwrap();
    let model = crease_core::model::TrainedModel::load(common::train_model(tmp.path())).unwrap();
    let controls: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    let served = common::serve_tube(model, Some("admin")).await;
    let addr = served.grpc;
    // The tube's five control points driven by five hand markers; the tracker is declared too
    // (extra markers are allowed).
    let drivers = [
        "RightHand",
        "RightIndexProximal",
        "RightIndexTip",
        "RightLittleProximal",
        "RightLittleTip",
    ];
    let mut map = format!(
        "[registration]\npoints = [{}]\ncalibration_frames = 10\n[markers]\n",
        controls
            .iter()
            .map(|c| format!("{c:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (c, m) in controls.iter().zip(drivers) {
        map += &format!("{c} = {m:?}\n");
    }
    let markers: Vec<String> = drivers
        .iter()
        .map(|s| (*s).to_owned())
        .chain(["frame-counter".to_owned()])
        .collect();
    let token = common::open_room(
        addr,
        "admin",
        v1::OpenRoomRequest {
            room: "vmc".into(),
            model: "tube".into(),
            retarget: Some(v1::Retarget {
                map_toml: map,
                markers,
                units: "m".into(),
                ..Default::default()
            }),
            ..Default::default()
        },
    )
    .await;
    // A subscriber to the room's base mesh, decoding every frame it gets (model order).
    let mut sub = crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{addr}"))
        .await
        .unwrap()
        .subscribe(v1::SubscribeRequest {
            room: "vmc".into(),
            level: v1::Level::Base as i32,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let first = sub.message().await.unwrap().unwrap();
    let Some(v1::mesh_frame::Body::Topology(topo)) = first.body else {
        panic!("first message is not the topology: {first:?}");
    };
    let topology = crease_proto::read_topology(&topo).unwrap();
    let subscriber = tokio::spawn(async move {
        let mut decoder = crease_core::codec::FrameDecoder::new(topology.vertex_count);
        let mut out = std::collections::BTreeMap::new();
        let (mut streamed, mut model) = (Vec::new(), Vec::new());
        while let Ok(Some(m)) = sub.message().await {
            let Some(v1::mesh_frame::Body::Frame(f)) = m.body else {
                continue;
            };
            decoder
                .decode(&f.data)
                .unwrap_or_else(|e| panic!("frame {}: {e}", f.seq));
            decoder.positions(&mut streamed);
            topology.to_model_order(&streamed, &mut model);
            out.insert(f.seq, model.clone());
            if f.seq as usize == N - 1 {
                break;
            }
        }
        out
    });
    const N: usize = 90;
    let bundles = (0..N)
        .map(|k| curl_bundle(k, std::f32::consts::FRAC_PI_2 * k as f32 / (N - 1) as f32))
        .collect();
    let (status, log) = run_bridge(addr, "vmc", &token, bundles, 15).await;
    assert!(status.success(), "crease bridge vmc failed:\n{log}");
    let last = log
        .lines()
        .rev()
        .find(|l| l.starts_with("vmc: done: "))
        .unwrap();
    assert!(
        last.contains(&format!(
            "{} datagrams ({N} bundles) in, {N} frames built, {N} published ({N} acked, 0 refused",
            N + 6
        )),
        "{last}"
    );
    assert!(
        last.contains("6 malformed datagrams dropped") && last.contains("p50"),
        "{last}"
    );
    let mut client =
        crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
    let info = client
        .get_room(v1::GetRoomRequest { room: "vmc".into() })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.published, N as u64);

    // The mesh follows the curl: the subscriber has the last bundle's mesh, the meshes change
    // over the bundles, and the tip of the tube (driven by the fingertips) moves between the
    // first and the last.
    let meshes = tokio::time::timeout(Duration::from_secs(20), subscriber)
        .await
        .expect("the last mesh arrives")
        .unwrap();
    assert!(
        meshes.contains_key(&(N as u64 - 1)),
        "the last bundle's mesh"
    );
    let seqs: Vec<u64> = meshes.keys().copied().collect();
    let moved = |a: u64, b: u64| {
        meshes[&a]
            .iter()
            .zip(&meshes[&b])
            .map(|(p, q)| p.distance(*q))
            .fold(0.0f32, f32::max)
    };
    let changed = seqs.windows(2).filter(|w| moved(w[0], w[1]) > 1e-4).count();
    let (first, last) = (seqs[0], *seqs.last().unwrap());
    let rms = (meshes[&first]
        .iter()
        .zip(&meshes[&last])
        .map(|(p, q)| p.distance_squared(*q))
        .sum::<f32>()
        / meshes[&first].len() as f32)
        .sqrt();
    println!(
        "vmc: {} of {N} meshes received; {changed} of {} consecutive pairs differ; first (seq \
         {first}) to last (seq {last}): vertices moved up to {:.4}, RMS {rms:.4} model units (the \
         tube is 7 long)",
        meshes.len(),
        seqs.len() - 1,
        moved(first, last)
    );
    assert!(
        meshes.len() >= N / 2,
        "most meshes reach an attentive subscriber"
    );
    assert!(
        changed * 10 >= (seqs.len() - 1) * 9,
        "the mesh changes from bundle to bundle as the fingers curl"
    );
    // 12-bit frames of a box some 10 units wide quantise to ~0.003: a twentieth of a unit
    // is well clear of that (measured: 0.13 max, 0.10 RMS; the bridge's own figure, the
    // marker residual RMS in the summary, is ~0.06 m).
    assert!(
        moved(first, last) > 0.05 && rms > 0.02,
        "the curl moves the mesh: {} model units",
        moved(first, last)
    );
}

/// A bundle of both hands, each with its fingers curled by `theta`: the right hand as
/// [`curl_bundle`] has it, the left its mirror image across Unity's x = 0.
fn two_hand_bundle(theta: f32) -> Vec<u8> {
    let (s, c) = (theta / 2.0).sin_cos();
    let mut content = vec![
        bone("RightHand", [0.35, 1.45, 0.05], ID),
        bone("LeftHand", [-0.35, 1.45, 0.05], ID),
    ];
    for (side, sx, q) in [
        ("Right", 1.0, [0.0, 0.0, s, c]),
        ("Left", -1.0, [0.0, 0.0, -s, c]),
    ] {
        for (f, z) in ["Index", "Little"].iter().zip([0.03, -0.03]) {
            content.push(bone(&format!("{side}{f}Proximal"), [sx * 0.09, 0.0, z], q));
            content.push(bone(
                &format!("{side}{f}Intermediate"),
                [sx * 0.045, 0.0, 0.0],
                q,
            ));
            content.push(bone(&format!("{side}{f}Distal"), [sx * 0.028, 0.0, 0.0], q));
        }
    }
    content.push(ok());
    bundle(content)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn crease_bridge_vmc_publishes_both_hands_into_a_room_of_actors() {
    // Issue 38: a room of two actors on the tube, the right hand driving `right`, the left
    // (the tube mirrored) driving `left`, each through a map of its hand's bones: the bridge
    // reads the actors from the room and every bundle makes one frame the room accepts
    // (what each actor's part holds: both_hands_of_one_skeleton_go_to_their_actors_in_one_frame).
    let tmp = tempfile::tempdir().unwrap();
    let model = crease_core::model::TrainedModel::load(common::train_model(tmp.path())).unwrap();
    let controls: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    let served = common::serve_tube(model, Some("admin")).await;
    let addr = served.grpc;
    let actor = |side: &str, mirror: &str| {
        let drivers = [
            "Hand",
            "IndexProximal",
            "IndexTip",
            "LittleProximal",
            "LittleTip",
        ]
        .map(|d| format!("{}{d}", if side == "right" { "Right" } else { "Left" }));
        let mut map = format!(
            "[registration]\npoints = [{}]\ncalibration_frames = 10\n[markers]\n",
            controls
                .iter()
                .map(|c| format!("{c:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        for (c, m) in controls.iter().zip(&drivers) {
            map += &format!("{c} = {m:?}\n");
        }
        v1::Actor {
            name: side.into(),
            model: "tube".into(),
            side: side.into(),
            mirror: mirror.into(),
            performer: "vmc".into(),
            retarget: Some(v1::Retarget {
                map_toml: map,
                markers: drivers.to_vec(),
                units: "m".into(),
                ..Default::default()
            }),
            ..Default::default()
        }
    };
    let token = common::open_room(
        addr,
        "admin",
        v1::OpenRoomRequest {
            room: "hands".into(),
            actors: vec![actor("right", ""), actor("left", "x")],
            ..Default::default()
        },
    )
    .await;
    const N: usize = 40;
    let bundles = (0..N)
        .map(|k| two_hand_bundle(std::f32::consts::FRAC_PI_2 * k as f32 / (N - 1) as f32))
        .collect();
    let (status, log) = run_bridge(addr, "hands", &token, bundles, usize::MAX).await;
    assert!(status.success(), "crease bridge vmc failed:\n{log}");
    assert!(
        log.contains("the right hand as actor \"right\" (5 markers) and the left hand as actor \"left\" (5 markers)"),
        "{log}"
    );
    let last = log
        .lines()
        .rev()
        .find(|l| l.starts_with("vmc: done: "))
        .unwrap();
    assert!(
        last.contains(&format!(
            "{N} frames built, {N} published ({N} acked, 0 refused"
        )),
        "{last}"
    );
    let info = crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{addr}"))
        .await
        .unwrap()
        .get_room(v1::GetRoomRequest {
            room: "hands".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.published, N as u64);
}
