//! `crease model`: operations on a trained model file. `mirror` writes the model reflected
//! across a plane through the origin (`crease_core::model::mirror`): a left hand from a
//! right-hand model, with its winding, normals, palette and control-point names following.

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
    }
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
