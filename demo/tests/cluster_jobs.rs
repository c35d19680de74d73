//! Batch jobs across replicas (issue 45), end to end: a real `nats-server` with JetStream and
//! two `crease-server` replicas A and B (the tube model, chunks of 40 frames, a 2 s ack wait).
//!
//! A job submitted to B (its client gone right after) is watched from A; B is `kill -9`ed while
//! it holds a chunk (stopped first and checked on the work queue's consumer: two chunks
//! unacknowledged while A holds at most one); the job still completes on A, A's metrics count
//! the redelivery, every frame of the result comes once and in order, each equals the
//! in-process prediction within the stream's quantisation, and the result equals, byte for
//! byte, the same job run by A alone afterwards. A cancelled job stops within one chunk.
//!
//! Skips, saying why, when `nats-server` is not installed (`.ci/run` installs it).

use crate::cluster_kit;
use crate::common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{authed, check_decoded, control_frame, model, predicted};
use crease_core::codec::FrameDecoder;
use crease_proto::v1;
use tonic::transport::Channel;

use cluster_kit::{ADMIN, Nats, Replica, free_port, nats_binary, until};
use v1::crease_client::CreaseClient;

const FRAMES: u64 = 3000;
const CHUNK: u64 = 40;

/// Frame `i`'s bend: inside the poses the tube was trained on (0 to 1.25 rad), where the
/// prediction stays in the model's pose box (the batch's quantisation box).
fn angle(i: u64) -> f32 {
    0.6 + 0.6 * (i as f32 * 0.01).sin()
}

fn frames(model: &crease_core::model::TrainedModel) -> Vec<v1::ControlFrame> {
    (0..FRAMES)
        .map(|i| control_frame(model, "", i, angle(i)))
        .collect()
}

/// Submits a job of `frames` on the tube model (admin token).
pub(crate) async fn submit(
    client: &mut CreaseClient<Channel>,
    frames: &[v1::ControlFrame],
) -> v1::JobInfo {
    let mut parts = vec![v1::SubmitJobRequest {
        part: Some(v1::submit_job_request::Part::Spec(v1::JobSpec {
            model: "tube".into(),
            ..Default::default()
        })),
    }];
    parts.extend(frames.chunks(500).map(|f| v1::SubmitJobRequest {
        part: Some(v1::submit_job_request::Part::Frames(v1::JobFrames {
            frames: f.to_vec(),
        })),
    }));
    client
        .submit_job(authed(tokio_stream::iter(parts), ADMIN))
        .await
        .unwrap()
        .into_inner()
}

async fn info(client: &mut CreaseClient<Channel>, job: &str) -> v1::JobInfo {
    let mut watch = client
        .watch_job(v1::WatchJobRequest { job: job.into() })
        .await
        .unwrap()
        .into_inner();
    watch.message().await.unwrap().unwrap()
}

/// Watches `job` to its end; returns its last status.
pub(crate) async fn watch_to_end(client: &mut CreaseClient<Channel>, job: &str) -> v1::JobInfo {
    let mut watch = client
        .watch_job(v1::WatchJobRequest { job: job.into() })
        .await
        .unwrap()
        .into_inner();
    let mut last = None;
    while let Some(info) = tokio::time::timeout(Duration::from_secs(120), watch.message())
        .await
        .expect("the job's watch went silent for 2 minutes")
        .unwrap()
    {
        last = Some(info);
    }
    last.expect("a watch sends the status at least once")
}

/// A done job's result: its topology, then every frame.
pub(crate) async fn result(client: &mut CreaseClient<Channel>, job: &str) -> Vec<v1::MeshFrame> {
    let mut stream = client
        .get_job_result(v1::GetJobResultRequest { job: job.into() })
        .await
        .unwrap()
        .into_inner();
    let mut out = Vec::new();
    while let Some(m) = stream.message().await.unwrap() {
        out.push(m);
    }
    out
}

/// Unacknowledged chunks on the work queue's consumer.
async fn ack_pending(js: &async_nats::jetstream::Context) -> usize {
    let mut consumer: async_nats::jetstream::consumer::PullConsumer = js
        .get_consumer_from_stream(
            crease_server::cluster::work::JOBS_CONSUMER,
            crease_server::cluster::work::JOBS_STREAM,
        )
        .await
        .unwrap();
    consumer.info().await.unwrap().num_ack_pending
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_survives_a_killed_replica_and_equals_a_single_replica_run() {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let nats = Nats::start(&nats_bin, free_port(), &dir.path().join("js"));
    let model = Arc::new(model());
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    model.save(models.join("tube.crease")).unwrap();
    let args: Vec<String> = [
        "--job-chunk-frames",
        &CHUNK.to_string(),
        "--job-ack-wait",
        "2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let mut a = Replica::start_with("A", &models, &nats.url(), dir.path(), &args);
    let mut b = Replica::start_with("B", &models, &nats.url(), dir.path(), &args);
    a.ready().await;
    b.ready().await;
    let js = async_nats::jetstream::new(async_nats::connect(nats.url()).await.unwrap());
    let frames = frames(&model);

    // Submitted to B, whose client then goes away.
    let job = {
        let mut on_b = b.client().await;
        submit(&mut on_b, &frames).await
    };
    assert_eq!(job.frames_total, FRAMES);
    assert_eq!(u64::from(job.chunks_total), FRAMES.div_ceil(CHUNK));
    let mut on_a = a.client().await;

    // Kill B while it holds a chunk: stopped, then checked (A holds at most one at a time).
    until(Duration::from_secs(60), "B ran a chunk", || async {
        b.metric("crease_cluster_job_chunks_total").await >= 1.0
    })
    .await;
    let mut killed = false;
    for _ in 0..50 {
        cluster_kit::signal(&b, "-STOP");
        let deadline = Instant::now() + Duration::from_millis(300);
        while Instant::now() < deadline {
            if ack_pending(&js).await >= 2 {
                killed = true;
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        if killed {
            b.kill9();
            break;
        }
        cluster_kit::signal(&b, "-CONT");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(killed, "never caught B holding a chunk");
    let at_kill = info(&mut on_a, &job.job).await;
    println!(
        "B killed holding a chunk: {} of {} chunks stored",
        at_kill.chunks_done, at_kill.chunks_total
    );
    assert!(
        at_kill.chunks_done < at_kill.chunks_total,
        "the job ended before the kill"
    );

    let end = watch_to_end(&mut on_a, &job.job).await;
    assert_eq!(
        v1::JobState::try_from(end.state),
        Ok(v1::JobState::Done),
        "{end:?}\n{}",
        a.log()
    );
    assert_eq!(
        (end.frames_done, end.chunks_done),
        (FRAMES, end.chunks_total)
    );
    assert!(
        a.metric("crease_cluster_job_redeliveries_total").await >= 1.0,
        "A counted no redelivery:\n{}",
        a.log()
    );

    // Every frame once, in order, each the in-process prediction within the quantisation.
    let got = result(&mut on_a, &job.job).await;
    assert_eq!(
        got.len() as u64,
        FRAMES + 1,
        "the topology, then every frame"
    );
    let Some(v1::mesh_frame::Body::Topology(t)) = &got[0].body else {
        panic!("the result starts with its topology");
    };
    let topology = crease_proto::read_topology(t).unwrap();
    let mut decoder = FrameDecoder::new(topology.vertex_count);
    for (i, m) in got[1..].iter().enumerate() {
        let Some(v1::mesh_frame::Body::Frame(f)) = &m.body else {
            panic!("message {} is not a frame", i + 1);
        };
        assert_eq!(f.seq, i as u64, "frames in order, each once");
        // Every frame decoded (the deltas chain); every 25th compared with the prediction.
        if i % 25 == 0 {
            let want = predicted(&model, &frames[i]);
            check_decoded(&mut decoder, &topology, &f.data, &want);
        } else {
            decoder.decode(&f.data).unwrap();
        }
    }

    // The same job on A alone: the same bytes.
    let alone = submit(&mut on_a, &frames).await;
    let alone_end = watch_to_end(&mut on_a, &alone.job).await;
    assert_eq!(
        v1::JobState::try_from(alone_end.state),
        Ok(v1::JobState::Done)
    );
    let again = result(&mut on_a, &alone.job).await;
    assert_eq!(again.len(), got.len());
    // Byte for byte, but for the server's latency (a measurement, not the stream).
    let stream_of = |m: &v1::MeshFrame| match &m.body {
        Some(v1::mesh_frame::Body::Frame(f)) => (f.seq, f.data.clone(), None),
        other => (0, Default::default(), other.clone()),
    };
    for (i, (x, y)) in got.iter().zip(&again).enumerate() {
        assert!(
            stream_of(x) == stream_of(y),
            "message {i} differs from the single-replica run"
        );
    }

    // A cancel lands within one chunk: at most the chunk running then is stored after it.
    let long = submit(&mut on_a, &frames).await;
    until(Duration::from_secs(60), "the third job began", || async {
        info(&mut a.client().await, &long.job).await.chunks_done >= 1
    })
    .await;
    let ran_before = a.metric("crease_cluster_job_chunks_total").await;
    let cancelled = on_a
        .cancel_job(authed(
            v1::CancelJobRequest {
                job: long.job.clone(),
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        v1::JobState::try_from(cancelled.state),
        Ok(v1::JobState::Cancelled)
    );
    tokio::time::sleep(Duration::from_secs(1)).await;
    let ran_after = a.metric("crease_cluster_job_chunks_total").await;
    assert!(
        ran_after - ran_before <= 1.0,
        "{} chunks ran after the cancel",
        ran_after - ran_before
    );
    let after = info(&mut on_a, &long.job).await;
    assert_eq!(
        after.chunks_done, cancelled.chunks_done,
        "nothing counted after the cancel"
    );
    assert!(after.chunks_done < after.chunks_total);
    assert_eq!(ack_pending(&js).await, 0, "the queue drained");
    let refused = on_a
        .get_job_result(v1::GetJobResultRequest { job: long.job })
        .await
        .unwrap_err();
    assert!(refused.message().contains("cancelled"), "{refused:?}");
}
