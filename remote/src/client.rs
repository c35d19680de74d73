//! Reaching a server: the one gRPC [`connect`] (plain or TLS), a room's description, bearer
//! tokens on requests, and the wire's capture clock.

use std::path::Path;

use anyhow::{Context, bail};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use tonic::transport::Channel;

/// Largest response message the network commands accept (a 16-bit keyframe of a 151K-vertex
/// detail mesh is ~1.2 MB; batches stream one frame per message).
pub const MAX_RESPONSE_BYTES: usize = 256 << 20;

/// How long to wait for a connection before calling the server unreachable.
const CONNECT_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// A gRPC client of the crease server at `server` (`http://` or `https://`). Over https the
/// server's certificate is checked against `ca` (a PEM file, for self-signed or private CAs)
/// or else the Mozilla roots (webpki-roots).
///
/// # Errors
/// A URL that does not parse, an unreadable `ca`, or a server that cannot be reached, each
/// naming what it was.
pub async fn connect(server: &str, ca: Option<&Path>) -> anyhow::Result<CreaseClient<Channel>> {
    use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};
    let mut endpoint = Endpoint::from_shared(server.to_owned())
        .with_context(|| {
            format!("--server {server:?} is not a URL (expected e.g. http://127.0.0.1:50051)")
        })?
        .connect_timeout(CONNECT_TIMEOUT);
    if server.starts_with("https://") {
        let tls = match ca {
            Some(path) => {
                let pem = std::fs::read(path)
                    .with_context(|| format!("reading --ca {}", path.display()))?;
                ClientTlsConfig::new().ca_certificate(Certificate::from_pem(pem))
            }
            None => ClientTlsConfig::new().with_webpki_roots(),
        };
        endpoint = endpoint
            .tls_config(tls)
            .with_context(|| format!("TLS settings for {server}"))?;
    } else if ca.is_some() {
        bail!("--ca applies to https:// servers, got {server}");
    }
    let channel = endpoint
        .connect()
        .await
        .with_context(|| format!("cannot reach the crease server at {server}"))?;
    Ok(CreaseClient::new(channel).max_decoding_message_size(MAX_RESPONSE_BYTES))
}

/// The models the server hosts (`ListModels`).
///
/// # Errors
/// The server's refusal or an unreachable server.
pub async fn list_models(client: &mut CreaseClient<Channel>) -> anyhow::Result<Vec<v1::ModelInfo>> {
    client
        .list_models(v1::ListModelsRequest {})
        .await
        .map(|r| r.into_inner().models)
        .map_err(|s| anyhow::anyhow!("listing the models: {}", s.message()))
}

/// Bytes per `ModelChunk` of an upload (the server takes messages up to 4 MiB).
pub const MODEL_CHUNK_BYTES: usize = 1 << 20;

/// Uploads a model file's `bytes` as model `name` (`UploadModel`, issue 39; admin `token`):
/// the first chunk names it and declares its size and SHA-256 (`sha256`, hex; the file's
/// own unless a caller tests the server's check), then the bytes in chunks of
/// [`MODEL_CHUNK_BYTES`]. Returns the model as the server loaded it.
///
/// # Errors
/// The server's refusal (its message names what was wrong), or an unreachable server.
pub async fn upload_model(
    client: &mut CreaseClient<Channel>,
    token: &str,
    name: &str,
    bytes: Vec<u8>,
    sha256: &str,
) -> anyhow::Result<v1::ModelInfo> {
    let size = bytes.len() as u64;
    let mut chunks: Vec<v1::ModelChunk> = bytes
        .chunks(MODEL_CHUNK_BYTES)
        .map(|c| v1::ModelChunk {
            data: c.to_vec(),
            ..Default::default()
        })
        .collect();
    if chunks.is_empty() {
        chunks.push(v1::ModelChunk::default());
    }
    chunks[0].name = name.to_owned();
    chunks[0].size = size;
    chunks[0].sha256 = sha256.to_owned();
    client
        .upload_model(authorized(tokio_stream::iter(chunks), token)?)
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("uploading model {name:?}: {}", s.message()))
}

/// Deletes model `name` from the server (`DeleteModel`, admin `token`).
///
/// # Errors
/// The server's refusal (in use by a room, no such model), or an unreachable server.
pub async fn delete_model(
    client: &mut CreaseClient<Channel>,
    token: &str,
    name: &str,
) -> anyhow::Result<()> {
    client
        .delete_model(authorized(
            v1::DeleteModelRequest {
                model: name.to_owned(),
            },
            token,
        )?)
        .await
        .map(|_| ())
        .map_err(|s| anyhow::anyhow!("deleting model {name:?}: {}", s.message()))
}

/// The server's models and, in a cluster, the cluster's stored ones (`ListModels`).
///
/// # Errors
/// The server's refusal or an unreachable server.
pub async fn list_all_models(
    client: &mut CreaseClient<Channel>,
) -> anyhow::Result<v1::ListModelsResponse> {
    client
        .list_models(v1::ListModelsRequest {})
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("listing the models: {}", s.message()))
}

/// The server's description of `room` (its model, settings and counters).
///
/// # Errors
/// The server's refusal (no such room), naming the room.
pub async fn get_room(
    client: &mut CreaseClient<Channel>,
    room: &str,
) -> anyhow::Result<v1::RoomInfo> {
    client
        .get_room(v1::GetRoomRequest {
            room: room.to_owned(),
        })
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("room {room:?}: {}", s.message()))
}

/// `msg` with `authorization: Bearer <token>` metadata (admin and publish tokens).
///
/// # Errors
/// A token that is not a valid header value.
pub fn authorized<T>(msg: T, token: &str) -> anyhow::Result<tonic::Request<T>> {
    let mut req = tonic::Request::new(msg);
    req.metadata_mut().insert(
        "authorization",
        bearer(token).context("the token is not a valid header value")?,
    );
    Ok(req)
}

/// The `authorization` header's value for `token` (`Bearer <token>`), for every authorised
/// call: [`authorized`]'s and the publish loop's.
///
/// # Errors
/// When the token holds characters a header cannot carry.
pub fn bearer(
    token: &str,
) -> Result<
    tonic::metadata::MetadataValue<tonic::metadata::Ascii>,
    tonic::metadata::errors::InvalidMetadataValue,
> {
    format!("Bearer {token}").parse()
}

/// Wall clock, microseconds since the Unix epoch (the wire's capture clock).
pub fn unix_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}
