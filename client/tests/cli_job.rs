//! Batch jobs without a cluster (issue 45): `crease job submit|watch|get|list|cancel` against
//! a server in this process (the server's default configuration, chunks of 2 frames so the
//! held points cross chunk boundaries: frames 2 and 4 start a chunk while a point is
//! occluded). The fetched frames equal a local `crease synth` of the same file within the
//! 16-bit bound of batches; a refused frame is named by its index in the job; unknown models
//! and jobs, a cancel of an ended job, a cancel that stops a long job, and a result fetched
//! after it expired each get a clear answer.

use crate::cli_synth_remote::{ANGLES, assert_close, batch_bound, controls_csv, names, stderr};
use crate::cli_take::max_distance;
use crate::common;

use std::time::Duration;

use common::{crease, serve_config, train_model};
use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_server::jobs::JobSettings;

const ADMIN: &str = "job-admin";

/// A server hosting `model` as `tube` with the default configuration but `jobs`.
async fn serve(model: TrainedModel, jobs: JobSettings) -> common::Served {
    serve_config(
        [("tube", model)],
        crease_server::Config {
            admin_token: Some(ADMIN.into()),
            jobs,
            ..crease_server::Config::default()
        },
    )
    .await
}

fn small_chunks() -> JobSettings {
    JobSettings {
        chunk_frames: 2,
        ..JobSettings::default()
    }
}

#[test]
fn a_job_equals_local_synth_and_every_refusal_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let model_path = train_model(dir);
    let model = TrainedModel::load(&model_path).unwrap();
    let count = model.controls.len();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (addr, bound, served) = runtime.block_on(async {
        let served = serve(model.clone(), small_chunks()).await;
        let bound = batch_bound(served.grpc).await;
        (served.grpc, bound, served)
    });
    let http = served.http;
    let url = format!("http://{addr}");
    let controls = dir.join("controls.csv");
    std::fs::write(&controls, controls_csv()).unwrap();
    let job = |args: &[&str]| job_cli(&url, args);

    // The reference: local synthesis of the same file.
    let local = dir.join("local");
    let out = crease()
        .args(["synth", "--model"])
        .arg(&model_path)
        .arg("--controls")
        .arg(&controls)
        .arg("--out")
        .arg(&local)
        .output()
        .unwrap();
    assert!(out.status.success(), "local synth: {}", stderr(&out));

    // Submit: the id on stdout, at once.
    let out = job(&[
        "submit",
        "--model",
        "tube",
        "--controls",
        controls.to_str().unwrap(),
        "--name",
        "bend",
    ]);
    assert!(out.status.success(), "submit: {}", stderr(&out));
    let id = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    assert!(crease_proto::job::is_job_id(&id), "{id:?}");
    assert!(stderr(&out).contains("4 chunks"), "{}", stderr(&out));

    // Watch until it ends: done, every frame.
    let out = job(&["watch", &id]);
    assert!(out.status.success(), "watch: {}", stderr(&out));
    let line = String::from_utf8_lossy(&out.stdout);
    assert!(
        line.contains(&format!("job {id} (done)")) && line.contains("7 of 7 frames"),
        "{line}"
    );

    // Get: the same file names as local synthesis, the same meshes within the bound.
    let fetched = dir.join("fetched");
    let out = job(&["get", &id, "--out", fetched.to_str().unwrap()]);
    assert!(out.status.success(), "get: {}", stderr(&out));
    assert_eq!(names(&fetched), names(&local));
    for i in 0..ANGLES.len() {
        let want = Mesh::read(local.join(format!("frame_{i:05}.obj"))).unwrap();
        let got = Mesh::read(fetched.join(format!("frame_{i:05}.obj"))).unwrap();
        assert_close(&format!("job frame {i}"), &got, &want, bound);
    }

    // Get as codec: the stream as sent, which `crease decode-stream` decodes to the last
    // frame's mesh.
    let stream_file = dir.join("job.stream");
    let out = job(&[
        "get",
        &id,
        "--format",
        "codec",
        "--out",
        stream_file.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "get codec: {}", stderr(&out));
    let last = dir.join("last.obj");
    let out = crease()
        .arg("decode-stream")
        .arg(&stream_file)
        .arg("--out")
        .arg(&last)
        .output()
        .unwrap();
    assert!(out.status.success(), "decode-stream: {}", stderr(&out));
    let n = ANGLES.len() - 1;
    let want = Mesh::read(local.join(format!("frame_{n:05}.obj"))).unwrap();
    assert_close(
        "codec's last frame",
        &Mesh::read(&last).unwrap(),
        &want,
        bound,
    );

    // Get as glTF: the frames baked into morph targets (the first is the base), each keyframe
    // the fetched OBJ, read back by the `gltf` crate.
    let glb = dir.join("job.glb");
    let out = job(&[
        "get",
        &id,
        "--format",
        "gltf",
        "--out",
        glb.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "get gltf: {}", stderr(&out));
    let baked = morph_frames(&glb);
    assert_eq!(baked.len(), ANGLES.len(), "one morph target per frame");
    for (i, frame) in baked.iter().enumerate() {
        let obj = Mesh::read(fetched.join(format!("frame_{i:05}.obj"))).unwrap();
        let d = max_distance(frame, &obj.positions);
        assert!(d <= 1e-5, "glTF frame {i}: {d} from the fetched OBJ");
    }

    // List: the job, named.
    let out = job(&["list"]);
    let listed = String::from_utf8_lossy(&out.stdout);
    assert!(
        listed.contains(&id) && listed.contains("\"bend\""),
        "{listed}"
    );

    // A cancel of an ended job says so.
    let out = job(&["cancel", &id]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains(&format!(
            "job {id:?} already ended (done): nothing to cancel"
        )),
        "{}",
        stderr(&out)
    );
    // Unknown jobs and models.
    let out = job(&["watch", "nosuchjob123"]);
    assert!(
        stderr(&out).contains("no job \"nosuchjob123\""),
        "{}",
        stderr(&out)
    );
    let out = job(&[
        "get",
        "nosuchjob123",
        "--out",
        dir.join("x").to_str().unwrap(),
    ]);
    assert!(
        stderr(&out).contains("no job \"nosuchjob123\""),
        "{}",
        stderr(&out)
    );
    let out = job(&[
        "submit",
        "--model",
        "nope",
        "--controls",
        controls.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no model \"nope\""),
        "{}",
        stderr(&out)
    );

    runtime.block_on(async {
        let mut client = CreaseClient::connect(url.clone()).await.unwrap();
        // A frame with a point missing, deep in the job: refused whole, by its index.
        let frame = |points: usize| {
            crease_proto::control::control_frame(
                "",
                0,
                0,
                &vec![Vec3::ZERO; points],
                &vec![true; points],
            )
        };
        let mut frames: Vec<_> = (0..5).map(|_| frame(count)).collect();
        frames[3] = frame(count - 1);
        let submit = |frames: Vec<v1::ControlFrame>| {
            let messages = vec![
                v1::SubmitJobRequest {
                    part: Some(v1::submit_job_request::Part::Spec(v1::JobSpec {
                        model: "tube".into(),
                        ..Default::default()
                    })),
                },
                v1::SubmitJobRequest {
                    part: Some(v1::submit_job_request::Part::Frames(v1::JobFrames {
                        frames,
                    })),
                },
            ];
            crease_remote::client::authorized(tokio_stream::iter(messages), ADMIN).unwrap()
        };
        let e = client.submit_job(submit(frames)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert_eq!(
            e.message(),
            format!(
                "SubmitJob.frames[3].positions: {} values, expected {} (x, y, z of {count} control points)",
                3 * (count - 1),
                3 * count
            )
        );
        let refused = crease_proto::errors::batch_frame_error(&e).unwrap();
        assert_eq!(refused.frame, Some(3));
        // Nothing was queued.
        let jobs = client
            .list_jobs(v1::ListJobsRequest {})
            .await
            .unwrap()
            .into_inner()
            .jobs;
        assert_eq!(jobs.len(), 1, "only the first job: {jobs:?}");
        // Without the admin token.
        let e = client
            .submit_job(tokio_stream::iter(Vec::<v1::SubmitJobRequest>::new()))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated, "{e:?}");

        // A long job (2,000 chunks of 2 frames), cancelled at once: it ends cancelled with
        // most of its frames never run, and a watcher learns it.
        let long: Vec<_> = (0..4000).map(|_| frame(count)).collect();
        let info = client.submit_job(submit(long)).await.unwrap().into_inner();
        // The gauges count it (queued or running), and the done job in neither.
        let metrics = tokio::task::spawn_blocking(move || http_get(http, "/metrics"))
            .await
            .unwrap();
        let gauge = |name: &str| -> i64 {
            let line = metrics.lines().find(|l| l.starts_with(&format!("{name} "))).unwrap_or_else(|| panic!("no {name} in /metrics"));
            line[name.len() + 1..].trim().parse().unwrap()
        };
        assert_eq!(gauge("crease_jobs_queued") + gauge("crease_jobs_running"), 1, "{metrics}");
        let cancelled = client
            .cancel_job(
                crease_remote::client::authorized(
                    v1::CancelJobRequest {
                        job: info.job.clone(),
                    },
                    ADMIN,
                )
                .unwrap(),
            )
            .await
            .unwrap()
            .into_inner();
        assert!(
            cancelled.chunks_done < cancelled.chunks_total,
            "{cancelled:?}"
        );
        let last = watch_to_end(&mut client, &info.job).await;
        assert_eq!(last.state, v1::JobState::Cancelled as i32, "{last:?}");
        assert!(last.frames_done < 4000, "{last:?}");
        // Its result: none.
        let e = client
            .get_job_result(v1::GetJobResultRequest {
                job: info.job.clone(),
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains("cancelled"), "{}", e.message());
    });

    // A server that keeps results for no time: the result of a done job has expired.
    let expiring = runtime.block_on(serve(
        model,
        JobSettings {
            ttl: Duration::ZERO,
            ..small_chunks()
        },
    ));
    let url = format!("http://{}", expiring.grpc);
    let run = |args: &[&str]| {
        crease()
            .arg("job")
            .args(args)
            .args(["--server", &url])
            .env("CREASE_ADMIN_TOKEN", ADMIN)
            .output()
            .unwrap()
    };
    let out = run(&[
        "submit",
        "--model",
        "tube",
        "--controls",
        controls.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let id = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    assert!(run(&["watch", &id]).status.success());
    let out = run(&["get", &id, "--out", dir.join("late").to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("its result expired"),
        "{}",
        stderr(&out)
    );
    drop(expiring);
}

/// A job whose model is deleted while it runs fails, naming the model; `GET /api/jobs` (the
/// viewer's list) shows it failed with that reason.
#[test]
fn a_job_whose_model_is_deleted_fails_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let model_path = train_model(tmp.path());
    let model = TrainedModel::load(&model_path).unwrap();
    let models = tmp.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    std::fs::copy(&model_path, models.join("tube.crease")).unwrap();
    let count = model.controls.len();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let served = serve_config(
            [("tube", model)],
            crease_server::Config {
                admin_token: Some(ADMIN.into()),
                models_dir: Some(models.clone()),
                jobs: small_chunks(),
                ..crease_server::Config::default()
            },
        )
        .await;
        let mut client = CreaseClient::connect(format!("http://{}", served.grpc))
            .await
            .unwrap();
        let frame = crease_proto::control::control_frame(
            "",
            0,
            0,
            &vec![Vec3::ZERO; count],
            &vec![true; count],
        );
        let messages = vec![
            v1::SubmitJobRequest {
                part: Some(v1::submit_job_request::Part::Spec(v1::JobSpec {
                    model: "tube".into(),
                    ..Default::default()
                })),
            },
            v1::SubmitJobRequest {
                part: Some(v1::submit_job_request::Part::Frames(v1::JobFrames {
                    frames: vec![frame; 20_000],
                })),
            },
        ];
        let job = client
            .submit_job(
                crease_remote::client::authorized(tokio_stream::iter(messages), ADMIN).unwrap(),
            )
            .await
            .unwrap()
            .into_inner();
        client
            .delete_model(
                crease_remote::client::authorized(
                    v1::DeleteModelRequest {
                        model: "tube".into(),
                    },
                    ADMIN,
                )
                .unwrap(),
            )
            .await
            .unwrap();
        let last = watch_to_end(&mut client, &job.job).await;
        assert_eq!(last.state, v1::JobState::Failed as i32, "{last:?}");
        assert!(last.frames_done < 20_000, "{last:?}");
        assert!(
            last.error.contains("chunk ") && last.error.contains("\"tube\""),
            "{}",
            last.error
        );
        let body = http_get(served.http, "/api/jobs");
        let list: crease_proto::json::JobList = serde_json::from_str(&body).unwrap();
        let listed = list.jobs.iter().find(|j| j.job == job.job).unwrap();
        assert_eq!(listed.state, "failed");
        assert_eq!(listed.error, last.error);
        assert_eq!(listed.level, "base");
        assert_eq!(listed.encoding, "vertices");
    });
}

/// Runs `crease job ARGS --server URL` with the admin token.
fn job_cli(url: &str, args: &[&str]) -> std::process::Output {
    let mut c = crease();
    c.arg("job").args(args).args(["--server", url]);
    c.env("CREASE_ADMIN_TOKEN", ADMIN);
    c.output().unwrap()
}

#[test]
fn a_palette_job_is_a_skinned_gltf_of_its_decoded_bones() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let model_path = train_model(dir);
    let model = TrainedModel::load(&model_path).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let served = runtime.block_on(serve(model, small_chunks()));
    let url = format!("http://{}", served.grpc);
    let controls = dir.join("controls.csv");
    std::fs::write(&controls, controls_csv()).unwrap();
    let controls = controls.to_str().unwrap();
    let local = dir.join("local");
    let out = crease()
        .args(["synth", "--model"])
        .arg(&model_path)
        .args(["--controls", controls, "--out"])
        .arg(&local)
        .output()
        .unwrap();
    assert!(out.status.success(), "local synth: {}", stderr(&out));

    // A palette job skinned with DQS is refused at submit, saying why.
    let submit = ["submit", "--model", "tube", "--controls", controls];
    let out = job_cli(
        &url,
        &[&submit[..], &["--encoding", "palette", "--skinning", "dqs"]].concat(),
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("JobSpec.encoding") && stderr(&out).contains("DQS"),
        "{}",
        stderr(&out)
    );

    let out = job_cli(&url, &[&submit[..], &["--encoding", "palette"]].concat());
    assert!(out.status.success(), "submit: {}", stderr(&out));
    let id = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    let out = job_cli(&url, &["watch", &id]);
    assert!(out.status.success(), "watch: {}", stderr(&out));
    let line = String::from_utf8_lossy(&out.stdout);
    assert!(
        line.contains("(done)") && line.contains("palette"),
        "{line}"
    );

    // The frames the reference decoder makes of the palette frames, and the skinned glTF.
    let decoded = dir.join("decoded");
    let out = job_cli(&url, &["get", &id, "--out", decoded.to_str().unwrap()]);
    assert!(out.status.success(), "get: {}", stderr(&out));
    let glb = dir.join("skinned.glb");
    let out = job_cli(
        &url,
        &[
            "get",
            &id,
            "--format",
            "gltf",
            "--fps",
            "10",
            "--out",
            glb.to_str().unwrap(),
        ],
    );
    assert!(out.status.success(), "get gltf: {}", stderr(&out));
    let doc = gltf::Gltf::from_slice(&std::fs::read(&glb).unwrap()).unwrap();
    let anim = doc.animations().next().expect("one animation");
    let keyframes = anim.channels().next().unwrap().sampler().input().count();
    assert_eq!(keyframes, ANGLES.len(), "one keyframe per frame");

    let rest = Mesh::read(local.join("frame_00000.obj")).unwrap();
    let (lo, hi) = rest.positions.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let size = lo.distance(hi);
    let mut moved = 0.0f32;
    for k in 0..ANGLES.len() {
        let want = Mesh::read(local.join(format!("frame_{k:05}.obj"))).unwrap();
        let palette = Mesh::read(decoded.join(format!("frame_{k:05}.obj"))).unwrap();
        // The glTF, skinned as a viewer does, is the decoded frame (f32 rounding apart).
        let skinned = crate::cli_take::gltf_skinned(&doc, k);
        let d = max_distance(&skinned, &palette.positions);
        assert!(
            d <= 1e-5 * size,
            "frame {k}: glTF {d} from the decoded palette frame"
        );
        // And the palette frame is the prediction within its quantisation (rotations to
        // ~2e-5 rad, translations to 16 bits of the pose box: well under 1e-3 of the size).
        let d = max_distance(&palette.positions, &want.positions);
        assert!(
            d <= 1e-3 * size,
            "frame {k}: palette {d} from local synth (size {size})"
        );
        moved = moved.max(max_distance(&want.positions, &rest.positions));
    }
    assert!(moved > 0.05 * size, "the frames bend the tube ({moved})");
    drop(served);
}

/// Every keyframe's mesh of a morph-target animation (`crease synth --gltf`'s layout): the base
/// positions plus target `i`'s displacements.
fn morph_frames(glb: &std::path::Path) -> Vec<Vec<Vec3>> {
    let (doc, buffers, _) = gltf::import(glb).expect("the GLB loads");
    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|b| Some(&buffers[b.index()]));
    let base: Vec<Vec3> = reader.read_positions().unwrap().map(Vec3::from).collect();
    reader
        .read_morph_targets()
        .map(|t| {
            base.iter()
                .zip(t.0.expect("POSITION displacements"))
                .map(|(b, d)| *b + Vec3::from(d))
                .collect()
        })
        .collect()
}

/// The body of `GET path` on `addr` (HTTP/1.0, which must answer 200).
fn http_get(addr: std::net::SocketAddr, path: &str) -> String {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").unwrap();
    let mut response = String::new();
    s.read_to_string(&mut response).unwrap();
    let (head, body) = response.split_once("\r\n\r\n").unwrap();
    assert!(
        head.starts_with("HTTP/1.0 200") || head.starts_with("HTTP/1.1 200"),
        "{head}\n{body}"
    );
    body.to_owned()
}

/// Watches `job` on `client` to its end (no gap of 30 s between updates); its last status.
async fn watch_to_end(
    client: &mut CreaseClient<tonic::transport::Channel>,
    job: &str,
) -> v1::JobInfo {
    let mut watch = client
        .watch_job(v1::WatchJobRequest { job: job.into() })
        .await
        .unwrap()
        .into_inner();
    let mut last = None;
    while let Some(s) = tokio::time::timeout(Duration::from_secs(30), watch.message())
        .await
        .expect("the watch ends once the job has")
        .unwrap()
    {
        last = Some(s);
    }
    last.expect("a watch sends the status at least once")
}
