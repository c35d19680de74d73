//! `crease handgen`: a generated hand data set (LYK06 sweep hand, issue 4) — posed meshes at
//! two resolutions, joint angles, control-point layouts, manifests and a contact sheet — and
//! `crease pose`: one posed hand mesh.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_hand::collide::{Ball, CollideOptions};
use crease_hand::dataset::{DatasetProgress, write_dataset_with};
use crease_hand::rig::{HandRig, Layers};
use crease_hand::skeleton::{HandPose, JointLimits, NamedPose};
use crease_hand::surface::Resolution;

use super::common::Progress;

/// Options of `crease handgen`.
#[derive(Clone, Debug, clap::Args)]
pub struct HandgenArgs {
    /// Training poses, the flat rest pose first, then the named poses, then sampled ones.
    #[arg(long, default_value_t = 14)]
    pub train: usize,
    /// Held-out test poses (sampled from a separate stream).
    #[arg(long, default_value_t = 40)]
    pub test: usize,
    /// Seed of the pose sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder (created).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Write only the base resolution (~8K vertices), not the detailed one (>= 150K).
    #[arg(long)]
    pub base_only: bool,
    /// An external rigid ball every pose is pushed out of (LYK06 "Collision detection with
    /// other objects"): `X,Y,Z,R`, centre and radius in metres in the hand frame (the wrist at
    /// the origin, the fingers along +Y, the palm facing -Z; e.g. `0,0.07,-0.045,0.03` sits in
    /// the palm of a grasp).
    #[arg(long, value_name = "X,Y,Z,R", value_parser = parse_ball, allow_hyphen_values = true)]
    pub collide_sphere: Option<Ball>,
}

/// `X,Y,Z,R` of `--collide-sphere`: a finite centre and a finite radius > 0, metres.
pub fn parse_ball(text: &str) -> Result<Ball, String> {
    let v: Vec<f32> = text
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f32>()
                .map_err(|e| format!("{p:?} in {text:?}: {e}"))
        })
        .collect::<Result<_, _>>()?;
    let [x, y, z, r] = v[..] else {
        return Err(format!(
            "{text:?}: expected X,Y,Z,R (4 numbers, metres), got {} numbers",
            v.len()
        ));
    };
    if ![x, y, z, r].iter().all(|c| c.is_finite()) {
        return Err(format!("{text:?}: every number must be finite"));
    }
    if r <= 0.0 {
        return Err(format!("radius R must be > 0 metres, got {r}"));
    }
    Ok(Ball {
        center: Vec3::new(x, y, z),
        radius: r,
    })
}

/// The rig's layers with `ball` as the external object (all layers on, as by default).
fn layers_with(ball: Option<Ball>) -> Layers {
    Layers {
        collide: Some(CollideOptions {
            object: ball,
            ..CollideOptions::default()
        }),
        ..Layers::default()
    }
}

/// Runs `crease handgen`.
pub fn run(args: &HandgenArgs) -> anyhow::Result<()> {
    let start = Instant::now();
    let resolutions: &[Resolution] = if args.base_only {
        &[Resolution::Base]
    } else {
        &[Resolution::Base, Resolution::Detailed]
    };
    // A bar on a terminal (one step per mesh of a resolution), the milestone lines either way.
    let bar = Progress::new((args.train + args.test) as u64);
    let elapsed = || start.elapsed().as_secs_f32();
    let summary = write_dataset_with(
        &args.out,
        args.train,
        args.test,
        args.seed,
        resolutions,
        layers_with(args.collide_sphere),
        |p| match p {
            DatasetProgress::Building(r) => bar.line(
                &format!("{r:?}"),
                Some(0),
                "building",
                &format!("[{:>5.1}s] building the {r:?} hand", elapsed()),
            ),
            DatasetProgress::Wrote {
                resolution,
                done,
                total,
                ..
            } if done == total => bar.line(
                &format!("{resolution:?}"),
                Some(done as u64),
                "written",
                &format!("[{:>5.1}s] wrote {total} {resolution:?} meshes", elapsed()),
            ),
            DatasetProgress::Wrote {
                resolution,
                name,
                done,
                ..
            } => bar.set(&format!("{resolution:?}"), done as u64, name),
            DatasetProgress::Sheet => bar.line(
                "sheet",
                None,
                "rendering",
                &format!("[{:>5.1}s] rendering the contact sheet", elapsed()),
            ),
        },
    );
    bar.finish();
    let summary = summary
        .with_context(|| format!("generating the hand data set in {}", args.out.display()))?;
    for (res, [v, t]) in &summary.resolutions {
        println!("{res}: {v} vertices, {t} triangles");
    }
    println!(
        "{} training + {} test poses in {} ({:.1} s)",
        summary.train.len(),
        summary.test.len(),
        args.out.display(),
        start.elapsed().as_secs_f32()
    );
    println!(
        "train with: crease train --examples {} --out hand.crease",
        args.out.join("train-back.toml").display()
    );
    Ok(())
}

/// Options of `crease pose`.
#[derive(Clone, Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("which").required(true).args(["pose", "angles"])))]
pub struct PoseArgs {
    /// A named pose: flat, relaxed, fist, point, victory, pinch, grasp, spread, thumbs-up, ok.
    #[arg(long)]
    pub pose: Option<NamedPose>,
    /// Joint angles: a JSON object of degree-of-freedom names to radians (as `crease handgen`
    /// writes in poses/); missing ones are 0. Clamped to the joint limits.
    #[arg(long, value_name = "FILE")]
    pub angles: Option<PathBuf>,
    /// Output mesh (.obj, .ply, .gltf or .glb).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Resolution.
    #[arg(long, default_value = "base", value_parser = ["base", "detailed"])]
    pub resolution: String,
    /// An external rigid ball the hand is pushed out of, `X,Y,Z,R` in metres in the hand
    /// frame (as `crease handgen --collide-sphere`).
    #[arg(long, value_name = "X,Y,Z,R", value_parser = parse_ball, allow_hyphen_values = true)]
    pub collide_sphere: Option<Ball>,
}

/// Runs `crease pose`.
pub fn run_pose(args: &PoseArgs) -> anyhow::Result<()> {
    let pose = match (&args.pose, &args.angles) {
        (Some(named), _) => HandPose::named(*named),
        (None, Some(path)) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let map: std::collections::BTreeMap<String, f32> = serde_json::from_str(&text)
                .with_context(|| {
                    format!("{}: expected a JSON object of joint angles", path.display())
                })?;
            let pose =
                HandPose::try_from(map).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            if !pose.is_finite() {
                bail!("{}: a joint angle is not finite", path.display());
            }
            pose.clamp(&JointLimits::adult())
        }
        (None, None) => bail!("give --pose NAME or --angles FILE"),
    };
    let resolution = match args.resolution.as_str() {
        "detailed" => Resolution::Detailed,
        _ => Resolution::Base,
    };
    let rig = HandRig::build(resolution).context("building the hand")?;
    let mesh = rig.posed_mesh(&pose, layers_with(args.collide_sphere));
    mesh.write(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!("{}: {} vertices", args.out.display(), mesh.vertex_count());
    Ok(())
}
