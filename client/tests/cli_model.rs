//! `crease model mirror` (issue 38): the real binary writes the mirrored model, which the
//! library would build, with its rest mesh reflected and its winding reversed; a bad plane or a
//! missing file is refused with a message naming it.

use crate::common;

use crease_core::glam::Vec3;
use crease_core::model::{MirrorPlane, TrainedModel};

use common::crease;

#[test]
fn model_mirror_writes_the_mirrored_model() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("right.crease");
    let output = dir.path().join("left.crease");
    let model = crease_testkit::model::model_with_detail();
    model.save(&input).unwrap();
    let out = crease()
        .args(["model", "mirror"])
        .arg(&input)
        .args(["--plane", "z", "--out"])
        .arg(&output)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("detail layer"), "stdout: {stdout}");
    let written = TrainedModel::load(&output).unwrap();
    assert_eq!(
        written,
        model.mirrored(&MirrorPlane::parse("z").unwrap()).unwrap()
    );
    // Independently of the library: z negated, each triangle's winding reversed.
    let rest = &model.rig.rest;
    let negated: Vec<Vec3> = (rest.positions.iter())
        .map(|p| Vec3::new(p.x, p.y, -p.z))
        .collect();
    let reversed: Vec<[u32; 3]> = rest.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
    assert_eq!(written.rig.rest.positions, negated);
    assert_eq!(written.rig.rest.triangles, reversed);
}

/// `crease model mirror ARGS`'s stderr, after checking that it failed.
fn refused(args: &[&std::ffi::OsStr]) -> String {
    let out = crease()
        .args(["model", "mirror"])
        .args(args)
        .output()
        .unwrap();
    assert!(!out.status.success(), "{args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn model_mirror_names_a_bad_plane_and_a_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("right.crease");
    let out = dir.path().join("x.crease");
    crease_testkit::model::model().save(&input).unwrap();
    let stderr = refused(&[
        input.as_os_str(),
        "--plane".as_ref(),
        "0,0,0".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(
        stderr.contains("--plane") && stderr.contains("zero"),
        "stderr: {stderr}"
    );
    let missing = dir.path().join("nowhere.crease");
    let stderr = refused(&[missing.as_os_str(), "--out".as_ref(), out.as_os_str()]);
    assert!(stderr.contains("nowhere.crease"), "stderr: {stderr}");
}

/// `crease model upload|list|delete` (issue 39) against a server with a models folder: the
/// upload lands in the folder as the file was, is listed, and opens rooms; a file that is not
/// a model is refused before it travels; delete empties the folder.
#[test]
fn model_upload_list_and_delete_through_the_server() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("models");
    std::fs::create_dir_all(&folder).unwrap();
    let file = dir.path().join("hand-v2.crease");
    let model = crease_testkit::model::model();
    model.save(&file).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let running = runtime.block_on(async {
        let loopback = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
        let state = crease_server::AppState::new(
            crease_server::registry::ModelRegistry::load_dir(&folder).unwrap(),
            crease_server::Config {
                grpc: loopback,
                http: loopback,
                admin_token: Some("adm".into()),
                models_dir: Some(folder.clone()),
                ..crease_server::Config::default()
            },
        );
        crease_server::serve(state).await.unwrap()
    });
    let server = format!("http://{}", running.grpc);
    let run = |args: &[&str]| {
        crease()
            .arg("model")
            .args(args)
            .args(["--server", &server])
            .output()
            .unwrap()
    };
    let path = file.to_str().unwrap();
    let out = run(&["upload", path, "--admin-token", "adm"]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(said.contains("uploaded model \"hand-v2\""), "{said}");
    assert_eq!(
        std::fs::read(folder.join("hand-v2.crease")).unwrap(),
        std::fs::read(&file).unwrap(),
        "the folder holds the file as it was"
    );
    let out = run(&["list"]);
    let listed = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && listed.starts_with("hand-v2\t"),
        "{listed}"
    );
    // A file that is not a model is named before it travels; a wrong token by the server.
    let junk = dir.path().join("junk.crease");
    std::fs::write(&junk, b"not a model").unwrap();
    let out = run(&["upload", junk.to_str().unwrap(), "--admin-token", "adm"]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && said.contains("is not a crease model"),
        "{said}"
    );
    let out = run(&["upload", path, "--name", "other", "--admin-token", "nope"]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && said.contains("wrong admin token"),
        "{said}"
    );
    assert!(!folder.join("other.crease").exists());
    let out = run(&["delete", "hand-v2", "--admin-token", "adm"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read_dir(&folder).unwrap().count(), 0);
    let out = run(&["list"]);
    assert!(out.status.success() && out.stdout.is_empty());
    runtime
        .block_on(running.shutdown(std::time::Duration::from_secs(1)))
        .unwrap();
}
