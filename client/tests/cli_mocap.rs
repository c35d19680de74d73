//! Mocap end to end on the real recordings in ../shared/data/mocap: a glove13 hand trained from
//! `crease handgen`, `crease retarget` + `crease synth` offline, and `crease stream --tsv/--c3d`
//! into a room of a server running in this process, with every mesh decoded and checked.
//! Every test skips with a note when the shared data is absent.

use crate::common;

use std::path::{Path, PathBuf};

use common::{Served, crease, open_room, run_ok, serve_model, shared_data};
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_proto::v1;

const TSV: &str = "qualisys-hand-glove-recording.tsv";
const C3D: &str = "ART-Human_hands_real_no6dof.c3d";

fn data(file: &str) -> Option<PathBuf> {
    shared_data(&format!("mocap/{file}"))
}

fn map(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../bench/mocap")).join(name)
}

/// A glove13 hand: `crease handgen` (base only) and `crease train` on its glove13 manifest.
fn glove_model(dir: &Path) -> PathBuf {
    let hg = dir.join("hg");
    run_ok(
        crease()
            .args([
                "handgen",
                "--train",
                "14",
                "--test",
                "1",
                "--base-only",
                "--out",
            ])
            .arg(&hg),
    );
    let model = dir.join("glove-hand.crease");
    run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(hg.join("train-glove13.toml"))
            .args(["--bones", "30", "--method", "local", "--no-detail", "--out"])
            .arg(&model),
    );
    model
}

/// The first `frames` frames of the Qualisys recording, with every finger marker (the ten
/// after hand_top, hand_left, hand_right) written as `nan` in frames `blank`.
fn short_tsv(src: &Path, dst: &Path, frames: usize, blank: std::ops::Range<usize>) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut out = String::new();
    let mut row = 0;
    for line in text.lines() {
        if line.starts_with("NO_OF_FRAMES") {
            out.push_str(&format!("NO_OF_FRAMES\t{frames}\n"));
            continue;
        }
        let is_data = line
            .split('\t')
            .next()
            .is_some_and(|f| f.parse::<u64>().is_ok());
        if !is_data {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        if row == frames {
            break;
        }
        let mut cols: Vec<&str> = line.split('\t').collect();
        if blank.contains(&row) {
            // Frame, Time, then x y z per marker: markers 3..13 are the fingers.
            for c in cols.iter_mut().take(2 + 3 * 13).skip(2 + 3 * 3) {
                *c = "nan";
            }
        }
        out.push_str(&cols.join("\t"));
        out.push('\n');
        row += 1;
    }
    std::fs::write(dst, out).unwrap();
}

/// The glove model and 200 frames of the Qualisys recording with every finger marker missing
/// in frames 100..150, in a temporary folder; `None` (skipped) without the shared data.
fn glove_clip() -> Option<(tempfile::TempDir, PathBuf, PathBuf)> {
    let src = data(TSV)?;
    let tmp = tempfile::tempdir().unwrap();
    let model = glove_model(tmp.path());
    let tsv = tmp.path().join("short.tsv");
    short_tsv(&src, &tsv, 200, 100..150);
    Some((tmp, model, tsv))
}

fn read_csv(path: &Path) -> Vec<Vec<f32>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse::<f32>().unwrap()).collect())
        .collect()
}

/// All ten finger markers gone for 50 frames: the retargeted frames carry them as invalid (no
/// neighbour of a fingertip is seen) and every synthesised mesh is finite, the hand holding
/// the pose it had (its fingers relative to the back of the hand).
#[test]
fn all_finger_markers_missing_still_yields_finite_meshes() {
    let Some((tmp, model_path, tsv)) = glove_clip() else {
        return;
    };
    let csv = tmp.path().join("controls.csv");
    let stdout = run_ok(
        crease()
            .args(["retarget", "--tsv"])
            .arg(&tsv)
            .arg("--map")
            .arg(map("qualisys-glove13.toml"))
            .arg("--model")
            .arg(&model_path)
            .arg("--out")
            .arg(&csv),
    );
    assert!(
        stdout.contains("200 frames at 100 Hz for 13 control points"),
        "{stdout}"
    );
    let rows = read_csv(&csv);
    assert_eq!(rows.len(), 200);
    let model = TrainedModel::load(&model_path).unwrap();
    let names: Vec<&str> = model.controls.iter().map(|c| c.name.as_str()).collect();
    let tip = names.iter().position(|n| *n == "index_tip").unwrap();
    assert!(rows[99].iter().all(|v| v.is_finite()));
    assert!(
        rows[120][3 * tip].is_nan(),
        "a fingertip with no seen neighbour is invalid"
    );
    assert!(
        rows[120][..9].iter().all(|v| v.is_finite()),
        "back markers still seen"
    );

    let out = tmp.path().join("meshes");
    run_ok(
        crease()
            .args(["synth", "--model"])
            .arg(&model_path)
            .arg("--controls")
            .arg(&csv)
            .arg("--out")
            .arg(&out)
            .args(["--beta", "0.3"]),
    );
    let mesh = |k: usize| Mesh::read(out.join(format!("frame_{k:05}.obj"))).unwrap();
    for k in [0, 99, 100, 125, 149, 150, 199] {
        let m = mesh(k);
        assert!(m.positions.iter().all(|p| p.is_finite()), "frame {k}");
    }
    // Held: the hand at frame 125 is the hand at frame 99 up to the back markers' jitter
    // (registered to the model's rest back), far from snapping to the rest pose.
    let (a, b) = (mesh(99), mesh(125));
    let moved = a
        .positions
        .iter()
        .zip(&b.positions)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0f32, f32::max);
    let rest_gap = a
        .positions
        .iter()
        .zip(&model.rig.rest.positions)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0f32, f32::max);
    assert!(
        moved < 0.5 * rest_gap,
        "held pose moved {moved} m; the pose is {rest_gap} m from rest"
    );

    // The same recording as a batch job (issue 45): `crease job submit --tsv --map` retargets
    // it as `crease retarget` does and the server's meshes equal the offline path above within
    // the batch's 16-bit quantisation (the refinement asked for: the test server's default is
    // off, `crease synth`'s is Refinement::ROOM_DEFAULT).
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let served = runtime.block_on(serve_model(
        "glove-hand",
        &model,
        Some("admin"),
        crease_server::Limits::default(),
    ));
    let url = format!("http://{}", served.grpc);
    let job = |args: &[&str]| {
        let mut c = crease();
        c.arg("job").args(args).args(["--server", &url]);
        c.env("CREASE_ADMIN_TOKEN", "admin");
        c
    };
    // Both jobs below ask for the offline path's settings.
    let submit = || {
        job(&[
            "submit",
            "--model",
            "glove-hand",
            "--beta",
            "0.3",
            "--refine",
            "8,0.01",
        ])
    };
    let id = run_ok(
        submit()
            .arg("--tsv")
            .arg(&tsv)
            .arg("--map")
            .arg(map("qualisys-glove13.toml")),
    );
    let id = id.trim().to_owned();
    let watched = run_ok(&mut job(&["watch", &id]));
    assert!(
        watched.contains("(done)") && watched.contains("200 of 200 frames"),
        "{watched}"
    );
    let fetched = tmp.path().join("job");
    run_ok(&mut job(&["get", &id, "--out", fetched.to_str().unwrap()]));
    let bound = runtime.block_on(crate::cli_synth_remote::batch_bound_of(
        served.grpc,
        "glove-hand",
    ));
    for k in 0..200 {
        let name = format!("frame_{k:05}.obj");
        let got = Mesh::read(fetched.join(&name)).unwrap();
        crate::cli_synth_remote::assert_close(&format!("job frame {k}"), &got, &mesh(k), bound);
    }

    // The server retargeted the raw markers (JobSpec.retarget) exactly as `crease retarget`
    // did here: a job of the offline control frames gives the same meshes, file for file.
    let offline = run_ok(submit().arg("--controls").arg(&csv));
    let offline = offline.trim().to_owned();
    run_ok(&mut job(&["watch", &offline]));
    let offline_frames = tmp.path().join("offline-job");
    run_ok(&mut job(&[
        "get",
        &offline,
        "--out",
        offline_frames.to_str().unwrap(),
    ]));
    for k in 0..200 {
        let name = format!("frame_{k:05}.obj");
        assert!(
            std::fs::read(fetched.join(&name)).unwrap()
                == std::fs::read(offline_frames.join(&name)).unwrap(),
            "frame {k}: the server-retargeted job differs from the offline retarget's"
        );
    }

    // A map for markers the recording does not have is refused at submit, naming the map.
    let out = job(&["submit", "--model", "glove-hand"])
        .arg("--tsv")
        .arg(&tsv)
        .arg("--map")
        .arg(map("vmc-glove13.toml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("JobSpec.retarget"),
        "{err}"
    );
}

struct Room {
    /// The server, stopped when the room is dropped.
    _served: Served,
    runtime: tokio::runtime::Runtime,
    server: String,
    token: String,
}

/// A server in this process hosting `model` as glove-hand, a room `mocap` on it with beta 0.3
/// and the default filter.
fn mocap_room(model: &Path) -> Room {
    let model = TrainedModel::load(model).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (served, token) = runtime.block_on(async {
        let limits = crease_server::Limits {
            publish_hz: 2000.0,
            ..crease_server::Limits::default()
        };
        let served = serve_model("glove-hand", &model, Some("admin"), limits).await;
        let addr = served.grpc;
        let open = v1::OpenRoomRequest {
            room: "mocap".into(),
            model: "glove-hand".into(),
            beta: 0.3,
            filter: Some(v1::MarkerFilter {
                min_cutoff_hz: 1.5,
                beta: 10.0,
                d_cutoff_hz: 1.0,
            }),
            ..Default::default()
        };
        let token = open_room(addr, "admin", open).await;
        (served, token)
    });
    Room {
        server: format!("http://{}", served.grpc),
        _served: served,
        runtime,
        token,
    }
}

fn stream(room: &Room) -> std::process::Command {
    let mut c = crease();
    c.args([
        "stream",
        "--server",
        &room.server,
        "--room",
        "mocap",
        "--token",
        &room.token,
    ]);
    c
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// 2 s of the Qualisys recording (with 50 frames of missing fingers) into a filtered mocap
/// room: every frame acknowledged, every mesh decoded finite, the missing markers counted and
/// held, the strip written; then the same clip resampled to 50 Hz.
#[test]
fn stream_tsv_into_a_mocap_room() {
    let Some((tmp, model, tsv)) = glove_clip() else {
        return;
    };
    let room = mocap_room(&model);
    let (json, strip) = (tmp.path().join("r.json"), tmp.path().join("strip.png"));
    let stdout = run_ok(
        stream(&room)
            .arg("--tsv")
            .arg(&tsv)
            .arg("--map")
            .arg(map("qualisys-glove13.toml"))
            .args(["--strip-every", "0.5", "--speed", "2", "--strip"])
            .arg(&strip)
            .arg("--report")
            .arg(&json),
    );
    assert!(stdout.contains("200 acknowledged, 0 refused"), "{stdout}");
    let r = report(&json);
    assert_eq!(r["acknowledged"], 200);
    // Points whose nearest neighbours are all fingers (the index tip, ...) have nothing to be
    // estimated from and go invalid in each of the 50 frames; the server holds exactly those.
    assert_eq!(r["frames_with_invalid"], 50, "{r}");
    assert!(r["invalid_in_frames"].as_u64().unwrap() >= 50, "{r}");
    assert_eq!(r["held_controls"], r["invalid_in_frames"], "{r}");
    assert_eq!(r["retarget"]["occluded_frames"], 50);
    assert_eq!(r["retarget"]["missing_points"], 500);
    let meshes = &r["meshes"];
    assert_eq!(meshes["non_finite"], 0, "{r}");
    assert_eq!(meshes["decode_errors"], 0, "{r}");
    assert_eq!(
        meshes["received"].as_u64().unwrap() + meshes["skipped"].as_u64().unwrap(),
        200,
        "{r}"
    );
    let residual = r["control_residual_rms_recording_units"].as_f64().unwrap();
    assert!(residual > 0.0 && residual < 100.0, "{residual} mm");
    // t = 0, 0.5, 1, 1.5 s.
    assert!(stdout.contains("(4 pictures)"), "{stdout}");
    let png = std::fs::read(&strip).unwrap();
    assert_eq!(&png[1..4], b"PNG");

    let stdout = run_ok(
        stream(&room)
            .arg("--tsv")
            .arg(&tsv)
            .arg("--map")
            .arg(map("qualisys-glove13.toml"))
            .args(["--rate", "50", "--speed", "2", "--check", "--report"])
            .arg(&json),
    );
    // 1.99 s at 50 Hz: 100 frames.
    assert!(stdout.contains("100 acknowledged"), "{stdout}");
    assert_eq!(report(&json)["meshes"]["non_finite"], 0);
    drop(room.runtime);
}

/// The same 2 s clip into a room that retargets itself (issue 19): opened by
/// `crease room open --map ... --markers-from` with the Qualisys map, the recording streamed
/// raw (no --map): every frame acknowledged, every mesh finite, and the residual, in the
/// performer's millimetres as the room reports it, as close as local retargeting's (the room
/// fits the scale while the first frames play, where local retargeting fits it before).
#[test]
fn stream_tsv_into_a_retargeting_room() {
    let Some((tmp, model, tsv)) = glove_clip() else {
        return;
    };
    let room = mocap_room(&model);
    let json = tmp.path().join("local.json");
    run_ok(
        stream(&room)
            .arg("--tsv")
            .arg(&tsv)
            .arg("--map")
            .arg(map("qualisys-glove13.toml"))
            .args(["--speed", "2", "--check", "--report"])
            .arg(&json),
    );
    let local = report(&json)["control_residual_rms_recording_units"]
        .as_f64()
        .unwrap();
    let token = run_ok(
        crease()
            .args([
                "room",
                "open",
                "--server",
                &room.server,
                "--admin-token",
                "admin",
            ])
            .args([
                "--room",
                "cap",
                "--model",
                "glove-hand",
                "--beta",
                "0.3",
                "--filter",
            ])
            .arg("--map")
            .arg(map("qualisys-glove13.toml"))
            .arg("--markers-from")
            .arg(&tsv),
    );
    let token = token.trim();
    let raw = tmp.path().join("raw.json");
    let stdout = run_ok(
        crease()
            .args([
                "stream",
                "--server",
                &room.server,
                "--room",
                "cap",
                "--token",
                token,
            ])
            .arg("--tsv")
            .arg(&tsv)
            .args(["--speed", "2", "--check", "--report"])
            .arg(&raw),
    );
    assert!(stdout.contains("200 acknowledged, 0 refused"), "{stdout}");
    let r = report(&raw);
    assert_eq!(r["meshes"]["non_finite"], 0, "{r}");
    assert_eq!(r["meshes"]["decode_errors"], 0, "{r}");
    let in_room = r["control_residual_rms_recording_units"].as_f64().unwrap();
    eprintln!("control residual RMS: local retargeting {local:.2} mm, in the room {in_room:.2} mm");
    assert!(
        in_room > 0.0 && in_room <= local * 1.1 + 0.5,
        "in the room {in_room} mm vs local {local} mm"
    );
    // The room has its own map: --map is refused, naming why; a marker the room expects
    // and the recording lacks is named.
    let out = crease()
        .args([
            "stream",
            "--server",
            &room.server,
            "--room",
            "cap",
            "--token",
            token,
        ])
        .arg("--tsv")
        .arg(&tsv)
        .arg("--map")
        .arg(map("qualisys-glove13.toml"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("its own map"), "{e}");
    // A map that gives a control point no source is refused when the room opens, naming it.
    let partial = tmp.path().join("partial.toml");
    let text = std::fs::read_to_string(map("qualisys-glove13.toml")).unwrap();
    std::fs::write(
        &partial,
        text.replace("little_middle = \"little_middle\"\n", ""),
    )
    .unwrap();
    let out = crease()
        .args([
            "room",
            "open",
            "--server",
            &room.server,
            "--admin-token",
            "admin",
        ])
        .args(["--room", "cap2", "--model", "glove-hand", "--map"])
        .arg(&partial)
        .arg("--markers-from")
        .arg(&tsv)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("no source for control point little_middle"),
        "{e}"
    );
    // Streaming a recording into a plain room without --map names --map.
    let out = stream(&room).arg("--tsv").arg(&tsv).output().unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("--map"), "{e}");
    drop(room.runtime);
}

/// The ART C3D sample (61 points, 969 frames at 60 Hz) through the right-hand map, with 101
/// samples of the right thumb tip marked invalid the C3D way (residual -1): all frames go
/// through, the gap is estimated from the thumb's other joints, every mesh is finite.
#[test]
fn stream_c3d_with_invalid_samples() {
    let Some(src) = data(C3D) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = glove_model(tmp.path());
    let mut bytes = std::fs::read(&src).unwrap();
    // Data from block 9, 61 points x 16 bytes per frame; RTTI is point 42.
    for f in 100..=200 {
        let at = 8 * 512 + f * 61 * 16 + 42 * 16 + 12;
        bytes[at..at + 4].copy_from_slice(&(-1.0f32).to_le_bytes());
    }
    let c3d = tmp.path().join("edited.c3d");
    std::fs::write(&c3d, bytes).unwrap();
    let room = mocap_room(&model);
    let json = tmp.path().join("r.json");
    let stdout = run_ok(
        stream(&room)
            .arg("--c3d")
            .arg(&c3d)
            .arg("--map")
            .arg(map("art-right-hand-glove13.toml"))
            .args(["--speed", "8", "--check", "--report"])
            .arg(&json),
    );
    assert!(stdout.contains("969 acknowledged, 0 refused"), "{stdout}");
    let r = report(&json);
    assert_eq!(r["retarget"]["frames"], 969);
    assert_eq!(r["retarget"]["occluded_frames"], 101);
    assert_eq!(r["retarget"]["estimated_points"], 101, "{r}");
    assert_eq!(r["meshes"]["non_finite"], 0);
    assert_eq!(r["scale"].as_f64().unwrap(), 0.001, "the map's fixed scale");
    drop(room.runtime);
}

#[test]
fn stream_and_retarget_errors_name_the_problem() {
    let err = |cmd: &mut std::process::Command| {
        let out = cmd.output().unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = err(crease().args([
        "stream", "--token", "t", "--frames", "f.csv", "--tsv", "x.tsv", "--map", "m.toml",
    ]));
    assert!(e.contains("cannot be used with"), "{e}");
    let e = err(crease().args([
        "stream", "--token", "t", "--frames", "f.csv", "--speed", "0",
    ]));
    assert!(e.contains("--speed must be a positive factor"), "{e}");
    let Some(src) = data(TSV) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = glove_model(tmp.path());
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        std::fs::read_to_string(map("qualisys-glove13.toml"))
            .unwrap()
            .replace("thumb_tip = \"thumb_tip\"", "thumb_tip = \"thumb_nail\""),
    )
    .unwrap();
    let e = err(crease()
        .args(["retarget", "--tsv"])
        .arg(&src)
        .arg("--map")
        .arg(&bad)
        .arg("--model")
        .arg(&model)
        .args(["--out", "/dev/null"]));
    assert!(
        e.contains("[markers] thumb_tip: the recording has no marker \"thumb_nail\""),
        "{e}"
    );
}

/// `crease room open --mocap | info | close` against a server in this process.
#[test]
fn room_commands_open_inspect_and_close() {
    let tmp = tempfile::tempdir().unwrap();
    let model = TrainedModel::load(common::train_model(tmp.path())).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let served = runtime.block_on(serve_model(
        "tube",
        &model,
        Some("adm"),
        crease_server::Limits::default(),
    ));
    let server = format!("http://{}", served.grpc);
    let room = |args: &[&str]| {
        let mut c = crease();
        c.arg("room").args(args).args(["--server", &server]);
        c
    };
    let token = run_ok(&mut room(&[
        "open",
        "--admin-token",
        "adm",
        "--room",
        "m",
        "--model",
        "tube",
        "--mocap",
    ]));
    assert_eq!(token.trim().len(), 32, "{token}");
    let info = run_ok(&mut room(&["info", "--room", "m"]));
    assert!(
        info.contains("model \"tube\"")
            && info.contains("beta 0.3")
            && info.contains("filter One Euro (min cutoff 1.5 Hz, beta 10, speed cutoff 1 Hz)"),
        "{info}"
    );
    // --beta and --filter override the preset.
    run_ok(&mut room(&[
        "open",
        "--admin-token",
        "adm",
        "--room",
        "k",
        "--model",
        "tube",
        "--mocap",
        "--beta",
        "2",
        "--filter",
        "3,0,1",
    ]));
    let info = run_ok(&mut room(&["info", "--room", "k"]));
    assert!(
        info.contains("beta 2") && info.contains("min cutoff 3 Hz, beta 0,"),
        "{info}"
    );
    // The skinning (issue 22): the model's default (LBS), or --skinning dqs.
    assert!(info.contains(", skinning lbs,"), "{info}");
    let opened = room(&[
        "open",
        "--admin-token",
        "adm",
        "--room",
        "d",
        "--model",
        "tube",
        "--skinning",
        "dqs",
    ])
    .output()
    .unwrap();
    assert!(opened.status.success(), "{opened:?}");
    let said = String::from_utf8_lossy(&opened.stderr);
    assert!(said.contains(", skinning dqs"), "{said}");
    let info = run_ok(&mut room(&["info", "--room", "d"]));
    assert!(info.contains(", skinning dqs,"), "{info}");
    let failed = |mut c: std::process::Command| {
        let out = c.output().unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = failed(room(&[
        "open",
        "--admin-token",
        "wrong",
        "--room",
        "x",
        "--model",
        "tube",
    ]));
    assert!(e.contains("opening room \"x\""), "{e}");
    let e = failed(room(&[
        "open",
        "--admin-token",
        "adm",
        "--room",
        "m",
        "--model",
        "tube",
    ]));
    assert!(e.contains("\"m\" is open"), "{e}");
    run_ok(&mut room(&["close", "--admin-token", "adm", "--room", "m"]));
    let e = failed(room(&["info", "--room", "m"]));
    assert!(e.contains("no room \"m\""), "{e}");
    drop(runtime);
}

/// Issue 38: both hands of the ART C3D in one room of two actors (bench/mocap/
/// art-hands-glove13.toml: the right hand on the glove13 hand, the left on it mirrored), from
/// `crease room open --actors` to `crease stream --c3d --check`: every frame acknowledged,
/// every actor's mesh decoded finite, a residual per hand, the right hand's as in a one-hand
/// room streamed the same recording in the same run; `crease room info` lists the actors and
/// `crease watch` decodes and dumps both hands.
#[test]
fn stream_c3d_into_a_room_of_both_hands() {
    let Some(c3d) = data(C3D) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = TrainedModel::load(glove_model(tmp.path())).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let served = runtime.block_on(serve_model(
        "glove-hand",
        &model,
        Some("admin"),
        crease_server::Limits {
            publish_hz: 4000.0,
            ..crease_server::Limits::default()
        },
    ));
    let server = format!("http://{}", served.grpc);
    let open = |room: &str, how: &[&str]| {
        let mut c = crease();
        c.args([
            "room",
            "open",
            "--server",
            &server,
            "--admin-token",
            "admin",
        ])
        .args([
            "--room",
            room,
            "--beta",
            "0.3",
            "--filter",
            "--markers-from",
        ])
        .arg(&c3d)
        .args(how);
        run_ok(&mut c).trim().to_owned()
    };
    let right_map = map("art-right-hand-glove13.toml");
    let one = open(
        "right",
        &[
            "--model",
            "glove-hand",
            "--map",
            right_map.to_str().unwrap(),
        ],
    );
    let hands = map("art-hands-glove13.toml");
    let both = open("art", &["--actors", hands.to_str().unwrap()]);
    let info = run_ok(crease().args(["room", "info", "--server", &server, "--room", "art"]));
    assert!(
        info.contains("room \"art\": 2 actors")
            && info
                .contains("actor \"right\" (right) of performer \"art\" on model \"glove-hand\"")
            && info.contains(
                "actor \"left\" (left) of performer \"art\" on model \"glove-hand~mirror-x\""
            ),
        "{info}"
    );
    // A viewer of both hands while the recording plays.
    let dump = tmp.path().join("watched");
    let watch = crease()
        .args([
            "watch", "--server", &server, "--room", "art", "--frames", "20", "--dump",
        ])
        .arg(&dump)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    let stream_into = |room: &str, token: &str, json: &Path| {
        run_ok(
            crease()
                .args([
                    "stream", "--server", &server, "--room", room, "--token", token,
                ])
                .arg("--c3d")
                .arg(&c3d)
                .args(["--speed", "4", "--check", "--report"])
                .arg(json),
        )
    };
    let both_json = tmp.path().join("both.json");
    let stdout = stream_into("art", &both, &both_json);
    let watched = watch.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&watched.stderr);
    assert!(watched.status.success(), "crease watch: {said}");
    assert!(said.contains("2 actors: right: "), "{said}");
    for actor in ["right", "left"] {
        let obj = dump.join(format!("frame_00019_{actor}.obj"));
        let mesh = Mesh::read(&obj).unwrap_or_else(|e| panic!("{}: {e}", obj.display()));
        assert!(
            mesh.positions.iter().all(|p| p.is_finite()),
            "{}",
            obj.display()
        );
    }
    let one_json = tmp.path().join("one.json");
    stream_into("right", &one, &one_json);
    assert!(stdout.contains("969 acknowledged, 0 refused"), "{stdout}");
    let r = report(&both_json);
    assert_eq!(r["meshes"]["non_finite"], 0, "{r}");
    assert_eq!(r["meshes"]["decode_errors"], 0, "{r}");
    let actor = |name: &str| {
        r["actors"]
            .as_array()
            .unwrap()
            .iter()
            .find(|a| a["name"] == name)
            .unwrap_or_else(|| panic!("no actor {name} in {r}"))["control_residual_rms_recording_units"]
            .as_f64()
            .unwrap()
    };
    let (right, left) = (actor("right"), actor("left"));
    let alone = report(&one_json)["control_residual_rms_recording_units"]
        .as_f64()
        .unwrap();
    eprintln!(
        "ART C3D residual RMS: right {right:.2} mm, left {left:.2} mm; the right hand alone {alone:.2} mm"
    );
    assert!(
        stdout.contains("actor \"right\": control residual RMS")
            && stdout.contains("actor \"left\""),
        "{stdout}"
    );
    assert!(
        (right - alone).abs() <= 0.02 * alone,
        "right {right} mm in the room of both hands, {alone} mm alone"
    );
    assert!(left > 0.0 && left < 2.0 * alone, "left {left} mm");
    drop(served);
}
