//! Compiles `crease/v1/crease.proto` (and the replicas' `cluster.proto`) without a system `protoc`: protox parses it into a
//! descriptor set, tonic-prost-build generates the messages and the service from that, and the
//! encoded set is kept in `OUT_DIR` for gRPC server reflection.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=crease");
    let fds = protox::compile(
        [
            "crease/v1/crease.proto",
            "crease/v1/cluster.proto",
            "crease/v1/take.proto",
        ],
        ["."],
    )?;
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(
        out.join("crease_descriptor.bin"),
        prost::Message::encode_to_vec(&fds),
    )?;
    tonic_prost_build::configure()
        // Encoded mesh frames are made once per room and sent to every subscriber: as `Bytes`
        // each message shares them instead of copying.
        .bytes(".crease.v1.Frame.data")
        .bytes(".crease.v1.ActorFrame.data")
        // A palette header (~1 MB at the detail level) is made once per model and level.
        .bytes(".crease.v1.PaletteTopology")
        .build_client(true)
        .build_server(true)
        .compile_fds(fds)?;
    Ok(())
}
