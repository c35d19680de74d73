//! The data-set generator behind `crease handgen`: posed sweep hands at two resolutions,
//! their joint angles, control-point layouts, and manifests `crease train`/`eval` read.
//!
//! # Poses ([`dataset_poses`])
//!
//! Training: the flat hand first (the rest pose, example 0), then the named poses in
//! [`NamedPose::ALL`] order, then poses from the seeded sampler until `train` poses. Test:
//! `test` poses from a sampler seeded differently ([`TEST_STREAM`]), so no test pose is a
//! training pose.
//!
//! # Control-point layouts ([`Layout`])
//!
//! Landmarks are placed on the flat rest skeleton (a point on a bone or on the palm, and a
//! side: dorsal or palmar) and snapped to the rest skin: the vertex facing that side closest
//! to the ray from the point along the side's direction. The three layouts:
//! - `palm` (17): the five fingertip pads, a pad on the middle phalanx of each finger and on
//!   the thumb's proximal phalanx, the base of each finger, thenar, hypothenar and palm centre;
//! - `back` (15): like HZY11's mocap markers, the back of the hand (top, radial and ulnar near
//!   the wrist), each nail, each PIP (thumb: IP) knuckle, and the index and little MCP knuckles;
//! - `glove13`: the 13 hand markers of the Qualisys glove recording in ../shared/data/mocap:
//!   `hand_top` (back of the hand over the middle metacarpal), `hand_left` / `hand_right`
//!   (radial / ulnar, near the wrist), and `<digit>_tip` (nail) and `<digit>_middle`
//!   (middle of the proximal phalanx, dorsal) of each digit. In the recording hand_left and
//!   hand_right sit ~3 cm apart about 5 cm proximal of hand_top, hand_left on the thumb side.
//!
//! # Files ([`write_dataset`])
//!
//! ```text
//! DIR/base/train/NN-NAME.ply, DIR/base/test/NNN-sampled.ply        binary PLY, shared topology
//! DIR/detailed/train/..., DIR/detailed/test/...                    the same poses, >= 150K vertices
//! DIR/poses/train/NN-NAME.json, DIR/poses/test/...                 joint angles (radians, by DOF name)
//! DIR/poses/train/NN-NAME.joints.json, ...                          joint centres (WebXR names, metres)
//! DIR/train-palm.toml, train-back.toml, train-glove13.toml         base training manifests with control_points
//! DIR/test.toml                                                    base test manifest (every mesh evaluated)
//! DIR/detailed/train.toml, DIR/detailed/test.toml                  detailed manifests
//! DIR/handgen.json                                                 summary: poses, layouts (names, vertices per resolution)
//! DIR/contact-sheet.png                                            every base pose, palm and thumb-side views
//! ```

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use serde::Serialize;

use super::palm::Domain;
use super::rig::{HandRig, Layers, RigScratch};
use super::skeleton::{Digit, HandPose, HandSkeleton, NamedPose, PoseSampler};
use super::surface::{Resolution, SurfaceError};
use crate::render::{View, contact_sheet};
use crease_core::mesh::examples::{ExampleSet, NamedMesh};
use crease_core::mesh::ply::{PlyFormat, write_ply};
use crease_core::mesh::{Mesh, MeshError};

/// Views of each pose on the contact sheet.
pub const SHEET_VIEWS: [View; 2] = [View::Palm, View::ThumbSide];
/// Tile size of the contact sheet (pixels).
const SHEET_TILE: u32 = 200;
/// Poses per row of the contact sheet.
const SHEET_COLUMNS: u32 = 6;

/// Xored into the seed for the test poses' sampler.
pub const TEST_STREAM: u64 = 0x7e57_7e57_7e57_7e57;

/// Errors of the generator.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// Building the rest surface failed.
    #[error(transparent)]
    Surface(#[from] SurfaceError),
    /// Writing a mesh failed.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// Writing another file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
    /// Writing the contact sheet failed.
    #[error("{path}: {message}")]
    Sheet {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// Asked for no training pose.
    #[error("--train must be at least 1 (the rest pose)")]
    NoTraining,
}

/// One named pose of the data set.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetPose {
    /// File stem, e.g. `03-fist` or `017-sampled`.
    pub name: String,
    /// The joint angles.
    pub pose: HandPose,
}

/// The training and test poses of a data set (module docs).
pub fn dataset_poses(train: usize, test: usize, seed: u64) -> (Vec<DatasetPose>, Vec<DatasetPose>) {
    let mut sampler = PoseSampler::new(seed);
    let mut train_poses = Vec::with_capacity(train);
    for k in 0..train {
        let (label, pose) = match NamedPose::ALL.get(k) {
            Some(&named) => (named.name().to_owned(), HandPose::named(named)),
            None => ("sampled".to_owned(), sampler.sample()),
        };
        train_poses.push(DatasetPose {
            name: format!("{k:02}-{label}"),
            pose,
        });
    }
    let mut sampler = PoseSampler::new(seed ^ TEST_STREAM);
    let test_poses = (0..test)
        .map(|k| DatasetPose {
            name: format!("{k:03}-sampled"),
            pose: sampler.sample(),
        })
        .collect();
    (train_poses, test_poses)
}

/// The training and test sets of [`dataset_poses`] at the base resolution, in memory: what
/// `train-LAYOUT.toml` and `test.toml` of [`write_dataset`] load (the same meshes, `layout`'s
/// landmarks as the training set's control points, names `train/NN-NAME.ply` and
/// `test/NNN-sampled.ply`), without writing them. `crease eval --hands` runs on these.
///
/// # Errors
/// [`DatasetError::NoTraining`] for `train == 0`; the surface's or the set's errors.
pub fn example_sets(
    train: usize,
    test: usize,
    seed: u64,
    layout: Layout,
) -> Result<(ExampleSet, ExampleSet), DatasetError> {
    if train == 0 {
        return Err(DatasetError::NoTraining);
    }
    let (train_poses, test_poses) = dataset_poses(train, test, seed);
    let rig = HandRig::build(Resolution::Base)?;
    let normals = rig.rest().vertex_normals();
    let controls: Vec<u32> = landmarks(layout, rig.skeleton(), rig.rest(), &normals)
        .iter()
        .map(|l| l.vertex)
        .collect();
    let mut scratch = RigScratch::new();
    let mut meshes = |set: &str, poses: &[DatasetPose]| -> Vec<NamedMesh> {
        poses
            .iter()
            .map(|p| {
                let mut mesh = Mesh {
                    positions: vec![Vec3::ZERO; rig.vertex_count()],
                    triangles: rig.rest().triangles.clone(),
                };
                rig.deform(
                    &p.pose,
                    Layers::default(),
                    &mut scratch,
                    &mut mesh.positions,
                );
                NamedMesh {
                    name: format!("{set}/{}.ply", p.name),
                    mesh,
                }
            })
            .collect()
    };
    let train_set = ExampleSet::new(
        "generated-hand",
        meshes("train", &train_poses),
        Some(controls),
    )?;
    let test_set = ExampleSet::new("generated-hand", meshes("test", &test_poses), None)?;
    Ok((train_set, test_set))
}

/// A control-point layout (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// 17 palmar points.
    Palm,
    /// 15 dorsal points.
    Back,
    /// The 13 markers of the glove recording.
    Glove13,
}

impl Layout {
    /// All layouts.
    pub const ALL: [Layout; 3] = [Layout::Palm, Layout::Back, Layout::Glove13];

    /// The layout named `name` (`palm`, `back`, `glove13`).
    pub fn from_name(name: &str) -> Option<Layout> {
        Layout::ALL.into_iter().find(|l| l.name() == name)
    }

    /// `palm`, `back`, `glove13`.
    pub const fn name(self) -> &'static str {
        match self {
            Layout::Palm => "palm",
            Layout::Back => "back",
            Layout::Glove13 => "glove13",
        }
    }
}

/// Where a landmark sits on the flat rest hand.
#[derive(Clone, Copy, Debug)]
enum Anchor {
    /// Between chain joints `from` and `from + 1` of a digit, at this fraction.
    Bone { digit: Digit, from: usize, at: f32 },
    /// A point of the palm domain `(u, v)` (may extrapolate).
    Palm(Vec2),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Dorsal,
    Palmar,
}

/// The last chain index (the tip) of a digit.
fn tip_chain(digit: Digit) -> usize {
    digit.joints().len() + 1
}

fn landmark_specs(layout: Layout) -> Vec<(String, Anchor, Side)> {
    use Side::{Dorsal, Palmar};
    let bone = |digit, from, at| Anchor::Bone { digit, from, at };
    let palm = |u, v| Anchor::Palm(Vec2::new(u, v));
    // The distal bone runs from chain tip - 1 to the tip.
    let nail = |d: Digit| bone(d, tip_chain(d) - 1, 0.6);
    // Proximal phalanx: from the MCP (chain 2).
    let proximal = |d: Digit, at| bone(d, 2, at);
    let mut out: Vec<(String, Anchor, Side)> = Vec::new();
    match layout {
        Layout::Palm => {
            for d in Digit::ALL {
                out.push((format!("{}_tip_pad", d.name()), nail(d), Palmar));
            }
            for d in Digit::ALL {
                let anchor = if d == Digit::Thumb {
                    proximal(d, 0.5)
                } else {
                    bone(d, 3, 0.5)
                };
                out.push((format!("{}_middle_pad", d.name()), anchor, Palmar));
            }
            for d in Digit::FINGERS {
                out.push((format!("{}_base", d.name()), proximal(d, 0.3), Palmar));
            }
            out.push(("thenar".into(), palm(-0.12, 0.35), Palmar));
            out.push(("hypothenar".into(), palm(0.95, 0.35), Palmar));
            out.push(("palm_centre".into(), palm(0.5, 0.55), Palmar));
        }
        Layout::Back => {
            out.push(("hand_top".into(), palm(0.5, 0.6), Dorsal));
            out.push(("hand_left".into(), palm(0.1, 0.12), Dorsal));
            out.push(("hand_right".into(), palm(0.9, 0.12), Dorsal));
            for d in Digit::ALL {
                out.push((format!("{}_nail", d.name()), nail(d), Dorsal));
            }
            for d in Digit::ALL {
                out.push((format!("{}_knuckle", d.name()), bone(d, 3, 0.0), Dorsal));
            }
            out.push(("index_mcp".into(), bone(Digit::Index, 2, 0.0), Dorsal));
            out.push(("little_mcp".into(), bone(Digit::Little, 2, 0.0), Dorsal));
        }
        Layout::Glove13 => {
            out.push(("hand_top".into(), palm(0.5, 0.6), Dorsal));
            out.push(("hand_left".into(), palm(0.1, 0.12), Dorsal));
            out.push(("hand_right".into(), palm(0.9, 0.12), Dorsal));
            for d in Digit::ALL {
                out.push((format!("{}_tip", d.name()), nail(d), Dorsal));
                out.push((format!("{}_middle", d.name()), proximal(d, 0.5), Dorsal));
            }
        }
    }
    out
}

/// A named control point: a vertex of the rest mesh.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Landmark {
    /// E.g. `hand_top`, `index_tip`.
    pub name: String,
    /// Vertex index in the rest mesh.
    pub vertex: u32,
}

/// The landmarks of `layout` on a rest mesh of `skeleton`'s flat pose (module docs).
pub fn landmarks(
    layout: Layout,
    skeleton: &HandSkeleton,
    rest: &Mesh,
    normals: &[Vec3],
) -> Vec<Landmark> {
    landmark_anchors(layout, skeleton, rest, normals)
        .into_iter()
        .map(|(landmark, _, _)| landmark)
        .collect()
}

/// What a landmark is placed from, for `crate::joint_map`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LandmarkAnchor {
    /// On the bone from chain joint `from` of `digit` to the next.
    Bone { digit: Digit, from: usize },
    /// On the palm.
    Palm,
}

/// [`landmarks`] with each one's anchor and whether it is palmar.
pub(crate) fn landmark_anchors(
    layout: Layout,
    skeleton: &HandSkeleton,
    rest: &Mesh,
    normals: &[Vec3],
) -> Vec<(Landmark, LandmarkAnchor, bool)> {
    let posed = skeleton.pose(&HandPose::FLAT);
    let domain = Domain::of(skeleton);
    landmark_specs(layout)
        .into_iter()
        .map(|(name, anchor, side)| {
            let (point, dorsal, kind) = match anchor {
                Anchor::Bone { digit, from, at } => {
                    let chain = posed.chain(digit);
                    let (a, b) = (chain[from], chain[from + 1]);
                    (
                        a.position.lerp(b.position, at),
                        a.dorsal(),
                        LandmarkAnchor::Bone { digit, from },
                    )
                }
                Anchor::Palm(uv) => (domain.at(uv).extend(0.0), Vec3::Z, LandmarkAnchor::Palm),
            };
            let dir = if side == Side::Dorsal {
                dorsal
            } else {
                -dorsal
            };
            let vertex = snap_to_skin(point, dir, &rest.positions, normals) as u32;
            (Landmark { name, vertex }, kind, side == Side::Palmar)
        })
        .collect()
}

/// The skin vertex over `point` in direction `dir` (unit): among the vertices facing `dir`
/// (normal within ~73 degrees) on that side of `point`, the one closest to the ray. 0 when
/// none qualifies.
pub(crate) fn snap_to_skin(point: Vec3, dir: Vec3, positions: &[Vec3], normals: &[Vec3]) -> usize {
    (0..positions.len())
        .filter(|&i| normals[i].dot(dir) > 0.3 && (positions[i] - point).dot(dir) > 0.0)
        .min_by(|&x, &y| {
            let off = |i: usize| {
                let r = positions[i] - point;
                (r - r.dot(dir) * dir).length_squared()
            };
            off(x).total_cmp(&off(y))
        })
        .unwrap_or(0)
}

/// What [`write_dataset`] wrote.
#[derive(Clone, Debug, Serialize)]
pub struct DatasetSummary {
    /// Seed of the pose sampler.
    pub seed: u64,
    /// Training pose names (file stems), rest first.
    pub train: Vec<String>,
    /// Test pose names.
    pub test: Vec<String>,
    /// Vertex and triangle counts per resolution (`base`, `detailed`).
    pub resolutions: BTreeMap<String, [usize; 2]>,
    /// Landmarks per layout and resolution.
    pub layouts: BTreeMap<String, BTreeMap<String, Vec<Landmark>>>,
    /// The external ball every pose was pushed out of (`crease handgen --collide-sphere`):
    /// centre x, y, z and radius, metres, in the hand frame; absent without one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ball: Option<[f32; 4]>,
}

/// Progress of [`write_dataset`].
#[derive(Clone, Copy, Debug)]
pub enum DatasetProgress<'a> {
    /// Building and binding the rest surface of a resolution.
    Building(Resolution),
    /// Rendering the contact sheet.
    Sheet,
    /// Wrote one posed mesh (`done` of `total` for this resolution).
    Wrote {
        /// Resolution.
        resolution: Resolution,
        /// The file stem.
        name: &'a str,
        /// Meshes written so far for this resolution.
        done: usize,
        /// Meshes to write for this resolution.
        total: usize,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> DatasetError + '_ {
    move |source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn write_text(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(io_err(path))
}

fn resolution_dir(resolution: Resolution) -> &'static str {
    match resolution {
        Resolution::Base => "base",
        Resolution::Detailed => "detailed",
    }
}

/// A posed skeleton's 25 joint centres by their WebXR names (`crate::webxr::JOINT_NAMES`),
/// metres in the hand frame, as JSON: `{"wrist": [x, y, z], ...}`.
fn joints_json(posed: &super::skeleton::PosedSkeleton) -> String {
    use super::webxr::{JOINT_COUNT, JOINT_NAMES, skeleton_frame};
    let joints: BTreeMap<&str, [f32; 3]> = (0..JOINT_COUNT)
        .map(|j| (JOINT_NAMES[j], skeleton_frame(posed, j).position.to_array()))
        .collect();
    serde_json::to_string_pretty(&joints).expect("joints serialise")
}

/// Generates the data set into `dir` (module docs), calling `progress` as it goes, and
/// returns the summary it also writes to `handgen.json`. `resolutions` are the ones to write
/// (`crease handgen` writes both).
pub fn write_dataset(
    dir: &Path,
    train: usize,
    test: usize,
    seed: u64,
    resolutions: &[Resolution],
    progress: impl FnMut(DatasetProgress<'_>),
) -> Result<DatasetSummary, DatasetError> {
    write_dataset_with(
        dir,
        train,
        test,
        seed,
        resolutions,
        Layers::default(),
        progress,
    )
}

/// [`write_dataset`] with the rig's `layers` (e.g. an external ball in
/// [`CollideOptions::object`](crate::collide::CollideOptions::object): every pose is pushed out
/// of it, LYK06 "Collision detection with other objects"). [`write_dataset`] is this with
/// [`Layers::default`].
pub fn write_dataset_with(
    dir: &Path,
    train: usize,
    test: usize,
    seed: u64,
    resolutions: &[Resolution],
    layers: Layers,
    mut progress: impl FnMut(DatasetProgress<'_>),
) -> Result<DatasetSummary, DatasetError> {
    if train == 0 {
        return Err(DatasetError::NoTraining);
    }
    let (train_poses, test_poses) = dataset_poses(train, test, seed);
    let mut summary = DatasetSummary {
        seed,
        train: train_poses.iter().map(|p| p.name.clone()).collect(),
        test: test_poses.iter().map(|p| p.name.clone()).collect(),
        resolutions: BTreeMap::new(),
        layouts: BTreeMap::new(),
        ball: layers
            .collide
            .and_then(|c| c.object)
            .map(|b| [b.center.x, b.center.y, b.center.z, b.radius]),
    };
    for (set, poses) in [("train", &train_poses), ("test", &test_poses)] {
        let folder = dir.join("poses").join(set);
        std::fs::create_dir_all(&folder).map_err(io_err(&folder))?;
        for p in poses.iter() {
            let angles: BTreeMap<String, f32> = p.pose.into();
            let path = folder.join(format!("{}.json", p.name));
            let text = serde_json::to_string_pretty(&angles).expect("angles serialise");
            write_text(&path, &text)?;
        }
    }
    // Base manifests name their detailed twins (read by `ExampleSet::load_detailed`).
    let with_detailed = resolutions.contains(&Resolution::Detailed);
    for &resolution in resolutions {
        progress(DatasetProgress::Building(resolution));
        let rig = HandRig::build(resolution)?;
        let res = resolution_dir(resolution);
        summary.resolutions.insert(
            res.to_owned(),
            [rig.vertex_count(), rig.rest().triangles.len()],
        );
        let normals = rig.rest().vertex_normals();
        for layout in Layout::ALL {
            summary
                .layouts
                .entry(layout.name().to_owned())
                .or_default()
                .insert(
                    res.to_owned(),
                    landmarks(layout, rig.skeleton(), rig.rest(), &normals),
                );
        }
        // The posed skeleton's joint centres, once (the skeleton is the same at every
        // resolution): what a hand tracker would report of each pose (issue 46's test).
        if resolution == resolutions[0] {
            for (set, poses) in [("train", &train_poses), ("test", &test_poses)] {
                for p in poses.iter() {
                    let path = dir
                        .join("poses")
                        .join(set)
                        .join(format!("{}.joints.json", p.name));
                    write_text(&path, &joints_json(&rig.skeleton().pose(&p.pose)))?;
                }
            }
        }
        let total = train_poses.len() + test_poses.len();
        let mut done = 0;
        let mut scratch = RigScratch::new();
        let mut sheet_meshes = Vec::new();
        let mut mesh = Mesh {
            positions: vec![Vec3::ZERO; rig.vertex_count()],
            triangles: rig.rest().triangles.clone(),
        };
        for (set, poses) in [("train", &train_poses), ("test", &test_poses)] {
            let folder = dir.join(res).join(set);
            std::fs::create_dir_all(&folder).map_err(io_err(&folder))?;
            for p in poses.iter() {
                rig.deform(&p.pose, layers, &mut scratch, &mut mesh.positions);
                write_ply(
                    folder.join(format!("{}.ply", p.name)),
                    &mesh,
                    PlyFormat::BinaryLittleEndian,
                )?;
                if resolution == Resolution::Base {
                    sheet_meshes.push((format!("{set} {}", p.name), mesh.clone()));
                }
                done += 1;
                progress(DatasetProgress::Wrote {
                    resolution,
                    name: &p.name,
                    done,
                    total,
                });
            }
        }
        if !sheet_meshes.is_empty() {
            progress(DatasetProgress::Sheet);
            let tiles: Vec<(&str, &Mesh)> =
                sheet_meshes.iter().map(|(n, m)| (n.as_str(), m)).collect();
            let sheet = contact_sheet(&tiles, &SHEET_VIEWS, SHEET_TILE, SHEET_COLUMNS);
            let path = dir.join("contact-sheet.png");
            sheet.write_png(&path).map_err(|e| DatasetError::Sheet {
                path: path.clone(),
                message: e.to_string(),
            })?;
        }
        // Manifests.
        let rest = format!("train/{}.ply", train_poses[0].name);
        let test_rest = test_poses.first().map(|p| format!("test/{}.ply", p.name));
        let ball = summary.ball.map_or(String::new(), |[x, y, z, r]| {
            format!(" --collide-sphere {x},{y},{z},{r}")
        });
        let header = format!(
            "# crease handgen --train {train} --test {test} --seed {seed}{ball}: {res} resolution.\n"
        );
        if resolution == Resolution::Base {
            for layout in Layout::ALL {
                let lms = &summary.layouts[layout.name()][res];
                let mut text = header.clone();
                let _ = writeln!(
                    text,
                    "# control points ({}): {}",
                    layout.name(),
                    lms.iter()
                        .map(|l| l.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                let _ = writeln!(text, "rest = \"base/{rest}\"");
                let _ = writeln!(text, "examples = [\"base/train/*.ply\"]");
                let ids: Vec<String> = lms.iter().map(|l| l.vertex.to_string()).collect();
                let _ = writeln!(text, "control_points = [{}]", ids.join(", "));
                let names: Vec<String> = lms.iter().map(|l| format!("{:?}", l.name)).collect();
                let _ = writeln!(text, "control_point_names = [{}]", names.join(", "));
                if with_detailed {
                    let _ = writeln!(text, "detailed = \"detailed/train.toml\"");
                }
                write_text(&dir.join(format!("train-{}.toml", layout.name())), &text)?;
            }
            if let Some(tr) = &test_rest {
                let mut text = format!(
                    "{header}# Held-out poses: every mesh of this set is evaluated.\nrest = \"base/{tr}\"\nexamples = [\"base/test/*.ply\"]\n"
                );
                if with_detailed {
                    text.push_str("detailed = \"detailed/test.toml\"\n");
                }
                write_text(&dir.join("test.toml"), &text)?;
            }
        } else {
            let text = format!("{header}rest = \"{rest}\"\nexamples = [\"train/*.ply\"]\n");
            write_text(&dir.join(res).join("train.toml"), &text)?;
            if let Some(tr) = &test_rest {
                let text = format!("{header}rest = \"{tr}\"\nexamples = [\"test/*.ply\"]\n");
                write_text(&dir.join(res).join("test.toml"), &text)?;
            }
        }
    }
    let path = dir.join("handgen.json");
    write_text(
        &path,
        &serde_json::to_string_pretty(&summary).expect("summary serialises"),
    )?;
    Ok(summary)
}
