//! TLS: with a certificate and key, gRPC and HTTP are served over rustls. A client that trusts
//! the certificate lists the models and reads `/healthz` over HTTPS; a plaintext client is
//! refused; shutdown still drains.

use std::sync::Arc;

use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_server::registry::ModelRegistry;
use crease_server::{AppState, Config, TlsFiles};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// A self-signed certificate for `localhost`, written with its key as PEM files in `dir`.
fn self_signed(
    dir: &std::path::Path,
) -> (rcgen::Certificate, std::path::PathBuf, std::path::PathBuf) {
    let key = rcgen::KeyPair::generate().unwrap();
    let cert = rcgen::CertificateParams::new(vec!["localhost".to_owned()])
        .unwrap()
        .self_signed(&key)
        .unwrap();
    let (cert_path, key_path) = (dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&cert_path, cert.pem()).unwrap();
    std::fs::write(&key_path, key.serialize_pem()).unwrap();
    (cert, cert_path, key_path)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grpc_and_https_over_tls() {
    let dir = tempfile::tempdir().unwrap();
    let (cert, cert_path, key_path) = self_signed(dir.path());

    // A missing key file is an error naming it.
    let bad = Config {
        grpc: "127.0.0.1:0".parse().unwrap(),
        http: "127.0.0.1:0".parse().unwrap(),
        tls: Some(TlsFiles {
            cert: cert_path.clone(),
            key: dir.path().join("missing.pem"),
        }),
        ..Config::default()
    };
    let err = crease_server::serve(AppState::new(ModelRegistry::default(), bad))
        .await
        .unwrap_err();
    assert!(err.to_string().contains("missing.pem"), "{err}");

    let state = AppState::new(
        ModelRegistry::default(),
        Config {
            grpc: "127.0.0.1:0".parse().unwrap(),
            http: "127.0.0.1:0".parse().unwrap(),
            tls: Some(TlsFiles {
                cert: cert_path,
                key: key_path,
            }),
            ..Config::default()
        },
    );
    let running = crease_server::serve(Arc::clone(&state)).await.unwrap();

    // gRPC over TLS, trusting the self-signed certificate.
    let tls = tonic::transport::ClientTlsConfig::new()
        .ca_certificate(tonic::transport::Certificate::from_pem(cert.pem()))
        .domain_name("localhost");
    let channel = tonic::transport::Channel::from_shared(format!(
        "https://localhost:{}",
        running.grpc.port()
    ))
    .unwrap()
    .tls_config(tls)
    .unwrap()
    .connect()
    .await
    .unwrap();
    let models = CreaseClient::new(channel)
        .list_models(v1::ListModelsRequest {})
        .await
        .unwrap()
        .into_inner();
    assert!(models.models.is_empty());

    // A plaintext gRPC client gets nowhere.
    let plain = async {
        let mut c = CreaseClient::connect(format!("http://{}", running.grpc)).await?;
        c.list_models(v1::ListModelsRequest {})
            .await
            .map_err(|e| Box::new(e) as Box<dyn std::error::Error>)?;
        Ok::<_, Box<dyn std::error::Error>>(())
    };
    let plain = tokio::time::timeout(std::time::Duration::from_secs(5), plain).await;
    assert!(
        !matches!(plain, Ok(Ok(()))),
        "a plaintext call succeeded on the TLS port"
    );

    // HTTPS /healthz with rustls, trusting the certificate.
    let _ = rustls::crypto::ring::default_provider().install_default();
    let mut roots = rustls::RootCertStore::empty();
    roots.add(cert.der().clone()).unwrap();
    let config = rustls::ClientConfig::builder()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(running.http).await.unwrap();
    let name = rustls::pki_types::ServerName::try_from("localhost").unwrap();
    let mut stream = connector.connect(name, tcp).await.unwrap();
    stream
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut text = String::new();
    let _ = stream.read_to_string(&mut text).await;
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    assert!(text.ends_with("ok\n"), "{text}");

    // Plain HTTP on the TLS port is not served.
    let mut tcp = tokio::net::TcpStream::connect(running.http).await.unwrap();
    tcp.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut buf = Vec::new();
    let _ =
        tokio::time::timeout(std::time::Duration::from_secs(5), tcp.read_to_end(&mut buf)).await;
    assert!(
        !String::from_utf8_lossy(&buf).starts_with("HTTP/1.1 200"),
        "plain HTTP answered on the TLS port"
    );

    let t = std::time::Instant::now();
    running
        .shutdown(std::time::Duration::from_secs(5))
        .await
        .unwrap();
    assert!(
        t.elapsed().as_secs_f32() < 6.0,
        "drained in {:?}",
        t.elapsed()
    );
}

/// One TLS connection to `addr` trusting `cert` (DER), or the handshake's error.
async fn tls_connect(
    addr: std::net::SocketAddr,
    cert: &rustls::pki_types::CertificateDer<'static>,
) -> std::io::Result<tokio_rustls::client::TlsStream<tokio::net::TcpStream>> {
    let _ = rustls::crypto::ring::default_provider().install_default();
    let mut roots = rustls::RootCertStore::empty();
    roots.add(cert.clone()).unwrap();
    let config = rustls::ClientConfig::builder()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(addr).await?;
    let name = rustls::pki_types::ServerName::try_from("localhost").unwrap();
    tokio::time::timeout(
        std::time::Duration::from_secs(5),
        connector.connect(name, tcp),
    )
    .await
    .map_err(|_| std::io::Error::other("handshake timed out"))?
}

/// `GET path` over `stream` (keep-alive), the whole response as text.
async fn https_get(
    stream: &mut tokio_rustls::client::TlsStream<tokio::net::TcpStream>,
    path: &str,
) -> String {
    stream
        .write_all(
            format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
                .as_bytes(),
        )
        .await
        .unwrap();
    let mut text = String::new();
    let _ = stream.read_to_string(&mut text).await;
    text
}

/// The connection caps hold for HTTPS too (issue 40): axum-server accepts TLS connections
/// itself, so they are admitted before the handshake. An address over its cap is closed
/// without a handshake while its first connections stay served; one slot freed, it connects.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn https_connections_are_capped_per_address_before_the_handshake() {
    use crease_server::Limits;
    use crease_server::admission::Caps;
    let dir = tempfile::tempdir().unwrap();
    let (cert, cert_path, key_path) = self_signed(dir.path());
    let state = AppState::new(
        ModelRegistry::default(),
        Config {
            grpc: "127.0.0.1:0".parse().unwrap(),
            http: "127.0.0.1:0".parse().unwrap(),
            tls: Some(TlsFiles {
                cert: cert_path,
                key: key_path,
            }),
            limits: Limits {
                connections: Caps {
                    per_address: 2,
                    total: 100,
                },
                ..Limits::default()
            },
            ..Config::default()
        },
    );
    let running = crease_server::serve(Arc::clone(&state)).await.unwrap();
    let der = cert.der().clone();
    let first = tls_connect(running.http, &der).await.unwrap();
    let mut second = tls_connect(running.http, &der).await.unwrap();
    // The third from the same address: closed before any handshake.
    let third = tls_connect(running.http, &der).await;
    assert!(third.is_err(), "a third HTTPS connection was admitted");
    // The admitted ones are served.
    let text = https_get(&mut second, "/healthz").await;
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    drop(second);
    drop(first);
    // Slots given back: a new connection is served and the refusal was counted.
    let mut text = String::new();
    for _ in 0..50 {
        if let Ok(mut s) = tls_connect(running.http, &der).await {
            text = https_get(&mut s, "/metrics").await;
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let refused: f64 = text
        .lines()
        .find(|l| l.starts_with("crease_admission_refused_total{kind=\"connections\"}"))
        .unwrap_or_else(|| panic!("no connection refusals in /metrics:\n{text}"))
        .rsplit(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(refused >= 1.0, "{refused}");
    running
        .shutdown(std::time::Duration::from_secs(5))
        .await
        .unwrap();
}
