//! Palette streams (issue 18) on the tube model with a pose-dependent detail layer: the
//! palette stream decoded by `core` matches the same room's vertex stream and the predictor's
//! own mesh, frame by frame, within both encodings' bounds, at the base and the detail level
//! (`common::palette_check`).

use crate::common;

use common::palette_check::compare_encodings;
use common::{control_frame, model_with_detail};
use crease_core::model::TrainedModel;
use crease_core::runtime::displacement::{DetailInput, DetailRegressor};
use crease_core::runtime::kernel::Kernel;
use crease_core::runtime::predict::LinearOperator;

const ADMIN: &str = "admin-secret";

/// The tube with a detail layer whose displacements depend on the pose: `h = D xi + b` over
/// three example control vectors (the tube bent by 0, 0.6 and 1.2 rad).
fn tube_with_posed_detail() -> TrainedModel {
    let mut model = model_with_detail();
    let layer = model.detail.as_mut().unwrap();
    let n = layer.regressor.vertex_count();
    let examples: Vec<f32> = [0.0f32, 0.6, 1.2]
        .iter()
        .flat_map(|&a| control_frame(&model_ref(), "x", 0, a).positions)
        .collect();
    let d_in = layer.regressor.d_in;
    let m: Vec<f32> = (0..n * 3)
        .map(|i| 0.01 * (((i * 2654435761) % 97) as f32 / 48.5 - 1.0))
        .collect();
    layer.regressor = DetailRegressor {
        input: DetailInput::Controls,
        kernel: Kernel::Gaussian { sigma: 0.8 },
        d_in,
        examples,
        operator: LinearOperator {
            rows: n,
            cols: 3,
            m,
            b: layer.regressor.operator.b.clone(),
        },
    };
    layer.regressor.validate().unwrap();
    model
}

fn model_ref() -> TrainedModel {
    common::model()
}

/// At both levels the palette stream was quantised (some error) and its bound is not vacuous
/// (the worst error is a real fraction of it); `compare_encodings` checked it holds.
fn assert_bounds_bite(r: &common::palette_check::PaletteReport) {
    for li in 0..2 {
        assert!(r.palette_error[li] > 0.0, "level {li}: no error at all");
        assert!(
            r.worst_ratio[li] > 1e-3,
            "level {li}: worst error / bound {}",
            r.worst_ratio[li]
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn palette_streams_match_vertex_streams_at_both_levels() {
    let model = tube_with_posed_detail();
    let running = common::serve_model("tube", &model, Some(ADMIN), common::unthrottled()).await;
    let frames = (1..=12u64)
        .map(|seq| control_frame(&model, "palette-check", seq, 0.1 * seq as f32))
        .collect();
    let url = format!("http://{}", running.grpc);
    let r = compare_encodings(&url, ADMIN, "tube", &model, frames).await;
    eprintln!("{r:#?}");
    assert_bounds_bite(&r);
}

/// The WebSocket sends a palette header the model encoded once: every subscriber gets the
/// bytes of the header gRPC sends, at its own level.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn websocket_palette_headers_are_the_grpc_headers_encoded() {
    use futures_util::StreamExt as _;
    use prost::Message as _;
    use tokio_tungstenite::tungstenite::Message;

    let model = tube_with_posed_detail();
    let running = common::serve_model("tube", &model, Some(ADMIN), common::unthrottled()).await;
    let mut client =
        crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{}", running.grpc))
            .await
            .unwrap();
    let open = crease_proto::v1::OpenRoomRequest {
        room: "headers".into(),
        model: "tube".into(),
        ..Default::default()
    };
    client.open_room(common::authed(open, ADMIN)).await.unwrap();
    for (level, query) in [
        (crease_proto::v1::Level::Base, "base"),
        (crease_proto::v1::Level::Detail, "detail"),
    ] {
        let grpc_first = client
            .subscribe(crease_proto::v1::SubscribeRequest {
                room: "headers".into(),
                level: level as i32,
                encoding: crease_proto::v1::Encoding::Palette as i32,
            })
            .await
            .unwrap()
            .into_inner()
            .message()
            .await
            .unwrap()
            .unwrap();
        assert!(matches!(
            grpc_first.body,
            Some(crease_proto::v1::mesh_frame::Body::PaletteTopology(_))
        ));
        let url = format!(
            "ws://{}/ws/rooms/headers?level={query}&encoding=palette",
            running.http
        );
        for _ in 0..2 {
            let (mut ws, _) = tokio_tungstenite::connect_async(url.as_str())
                .await
                .unwrap();
            let Some(Ok(Message::Binary(bytes))) = ws.next().await else {
                panic!("{query}: no binary first message");
            };
            assert_eq!(
                crease_proto::v1::MeshFrame::decode(bytes.as_ref()).unwrap(),
                grpc_first,
                "{query}"
            );
            assert_eq!(
                bytes.as_ref(),
                grpc_first.encode_to_vec().as_slice(),
                "{query}"
            );
        }
    }
}

/// A mirrored model (issue 38: a left hand from a right-hand model) streams like any other:
/// its palette header (rest mesh, skin, subdivision, detail regressor) and its frames decode
/// by `core` to its vertex stream and its predictor's mesh at both levels, so the winding,
/// normals and detail rows followed the mirror. The registry builds a mirror once and shares
/// it, names it after its plane, and forgets it when the model is replaced.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mirrored_model_streams_palettes_that_match_its_vertices() {
    use crease_core::model::MirrorPlane;
    use crease_server::registry::ModelRegistry;

    let registry = ModelRegistry::default();
    registry.insert("tube", tube_with_posed_detail());
    let first = registry.mirrored("tube", &MirrorPlane::X).unwrap().unwrap();
    let again = registry.mirrored("tube", &MirrorPlane::X).unwrap().unwrap();
    assert!(std::sync::Arc::ptr_eq(&first, &again), "built twice");
    assert_eq!(first.name, "tube~mirror-x");
    assert_eq!(first.info.name, "tube~mirror-x");
    assert!(registry.mirrored("nothing", &MirrorPlane::X).is_none());
    assert_eq!(registry.list().len(), 1, "a mirror is not listed");
    registry.insert("tube", tube_with_posed_detail());
    let rebuilt = registry.mirrored("tube", &MirrorPlane::X).unwrap().unwrap();
    assert!(
        !std::sync::Arc::ptr_eq(&first, &rebuilt),
        "a replaced model's mirror was kept"
    );

    let model = (*first.model).clone();
    let running =
        common::serve_model("tube-left", &model, Some(ADMIN), common::unthrottled()).await;
    // The original's control frames, mirrored across x = 0.
    let frames = (1..=12u64)
        .map(|seq| {
            let mut f = control_frame(&model_ref(), "palette-check", seq, 0.1 * seq as f32);
            for p in f.positions.chunks_exact_mut(3) {
                p[0] = -p[0];
            }
            f
        })
        .collect();
    let url = format!("http://{}", running.grpc);
    let r = compare_encodings(&url, ADMIN, "tube-left", &model, frames).await;
    eprintln!("{r:#?}");
    assert_bounds_bite(&r);
}
