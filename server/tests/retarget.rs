//! Rooms that retarget (issue 19): a room opened with a marker map takes the capture's raw
//! markers (`ControlFrame.markers`, in the capture's units and frame) and runs the
//! registration (rigid + a scale fitted on the first frames) before predicting. Checked
//! against the same frames sent as control points to a plain room: the same residual, and the
//! capture-units residual is the model one divided by the fitted scale. Bad input is refused
//! naming what is wrong.

use crate::common;

use common::{authed, bent, model, serve_model, unthrottled};
use crease_core::glam::{Quat, Vec3};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;

const ADMIN: &str = "admin-secret";

/// The capture: millimetres, rotated and moved (model = 0.001 R^-1 (capture - t)).
fn to_capture(p: Vec3) -> Vec3 {
    Quat::from_rotation_y(0.7) * (p * 1000.0) + Vec3::new(250.0, -40.0, 900.0)
}

async fn publish(
    client: &mut CreaseClient<tonic::transport::Channel>,
    token: &str,
    frames: Vec<v1::ControlFrame>,
) -> Vec<v1::PublishAck> {
    let mut acks = client
        .publish(authed(tokio_stream::iter(frames), token))
        .await
        .unwrap()
        .into_inner();
    let mut out = Vec::new();
    while let Some(a) = acks.message().await.unwrap() {
        out.push(a);
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_retargeting_room_registers_raw_markers_and_names_bad_input() {
    let model = model();
    let running = serve_model("tube", &model, Some(ADMIN), unthrottled()).await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let names: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    // Markers "M0".. drive the control points; an extra marker "X" is declared and ignored.
    let mut toml = String::from("[registration]\npoints = [");
    toml += &names
        .iter()
        .map(|n| format!("{n:?}"))
        .collect::<Vec<_>>()
        .join(", ");
    toml += "]\ncalibration_frames = 3\n[markers]\n";
    for (i, n) in names.iter().enumerate() {
        toml += &format!("{n} = \"M{i}\"\n");
    }
    let markers: Vec<String> = (0..names.len())
        .map(|i| format!("M{i}"))
        .chain(["X".to_owned()])
        .collect();
    let retarget = v1::Retarget {
        map_toml: toml.clone(),
        markers: markers.clone(),
        units: "mm".into(),
        ..Default::default()
    };
    let open = |room: &str, retarget: Option<v1::Retarget>| v1::OpenRoomRequest {
        room: room.into(),
        model: "tube".into(),
        retarget,
        ..Default::default()
    };
    let token = client
        .open_room(authed(open("cap", Some(retarget.clone())), ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let plain = client
        .open_room(authed(open("plain", None), ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let info = client
        .get_room(v1::GetRoomRequest { room: "cap".into() })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.retarget.as_ref().unwrap().markers, markers);

    // The same poses as markers in the capture's frame; and retargeted here by crease-mocap
    // itself (what `crease stream` did locally before rooms retargeted), sent as control points
    // to a plain room: the two rooms must agree frame by frame.
    let map =
        crease_mocap::map::MarkerMap::parse(std::path::Path::new("test.toml"), &toml).unwrap();
    let recording =
        crease_mocap::Recording::new(markers.clone(), 0.0, "mm", Vec::new(), Vec::new());
    let bound = map.bind(&recording, &names).unwrap();
    let rest: Vec<Vec3> = model
        .controls
        .iter()
        .map(|c| model.rig.rest.positions[c.vertex as usize])
        .collect();
    let mut local = crease_mocap::Retarget::new(bound, &rest);
    let angles: Vec<f32> = (0..12).map(|k| 0.1 * k as f32).collect();
    let mut capture_frames = Vec::new();
    let mut control_frames = Vec::new();
    let n = names.len();
    let mut scales = Vec::new();
    for (seq, &a) in angles.iter().enumerate() {
        let p = bent(&model.rig.rest, a);
        let points: Vec<Vec3> = model
            .controls
            .iter()
            .map(|c| p[c.vertex as usize])
            .collect();
        let mut m: Vec<Vec3> = points.iter().map(|&q| to_capture(q)).collect();
        m.push(Vec3::new(1.0, 2.0, 3.0)); // X
        let seen = vec![true; m.len()];
        let (mut c, mut v) = (vec![Vec3::ZERO; n], vec![false; n]);
        local.frame(
            &crease_mocap::MarkerFrame {
                index: seq,
                time: 0.0,
                positions: &m,
                valid: &seen,
            },
            &mut c,
            &mut v,
        );
        scales.push(local.registration().transform().unwrap().scale);
        capture_frames.push(v1::ControlFrame {
            room: "cap".into(),
            seq: seq as u64,
            markers: m.iter().flat_map(|q| q.to_array()).collect(),
            ..Default::default()
        });
        let mut mask = Vec::new();
        crease_proto::encode_valid_mask(&v, &mut mask);
        control_frames.push(v1::ControlFrame {
            room: "plain".into(),
            seq: seq as u64,
            positions: c.iter().flat_map(|q| q.to_array()).collect(),
            valid: mask,
            ..Default::default()
        });
    }
    let scale = local.registration().scale().unwrap();
    assert!((scale - 0.001).abs() < 2e-4, "fitted scale {scale}");
    let cap = publish(&mut client, &token, capture_frames).await;
    let direct = publish(&mut client, &plain, control_frames).await;
    assert_eq!(cap.len(), angles.len());
    for ((c, d), s) in cap.iter().zip(&direct).zip(&scales) {
        assert!(c.error.is_none() && d.error.is_none(), "{c:?} {d:?}");
        assert_eq!(c.held_controls, d.held_controls, "frame {}", c.seq);
        assert!(
            (c.control_residual - d.control_residual).abs() <= 1e-6,
            "frame {}: retargeted in the room {} vs here {}",
            c.seq,
            c.control_residual,
            d.control_residual
        );
        // The capture-units residual is the model one over the frame's scale (the running
        // estimate during calibration, then the fitted one).
        assert!(
            (c.control_residual_capture * s - c.control_residual).abs()
                <= 1e-4 * c.control_residual.max(1e-9),
            "frame {}: capture {} vs model {} (scale {scale})",
            c.seq,
            c.control_residual_capture,
            c.control_residual
        );
    }
    eprintln!(
        "retargeting room: residual (model units) {:?}, scale {scale}",
        cap.iter().map(|a| a.control_residual).collect::<Vec<_>>()
    );
    assert!(
        cap.iter().any(|a| a.control_residual > 0.0),
        "a residual to compare"
    );

    // Bad input, named.
    let bad = |f: v1::ControlFrame| vec![f];
    let acks = publish(
        &mut client,
        &token,
        bad(v1::ControlFrame {
            room: "cap".into(),
            positions: vec![0.0; 9],
            ..Default::default()
        }),
    )
    .await;
    let e = acks[0].error.as_ref().unwrap();
    assert!(
        e.message.contains("positions") && e.message.contains("markers"),
        "{e:?}"
    );
    let acks = publish(
        &mut client,
        &token,
        bad(v1::ControlFrame {
            room: "cap".into(),
            markers: vec![0.0; 5],
            ..Default::default()
        }),
    )
    .await;
    let e = acks[0].error.as_ref().unwrap();
    assert!(
        e.message.contains("markers") && e.message.contains("5 values"),
        "{e:?}"
    );
    let acks = publish(
        &mut client,
        &plain,
        bad(v1::ControlFrame {
            room: "plain".into(),
            markers: vec![0.0; 12],
            ..Default::default()
        }),
    )
    .await;
    let e = acks[0].error.as_ref().unwrap();
    assert!(e.message.contains("Retarget"), "{e:?}");
    // A map naming a marker the capture does not declare.
    let unknown = v1::Retarget {
        markers: vec!["M0".into(), "M1".into()],
        ..retarget.clone()
    };
    let err = client
        .open_room(authed(open("cap2", Some(unknown)), ADMIN))
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::InvalidArgument);
    assert!(err.message().contains("M2"), "{}", err.message());
    // A map that leaves a control point (here also a registration point) without a source
    // is refused naming it (client/tests/cli_mocap.rs checks a plain control point).
    let partial = v1::Retarget {
        map_toml: toml.replace(&format!("{} = \"M2\"\n", names[2]), ""),
        ..retarget.clone()
    };
    let err = client
        .open_room(authed(open("cap4", Some(partial)), ADMIN))
        .await
        .unwrap_err();
    assert!(err.message().contains(&names[2]), "{}", err.message());
    // A map name with no maps folder.
    let named = v1::Retarget {
        map_toml: String::new(),
        map_name: "glove".into(),
        ..retarget
    };
    let err = client
        .open_room(authed(open("cap3", Some(named)), ADMIN))
        .await
        .unwrap_err();
    assert!(err.message().contains("maps folder"), "{}", err.message());
}
