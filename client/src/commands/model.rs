//! `crease model`: operations on a trained model file. `mirror` writes the model reflected
//! across a plane through the origin (`crease_core::model::mirror`): a left hand from a
//! right-hand model, with its winding, normals, palette and control-point names following.
//! `upload`, `delete` and `list` manage a running server's models (issue 39: `UploadModel`,
//! `DeleteModel`, `ListModels`; the server's `model_api` says what each checks).

use std::path::PathBuf;

use anyhow::Context;
use crease_core::model::{MirrorPlane, TrainedModel};

/// `crease model`'s operations.
#[derive(Debug, clap::Args)]
pub struct ModelArgs {
    /// The operation.
    #[command(subcommand)]
    pub command: ModelCommand,
}

/// What `crease model` does.
#[derive(Debug, clap::Subcommand)]
pub enum ModelCommand {
    /// Mirror a model across a plane through the origin (a left hand from a right-hand model):
    /// its prediction for mirrored control points is the mirror of the original's.
    Mirror(MirrorArgs),
    /// Upload a model file to a running server (admin token): checked there (size, SHA-256,
    /// format), written into its models folder, ready for rooms at once; in a cluster,
    /// offered to every replica.
    Upload(UploadArgs),
    /// Delete a model from a running server's folder (admin token); refused while a room
    /// uses it.
    Delete(DeleteArgs),
    /// List a running server's models (and, in a cluster, the cluster's).
    List(ListArgs),
}

/// `crease model upload`'s arguments.
#[derive(Debug, clap::Args)]
pub struct UploadArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: super::common::ServerArgs,
    /// The server's admin token.
    #[command(flatten)]
    pub admin: super::room::AdminArgs,
    /// The model file (`crease train --out`).
    pub model: PathBuf,
    /// Its name on the server (rooms name it): 1-64 characters of A-Z, a-z, 0-9, _ and -.
    /// Default: the file's stem.
    #[arg(long)]
    pub name: Option<String>,
}

/// `crease model delete`'s arguments.
#[derive(Debug, clap::Args)]
pub struct DeleteArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: super::common::ServerArgs,
    /// The server's admin token.
    #[command(flatten)]
    pub admin: super::room::AdminArgs,
    /// The model's name on the server.
    pub name: String,
}

/// `crease model list`'s arguments.
#[derive(Debug, clap::Args)]
pub struct ListArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: super::common::ServerArgs,
}

/// `crease model mirror`'s arguments.
#[derive(Debug, clap::Args)]
pub struct MirrorArgs {
    /// The model to mirror (`crease train`'s output).
    pub model: PathBuf,
    /// The mirror plane: the axis it is normal to (`x` is the plane x = 0) or a normal
    /// `nx,ny,nz`; it passes through the origin.
    #[arg(long, default_value = "x", value_name = "PLANE")]
    pub plane: MirrorPlane,
    /// Where to write the mirrored model.
    #[arg(long, short)]
    pub out: PathBuf,
}

/// Runs `crease model`.
///
/// # Errors
/// An unreadable or invalid model, or an unwritable output, naming the file.
pub fn run(args: &ModelArgs) -> anyhow::Result<()> {
    match &args.command {
        ModelCommand::Mirror(m) => mirror(m),
        ModelCommand::Upload(a) => on_server(upload(a)),
        ModelCommand::Delete(a) => on_server(delete(a)),
        ModelCommand::List(a) => on_server(list(a)),
    }
}

/// Runs one server call on a current-thread runtime.
fn on_server(call: impl std::future::Future<Output = anyhow::Result<()>>) -> anyhow::Result<()> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?
        .block_on(call)
}

async fn upload(args: &UploadArgs) -> anyhow::Result<()> {
    let bytes = std::fs::read(&args.model)
        .with_context(|| format!("reading the model {}", args.model.display()))?;
    // Checked here first: a file that is not a model is named before it travels.
    TrainedModel::from_bytes(&bytes)
        .with_context(|| format!("{} is not a crease model", args.model.display()))?;
    let name = match &args.name {
        Some(n) => n.clone(),
        None => args
            .model
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
    };
    let sha256 = {
        use sha2::Digest;
        sha2::Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    };
    let size = bytes.len();
    let mut client = args.server.connect().await?;
    let info = crease_remote::client::upload_model(
        &mut client,
        &args.admin.admin_token,
        &name,
        bytes,
        &sha256,
    )
    .await?;
    eprintln!(
        "uploaded model {:?} ({size} bytes, SHA-256 {sha256}): {} vertices, {} control points, {} bones",
        info.name,
        info.base_vertices,
        info.control_points.len(),
        info.bones
    );
    Ok(())
}

async fn delete(args: &DeleteArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    crease_remote::client::delete_model(&mut client, &args.admin.admin_token, &args.name).await?;
    eprintln!("deleted model {:?}", args.name);
    Ok(())
}

async fn list(args: &ListArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let all = crease_remote::client::list_all_models(&mut client).await?;
    for m in &all.models {
        println!(
            "{}\t{} vertices\t{} control points\t{}",
            m.name,
            m.base_vertices,
            m.control_points.len(),
            if m.detail_vertices > 0 {
                "detail"
            } else {
                "base only"
            }
        );
    }
    for m in &all.cluster {
        let here = all.models.iter().any(|l| l.name == m.name);
        println!(
            "{}\tin the cluster's store\t{} bytes\tSHA-256 {}{}",
            m.name,
            m.bytes,
            m.sha256,
            if here { "" } else { "\t(not loaded here)" }
        );
    }
    Ok(())
}

fn mirror(args: &MirrorArgs) -> anyhow::Result<()> {
    let model = TrainedModel::load(&args.model)
        .with_context(|| format!("reading the model {}", args.model.display()))?;
    let mirrored = model
        .mirrored(&args.plane)
        .with_context(|| format!("mirroring {}", args.model.display()))?;
    mirrored
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let renamed = (model.controls.iter().zip(&mirrored.controls))
        .filter(|(a, b)| a.name != b.name)
        .count();
    println!(
        "wrote {} ({} vertices, {} bones, {} control points, {renamed} renamed{}) mirrored \
         across the plane through the origin normal to {}",
        args.out.display(),
        mirrored.rig.rest.vertex_count(),
        mirrored.rig.bone_count,
        mirrored.controls.len(),
        if mirrored.detail.is_some() {
            ", detail layer"
        } else {
            ""
        },
        args.plane.normal()
    );
    Ok(())
}
