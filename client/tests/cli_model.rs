//! `crease model mirror` (issue 38): the real binary writes the mirrored model, which the
//! library would build, with its rest mesh reflected and its winding reversed; a bad plane or a
//! missing file is refused with a message naming it.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

mod common;

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
