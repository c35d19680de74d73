//! Models through the API (issue 39) over a real socket: an uploaded model lands in the models
//! folder byte for byte (a fresh registry of the folder loads it), opens rooms at once, and is
//! listed; uploads that are cut short, carry another digest, are not a model, are too large,
//! name no model or a bad name, or come without the admin token are refused naming why and
//! leave the folder as it was; a model in use cannot be deleted, and one deleted is gone from
//! the folder and the list.

use crate::common;

use std::net::SocketAddr;
use std::path::Path;

use common::*;
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_server::registry::{ModelRegistry, sha256_hex};
use crease_server::{AppState, Config, Limits};
use tonic::Code;

const ADMIN: &str = "admin-secret";

/// The folder's file names, sorted.
fn files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// An upload of `chunks` (first chunk as given) with `token`: the server's answer.
async fn upload(
    client: &mut CreaseClient<tonic::transport::Channel>,
    token: &str,
    chunks: Vec<v1::ModelChunk>,
) -> Result<v1::ModelInfo, tonic::Status> {
    client
        .upload_model(authed(tokio_stream::iter(chunks), token))
        .await
        .map(tonic::Response::into_inner)
}

/// `bytes` as chunks of `size` bytes, the first naming `name` with `declared` size and digest.
fn chunks(
    name: &str,
    bytes: &[u8],
    declared: u64,
    sha256: &str,
    size: usize,
) -> Vec<v1::ModelChunk> {
    let mut out: Vec<v1::ModelChunk> = bytes
        .chunks(size)
        .map(|c| v1::ModelChunk {
            data: c.to_vec(),
            ..Default::default()
        })
        .collect();
    out[0].name = name.into();
    out[0].size = declared;
    out[0].sha256 = sha256.into();
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploaded_models_open_rooms_and_bad_uploads_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let model = model();
    let bytes = model.to_bytes().unwrap();
    let sha = sha256_hex(&bytes);
    let loopback = SocketAddr::from(([127, 0, 0, 1], 0));
    let state = AppState::new(
        ModelRegistry::load_dir(dir.path()).unwrap(),
        Config {
            grpc: loopback,
            http: loopback,
            admin_token: Some(ADMIN.into()),
            limits: Limits {
                model_bytes: 2 * bytes.len() as u64,
                ..unthrottled()
            },
            models_dir: Some(dir.path().to_path_buf()),
            ..Config::default()
        },
    );
    let running = crease_server::serve(state).await.unwrap();
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let n = bytes.len() as u64;

    // Refusals, each naming why, none leaving a file.
    let refused = [
        (
            "cut short",
            chunks("tube", &bytes[..bytes.len() / 2], n, &sha, 4096),
            ADMIN,
            Code::DataLoss,
            "truncated",
        ),
        (
            "another digest",
            chunks("tube", &bytes, n, &"ab".repeat(32), 4096),
            ADMIN,
            Code::InvalidArgument,
            "the upload declared abab",
        ),
        (
            "more than declared",
            chunks("tube", &bytes, n - 10, &sha, 4096),
            ADMIN,
            Code::InvalidArgument,
            "more than the",
        ),
        (
            "not a model",
            chunks("junk", &[7u8; 300], 300, &sha256_hex(&[7u8; 300]), 100),
            ADMIN,
            Code::InvalidArgument,
            "not a crease model file",
        ),
        (
            "too large",
            chunks("tube", &bytes, 3 * n, &sha, 4096),
            ADMIN,
            Code::ResourceExhausted,
            "over this server's cap",
        ),
        (
            "a path for a name",
            chunks("../tube", &bytes, n, &sha, 4096),
            ADMIN,
            Code::InvalidArgument,
            "is not a model name",
        ),
        (
            "no name",
            chunks("", &bytes, n, &sha, 4096),
            ADMIN,
            Code::InvalidArgument,
            "the first chunk must name the model",
        ),
        (
            "a wrong admin token",
            chunks("tube", &bytes, n, &sha, 4096),
            "nope",
            Code::PermissionDenied,
            "wrong admin token",
        ),
    ];
    for (what, request, token, code, says) in refused {
        let e = upload(&mut client, token, request).await.unwrap_err();
        assert_eq!(e.code(), code, "{what}: {e:?}");
        assert!(e.message().contains(says), "{what}: {}", e.message());
        assert!(
            files(dir.path()).is_empty(),
            "{what}: left {:?}",
            files(dir.path())
        );
    }

    // The upload: the model in the folder byte for byte, listed, loadable from the folder.
    let info = upload(
        &mut client,
        ADMIN,
        chunks("tube", &bytes, n, &sha, 64 * 1024),
    )
    .await
    .unwrap();
    assert_eq!(info.name, "tube");
    assert_eq!(info.base_vertices as usize, model.rig.rest.positions.len());
    assert_eq!(files(dir.path()), ["tube.crease"]);
    assert_eq!(
        sha256_hex(&std::fs::read(dir.path().join("tube.crease")).unwrap()),
        sha
    );
    let reloaded = ModelRegistry::load_dir(dir.path()).unwrap();
    assert_eq!(
        reloaded.get("tube").unwrap().info,
        info,
        "the folder's file is the model"
    );
    let listed = client
        .list_models(v1::ListModelsRequest {})
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        listed
            .models
            .iter()
            .map(|m| m.name.as_str())
            .collect::<Vec<_>>(),
        ["tube"]
    );
    assert!(listed.cluster.is_empty(), "no cluster here");
    // The same model again is a success without a write; another model under its name is not.
    upload(&mut client, ADMIN, chunks("tube", &bytes, n, &sha, 1 << 20))
        .await
        .unwrap();
    let other = model_of(curled).to_bytes().unwrap();
    let e = upload(
        &mut client,
        ADMIN,
        chunks(
            "tube",
            &other,
            other.len() as u64,
            &sha256_hex(&other),
            4096,
        ),
    )
    .await
    .unwrap_err();
    assert_eq!(e.code(), Code::AlreadyExists, "{e:?}");

    // A room on it at once; the model cannot be deleted while the room is open.
    let token = client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "up".into(),
                model: "tube".into(),
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let mut acks = client
        .publish(authed(
            tokio_stream::iter(vec![control_frame(&model, "up", 1, 0.3)]),
            &token,
        ))
        .await
        .unwrap()
        .into_inner();
    let ack = acks.message().await.unwrap().unwrap();
    assert!(ack.error.is_none(), "{ack:?}");
    let delete = |name: &str| v1::DeleteModelRequest { model: name.into() };
    let e = client
        .delete_model(authed(delete("tube"), ADMIN))
        .await
        .unwrap_err();
    assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
    assert!(e.message().contains("in use by room up"), "{}", e.message());
    assert_eq!(files(dir.path()), ["tube.crease"]);
    // A subscriber of the room: its stream ends when the room closes (CloseRoom's promise),
    // though the server's task for it holds the room.
    let mut sub = client
        .subscribe(v1::SubscribeRequest {
            room: "up".into(),
            level: v1::Level::Base as i32,
            encoding: v1::Encoding::Vertices as i32,
        })
        .await
        .unwrap()
        .into_inner();
    let first = sub.message().await.unwrap().unwrap();
    assert!(
        matches!(first.body, Some(v1::mesh_frame::Body::Topology(_))),
        "{first:?}"
    );
    client
        .close_room(authed(v1::CloseRoomRequest { room: "up".into() }, ADMIN))
        .await
        .unwrap();
    let ended = tokio::time::timeout(std::time::Duration::from_secs(10), async {
        while sub.message().await.unwrap().is_some() {}
    })
    .await;
    assert!(ended.is_ok(), "the subscription outlived its room's close");
    client
        .delete_model(authed(delete("tube"), ADMIN))
        .await
        .unwrap();
    assert!(files(dir.path()).is_empty());
    let listed = client
        .list_models(v1::ListModelsRequest {})
        .await
        .unwrap()
        .into_inner();
    assert!(listed.models.is_empty(), "{listed:?}");
    let e = client
        .delete_model(authed(delete("tube"), ADMIN))
        .await
        .unwrap_err();
    assert_eq!(e.code(), Code::NotFound, "{e:?}");
    running
        .shutdown(std::time::Duration::from_secs(1))
        .await
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_without_a_models_folder_refuses_uploads() {
    let model = model();
    let served = serve_model("tube", &model, Some(ADMIN), unthrottled()).await;
    let mut client = CreaseClient::connect(format!("http://{}", served.grpc))
        .await
        .unwrap();
    let bytes = model.to_bytes().unwrap();
    let e = upload(
        &mut client,
        ADMIN,
        chunks(
            "t2",
            &bytes,
            bytes.len() as u64,
            &sha256_hex(&bytes),
            1 << 20,
        ),
    )
    .await
    .unwrap_err();
    assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
    assert!(e.message().contains("no models folder"), "{}", e.message());
}
