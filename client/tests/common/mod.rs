//! Helpers shared by the command-line tests: the `crease` binary and a bending tube (the
//! crease-testkit tube model's) trained into a small model through it.
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

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

#[allow(unused_imports)] // each test binary uses some of these
pub(crate) use crease_testkit::model::{AROUND, RINGS, bent_mesh as bent, tube};
#[allow(unused_imports)] // each test binary uses some of these
pub(crate) use crease_testkit::server::{Served, serve_config, serve_model};

/// Control points: a base vertex, two at mid height, two at the tip.
pub(crate) const CONTROLS: [usize; 5] = [0, 4 * AROUND, 4 * AROUND + 3, 7 * AROUND, 7 * AROUND + 3];

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

/// A crease server on free loopback ports hosting `model` as `tube`, with `admin` as the admin
/// token and the default limits; it runs until the returned guard is dropped.
pub(crate) async fn serve_tube(
    model: crease_core::model::TrainedModel,
    admin: Option<&str>,
) -> Served {
    serve_model("tube", &model, admin, crease_server::Limits::default()).await
}

/// As [`serve_tube`], with everything else the server's default configuration (rooms and
/// batches that do not choose get its refinement, as `crease-server` without flags).
pub(crate) async fn serve_tube_defaults(model: crease_core::model::TrainedModel) -> Served {
    serve_config([("tube", model)], crease_server::Config::default()).await
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
