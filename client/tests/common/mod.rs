//! Helpers shared by the command-line tests: the `crease` binary and a bending tube trained
//! into a small model.
#![allow(dead_code)]
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::path::Path;
use std::process::Command;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;

pub(crate) fn crease() -> Command {
    Command::new(env!("CARGO_BIN_EXE_crease"))
}

/// Runs `cmd`, which must succeed (the panic shows its stdout and stderr); returns its stdout.
pub(crate) fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().expect("the command starts");
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 output")
}

pub(crate) const RINGS: usize = 8;
pub(crate) const AROUND: usize = 6;
/// Control points: a base vertex, two at mid height, two at the tip.
pub(crate) const CONTROLS: [usize; 5] = [0, 4 * AROUND, 4 * AROUND + 3, 7 * AROUND, 7 * AROUND + 3];

/// A tube along z from 0 to 7 (unit radius), `RINGS` rings of `AROUND` vertices.
pub(crate) fn tube() -> Mesh {
    let mut positions = Vec::new();
    for r in 0..RINGS {
        for a in 0..AROUND {
            let phi = std::f32::consts::TAU * a as f32 / AROUND as f32;
            positions.push(Vec3::new(phi.cos(), phi.sin(), r as f32));
        }
    }
    let mut triangles = Vec::new();
    for r in 0..RINGS - 1 {
        for a in 0..AROUND {
            let i0 = (r * AROUND + a) as u32;
            let i1 = (r * AROUND + (a + 1) % AROUND) as u32;
            let (j0, j1) = (i0 + AROUND as u32, i1 + AROUND as u32);
            triangles.push([i0, i1, j1]);
            triangles.push([i0, j1, j0]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// The tube with its upper half rotated by `angle` about the x axis through z = 3.5.
pub(crate) fn bent(rest: &Mesh, angle: f32) -> Mesh {
    let q = Quat::from_rotation_x(angle);
    let pivot = Vec3::new(0.0, 0.0, 3.5);
    Mesh {
        positions: rest
            .positions
            .iter()
            .map(|&p| {
                if p.z > pivot.z {
                    pivot + q * (p - pivot)
                } else {
                    p
                }
            })
            .collect(),
        triangles: rest.triangles.clone(),
    }
}

/// Writes the rest tube and six bent poses, trains a 2-bone global model on them and returns
/// the model's path.
pub(crate) fn train_model(dir: &Path) -> std::path::PathBuf {
    let examples = dir.join("examples");
    std::fs::create_dir_all(&examples).unwrap();
    let rest = tube();
    rest.write(examples.join("reference.obj")).unwrap();
    for k in 1..=6 {
        bent(&rest, 0.15 * k as f32)
            .write(examples.join(format!("pose{k}.obj")))
            .unwrap();
    }
    let model = dir.join("tube.crease");
    let controls = CONTROLS.map(|c| c.to_string()).join(",");
    let out = crease()
        .args(["train", "--examples"])
        .arg(&examples)
        .args([
            "--bones",
            "2",
            "--max-influences",
            "2",
            "--kc",
            "3",
            "--kp",
            "3",
        ])
        .args(["--method", "global", "--control-points", &controls, "--out"])
        .arg(&model)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "train failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    model
}

/// Starts a crease server on free loopback ports hosting `model` as `tube`, with `admin` as
/// the admin token, and leaves it running for the rest of the test process. Returns its gRPC
/// address.
pub(crate) async fn serve_tube(
    model: crease_core::model::TrainedModel,
    admin: Option<&str>,
) -> std::net::SocketAddr {
    serve_model("tube", model, admin, crease_server::Limits::default()).await
}

/// Starts a crease server on free loopback ports hosting `model` as `name`, with `admin` as
/// its admin token and `limits`; returns the gRPC address.
pub(crate) async fn serve_model(
    name: &str,
    model: crease_core::model::TrainedModel,
    admin: Option<&str>,
    limits: crease_server::Limits,
) -> std::net::SocketAddr {
    let registry = crease_server::registry::ModelRegistry::default();
    registry.insert(name, model);
    let state = crease_server::AppState::new(
        registry,
        crease_server::Config {
            grpc: "127.0.0.1:0".parse().unwrap(),
            http: "127.0.0.1:0".parse().unwrap(),
            admin_token: admin.map(str::to_owned),
            limits,
            ..crease_server::Config::default()
        },
    );
    let running = crease_server::serve(state).await.unwrap();
    let addr = running.grpc;
    std::mem::forget(running);
    addr
}

/// `rel` below the shared data folder (`../shared/data` beside the checkout), or `None` with a
/// note on stderr when it is not there (the test then skips).
pub(crate) fn shared_data(rel: &str) -> Option<std::path::PathBuf> {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")).join(rel);
    if path.exists() {
        Some(path)
    } else {
        eprintln!(
            "skipping: {} not found (shared data sets absent)",
            path.display()
        );
        None
    }
}

/// Opens `room` on `model` at the server `addr` with the admin token `admin`; returns the
/// room's publish token.
pub(crate) async fn open_room(
    addr: std::net::SocketAddr,
    admin: &str,
    request: crease_proto::v1::OpenRoomRequest,
) -> String {
    let mut client =
        crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
    let mut open = tonic::Request::new(request);
    open.metadata_mut()
        .insert("authorization", format!("Bearer {admin}").parse().unwrap());
    client
        .open_room(open)
        .await
        .unwrap()
        .into_inner()
        .publish_token
}
