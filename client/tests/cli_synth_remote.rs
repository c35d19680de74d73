//! `crease synth --server URL --model NAME` against a real server (in this process, port 0,
//! the server's default configuration): the meshes the server synthesises, decoded and put
//! back in model vertex order, match the local `crease synth --model FILE` output file for file and vertex for vertex, within the
//! 16-bit quantisation bound of the server's batches (computed here from the `Topology` the
//! server sends to a plain gRPC client), also when the frames are split over several requests
//! and an occluded point starts a request. Both sides refine by default (issue 42) and
//! `--refine off` turns it off on both. Errors name the model, the CSV line and the URL.

use crate::common;

use std::path::Path;
use std::process::Output;

use common::{CONTROLS, bent, crease, serve_tube_defaults, train_model, tube};
use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;

/// Slack on top of the quantisation bound: the bound is half a grid step exactly, and a decoded
/// coordinate is rounded once more to f32 (half an ulp of coordinates below 10).
pub(crate) const EPSILON: f32 = 1e-5;

/// Bends between and beyond the training poses (0.15..0.9). Frames 2 and 3 occlude the second
/// tip point and frame 4 the first mid point: with two frames per request, frames 2 and 4 start
/// a request with a point the server has to hold from an earlier request.
pub(crate) const ANGLES: [f32; 7] = [0.05, 0.3, 0.55, 0.8, 1.0, 0.45, 0.2];

pub(crate) fn occluded(frame: usize, point: usize) -> bool {
    matches!((frame, point), (2 | 3, 4) | (4, 1))
}

/// The control CSV: a header, a comment, then one line per frame (empty fields where occluded).
pub(crate) fn controls_csv() -> String {
    let rest = tube();
    let mut csv = String::from("# the tube bending\n");
    let header: Vec<String> = (0..CONTROLS.len())
        .flat_map(|j| [format!("x{j}"), format!("y{j}"), format!("z{j}")])
        .collect();
    csv += &header.join(",");
    csv.push('\n');
    for (i, &angle) in ANGLES.iter().enumerate() {
        let pose = bent(&rest, angle);
        let fields: Vec<String> = CONTROLS
            .iter()
            .enumerate()
            .flat_map(|(j, &c)| {
                if occluded(i, j) {
                    vec![String::new(); 3]
                } else {
                    pose.positions[c].to_array().map(|v| v.to_string()).to_vec()
                }
            })
            .collect();
        csv += &fields.join(",");
        csv.push('\n');
    }
    csv
}

pub(crate) fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The sorted file names in `dir`.
pub(crate) fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A triangle starting at its smallest corner (meshopt's index codec may rotate corners).
fn canonical(t: &[u32; 3]) -> [u32; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap();
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

/// Every vertex of `got` within `bound` (per axis) of `want`; the same triangles.
pub(crate) fn assert_close(what: &str, got: &Mesh, want: &Mesh, bound: Vec3) {
    assert_eq!(
        got.vertex_count(),
        want.vertex_count(),
        "{what}: vertex count"
    );
    let g: Vec<_> = got.triangles.iter().map(canonical).collect();
    let w: Vec<_> = want.triangles.iter().map(canonical).collect();
    assert_eq!(g, w, "{what}: triangles");
    for (i, (a, b)) in got.positions.iter().zip(&want.positions).enumerate() {
        let d = (*a - *b).abs();
        assert!(
            d.cmple(bound).all(),
            "{what}, vertex {i}: remote {a}, local {b} (off by {d}, bound {bound})"
        );
    }
}

/// The model at `path` with its skin replaced by a smooth blend of bones 0 and 1 along the
/// tube (all of bone 0 below z = 2, all of bone 1 above z = 5): what LBS and DQS differ on.
fn blended_weights(path: &Path) -> TrainedModel {
    let mut model = TrainedModel::load(path).unwrap();
    assert_eq!(model.rig.bone_count, 2);
    // Which bone holds the tube's base (z = 0) in the fitted rig.
    let (bones, weights) = model.rig.skin.vertex(0);
    let base = bones[weights
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .unwrap()
        .0];
    let (mut indices, mut blend) = (Vec::new(), Vec::new());
    for p in &model.rig.rest.positions {
        let t = ((p.z - 2.0) / 3.0).clamp(0.0, 1.0);
        indices.extend([base, 1 - base]);
        blend.extend([1.0 - t, t]);
    }
    model.rig.skin = crease_core::runtime::skin::SkinWeights::new(2, indices, blend).unwrap();
    model.validate().unwrap();
    model
}

/// Half a grid step (plus [`EPSILON`]) of the batches of the server at `addr`, from the
/// `Topology` it sends a plain gRPC client.
pub(crate) async fn batch_bound(addr: std::net::SocketAddr) -> Vec3 {
    batch_bound_of(addr, "tube").await
}

/// [`batch_bound`] of the server's model `model`.
pub(crate) async fn batch_bound_of(addr: std::net::SocketAddr, model: &str) -> Vec3 {
    let mut client = CreaseClient::connect(format!("http://{addr}"))
        .await
        .unwrap();
    let mut stream = client
        .synthesize(v1::SynthesizeRequest {
            model: model.into(),
            frames: Vec::new(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let Some(v1::mesh_frame::Body::Topology(t)) = stream.message().await.unwrap().unwrap().body
    else {
        panic!("the batch starts with its topology");
    };
    let q = t.quantization.unwrap();
    let (lo, hi) = (Vec3::from(q.min.unwrap()), Vec3::from(q.max.unwrap()));
    (hi - lo) / ((1u32 << t.bits) - 1) as f32 * 0.5 + Vec3::splat(EPSILON)
}

#[test]
fn remote_synth_matches_local_synth_within_the_quantisation_bound() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let model_path = train_model(dir);
    let model = TrainedModel::load(&model_path).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (addr, qbox, _served) = runtime.block_on(async {
        let served = serve_tube_defaults(model).await;
        let addr = served.grpc;
        // The quantisation box of the server's batches, as any client sees it.
        let mut client = CreaseClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
        let mut stream = client
            .synthesize(v1::SynthesizeRequest {
                model: "tube".into(),
                frames: Vec::new(),
                ..Default::default()
            })
            .await
            .unwrap()
            .into_inner();
        let Some(v1::mesh_frame::Body::Topology(t)) = stream.message().await.unwrap().unwrap().body
        else {
            panic!("the batch starts with its topology");
        };
        (addr, t, served)
    });
    let url = format!("http://{addr}");
    let q = qbox.quantization.unwrap();
    let (lo, hi) = (Vec3::from(q.min.unwrap()), Vec3::from(q.max.unwrap()));
    let step = (hi - lo) / ((1u32 << qbox.bits) - 1) as f32;
    assert_eq!(qbox.bits, 16, "batches are 16-bit");
    let bound = step * 0.5 + Vec3::splat(EPSILON);
    assert!(
        bound.max_element() < 1e-3,
        "a 16-bit bound of a 7-unit tube is ~1e-4, got {bound}"
    );

    let controls = dir.join("controls.csv");
    std::fs::write(&controls, controls_csv()).unwrap();
    let synth = |model: &str, server: Option<&str>| {
        let mut c = crease();
        c.args(["synth", "--model", model, "--controls"])
            .arg(&controls);
        if let Some(s) = server {
            c.args(["--server", s]);
        }
        c
    };
    let model_arg = model_path.to_str().unwrap();

    // Local synthesis, the reference.
    let local = dir.join("local");
    let out = synth(model_arg, None)
        .arg("--out")
        .arg(&local)
        .output()
        .unwrap();
    assert!(out.status.success(), "local synth: {}", stderr(&out));
    let local_names = names(&local);
    assert_eq!(local_names.len(), ANGLES.len());
    let local_meshes: Vec<Mesh> = (0..ANGLES.len())
        .map(|i| Mesh::read(local.join(format!("frame_{i:05}.obj"))).unwrap())
        .collect();
    // The frames differ from each other by far more than the bound (the comparison means
    // something), and the occluded frames were bent (the held tip point mattered).
    for w in local_meshes.windows(2) {
        let moved = w[0]
            .positions
            .iter()
            .zip(&w[1].positions)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f32::max);
        assert!(moved > 0.1, "consecutive frames {moved} apart");
    }

    // Remote, one request: same names, same meshes.
    let remote = dir.join("remote");
    let out = synth("tube", Some(&url))
        .arg("--out")
        .arg(&remote)
        .output()
        .unwrap();
    assert!(out.status.success(), "remote synth: {}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.starts_with(&format!("wrote {} frames to ", ANGLES.len()))
            && stdout.contains("bytes/vertex/frame")
            && stdout.contains("3 occluded control values held"),
        "{stdout}"
    );
    assert_eq!(names(&remote), local_names);
    for (i, want) in local_meshes.iter().enumerate() {
        let got = Mesh::read(remote.join(format!("frame_{i:05}.obj"))).unwrap();
        assert_close(&format!("frame {i}"), &got, want, bound);
    }
    // `--refine off` on both sides: the same meshes again, and not the default's (the default
    // refines these bends: some vertex moves by far more than the bound).
    let (local_off, remote_off) = (dir.join("local-off"), dir.join("remote-off"));
    for (model, server, out_dir) in [
        (model_arg, None, &local_off),
        ("tube", Some(url.as_str()), &remote_off),
    ] {
        let out = synth(model, server)
            .args(["--refine", "off", "--out"])
            .arg(out_dir)
            .output()
            .unwrap();
        assert!(out.status.success(), "synth --refine off: {}", stderr(&out));
    }
    let mut refined_by = 0.0f32;
    for (i, refined) in local_meshes.iter().enumerate() {
        let plain = Mesh::read(local_off.join(format!("frame_{i:05}.obj"))).unwrap();
        let got = Mesh::read(remote_off.join(format!("frame_{i:05}.obj"))).unwrap();
        assert_close(&format!("unrefined frame {i}"), &got, &plain, bound);
        for (a, b) in plain.positions.iter().zip(&refined.positions) {
            refined_by = refined_by.max(a.distance(*b));
        }
    }
    assert!(
        refined_by > 100.0 * bound.max_element(),
        "the default refinement moved no vertex beyond the bound: {refined_by}"
    );

    // Remote, two frames per request, PLY, and a glTF: continuous numbering, the held points
    // carried over request boundaries.
    let chunked = dir.join("chunked");
    let glb = dir.join("remote.glb");
    let out = synth("tube", Some(&url))
        .args(["--chunk-frames", "2", "--format", "ply", "--out"])
        .arg(&chunked)
        .arg("--gltf")
        .arg(&glb)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "chunked remote synth: {}",
        stderr(&out)
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("4 requests"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let ply_names: Vec<String> = local_names
        .iter()
        .map(|n| n.replace(".obj", ".ply"))
        .collect();
    assert_eq!(names(&chunked), ply_names);
    for (i, want) in local_meshes.iter().enumerate() {
        let got = Mesh::read(chunked.join(format!("frame_{i:05}.ply"))).unwrap();
        assert_close(&format!("chunked frame {i}"), &got, want, bound);
    }
    // The glTF's keyframe i (its rest mesh plus morph target i) is frame i.
    let (doc, buffers, _) = gltf::import(&glb).expect("the GLB loads");
    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|b| Some(&buffers[b.index()]));
    let base: Vec<Vec3> = reader
        .read_positions()
        .unwrap()
        .map(Vec3::from_array)
        .collect();
    let targets: Vec<_> = reader.read_morph_targets().collect();
    assert_eq!(targets.len(), ANGLES.len(), "one morph target per frame");
    for (i, (t, want)) in targets.into_iter().zip(&local_meshes).enumerate() {
        let positions: Vec<Vec3> = base
            .iter()
            .zip(t.0.expect("POSITION displacements"))
            .map(|(&b, d)| b + Vec3::from_array(d))
            .collect();
        let got = Mesh {
            positions,
            triangles: want.triangles.clone(),
        };
        assert_close(&format!("glTF keyframe {i}"), &got, want, bound);
    }

    // --skinning dqs (issue 22), locally and on the server. This tube's two bones are rigid
    // segments, on which LBS and DQS agree; a copy whose weights blend the bones smoothly
    // along the tube (z from 2 to 5) tells them apart: the same DQS meshes on both sides, and
    // not the LBS ones (the option reached the predictor on both sides).
    let blended = blended_weights(&model_path);
    let blended_path = dir.join("blended.crease");
    blended.save(&blended_path).unwrap();
    let (blended_url, blended_bound, _blended_served) = runtime.block_on(async {
        let served = serve_tube_defaults(blended).await;
        let addr = served.grpc;
        (format!("http://{addr}"), batch_bound(addr).await, served)
    });
    let blended_arg = blended_path.to_str().unwrap();
    let run_into = |model: &str, server: Option<&str>, skinning: &str, out_dir: &Path| {
        let out = synth(model, server)
            .args(["--skinning", skinning, "--out"])
            .arg(out_dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "synth --skinning {skinning}: {}",
            stderr(&out)
        );
    };
    let (local_lbs, local_dqs, remote_dqs) = (
        dir.join("blended-lbs"),
        dir.join("blended-dqs"),
        dir.join("blended-remote-dqs"),
    );
    run_into(blended_arg, None, "lbs", &local_lbs);
    run_into(blended_arg, None, "dqs", &local_dqs);
    run_into("tube", Some(&blended_url), "dqs", &remote_dqs);
    let mut apart: f32 = 0.0;
    for i in 0..ANGLES.len() {
        let name = format!("frame_{i:05}.obj");
        let want = Mesh::read(local_dqs.join(&name)).unwrap();
        let got = Mesh::read(remote_dqs.join(&name)).unwrap();
        assert_close(&format!("DQS frame {i}"), &got, &want, blended_bound);
        let lbs = Mesh::read(local_lbs.join(&name)).unwrap();
        apart = lbs
            .positions
            .iter()
            .zip(&want.positions)
            .map(|(a, b)| a.distance(*b))
            .fold(apart, f32::max);
    }
    assert!(
        apart > 10.0 * blended_bound.max_element(),
        "DQS frames {apart} from the LBS ones (bound {blended_bound})"
    );

    // An unknown model: the server's NotFound, naming it.
    let out = synth("no-such-model", Some(&url))
        .arg("--out")
        .arg(dir.join("none"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("no-such-model"), "{}", stderr(&out));

    // A CSV line with a wrong field count: the line named, remotely and locally.
    let bad = dir.join("bad.csv");
    let mut lines: Vec<String> = controls_csv().lines().map(str::to_owned).collect();
    lines[3].push_str(",1.0");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    for (model, server) in [("tube", Some(url.as_str())), (model_arg, None)] {
        let mut c = crease();
        c.args(["synth", "--model", model, "--controls"])
            .arg(&bad)
            .arg("--out")
            .arg(dir.join("bad"));
        if let Some(s) = server {
            c.args(["--server", s]);
        }
        let out = c.output().unwrap();
        assert!(!out.status.success());
        let err = stderr(&out);
        assert!(
            err.contains("line 4") && err.contains("16 fields, expected 15"),
            "{err}"
        );
    }

    // An unreachable server: the URL named.
    let free = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let dead = format!("http://{}", free.local_addr().unwrap());
    drop(free);
    let out = synth("tube", Some(&dead))
        .arg("--out")
        .arg(dir.join("dead"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains(&dead), "{}", stderr(&out));
}
