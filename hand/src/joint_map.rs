//! WebXR joint maps (issue 19): a tracked hand's joints as mocap markers, and the marker map
//! (`crease_mocap::map`) that puts a control-point layout's landmarks on them.
//!
//! # The markers
//!
//! A WebXR runtime reports, per joint, a pose (its centre; `-Z` along the bone, `+Y` out of the
//! back of the hand) and a radius. The viewer (`web/xr.js`) publishes three points per joint
//! ([`capture_markers`]): the centre under the joint's name, the centre plus the radius along
//! `+Y` (`<joint>/dorsal`, on the skin over the joint, where a glove's marker would sit) and
//! minus it (`<joint>/palmar`). The landmarks of [`Layout`] are skin points too, dorsal or
//! palmar, so a map mixes the points of the same side.
//!
//! # Fitting the mixes ([`fit_joint_map`])
//!
//! The same three points exist on the sweep hand ([`virtual_markers`]): the joint centres of
//! the posed skeleton, and the skin vertex where the ray from each along its dorsal (palmar)
//! axis first meets the skin. Each landmark's
//! source is an affine mix (weights summing to 1) of the same-side points of a few candidate
//! joints, fitted by least squares over posed hands (the data set's training poses) with a
//! small ridge:
//! - a landmark on a bone (`dataset`'s `Anchor::Bone`, between chain joints `from` and
//!   `from + 1`): those two joints (the wrist when `from` is 0);
//! - a landmark on the palm: the metacarpal and MCP (`*-phalanx-proximal`) joints of the four
//!   fingers, and the wrist.
//!
//! The mixes are written in the landmarks' own frame (centred on the candidates' mean before
//! fitting, so the ridge does not depend on where the hand is). Measured by the tests on the
//! data set's sampled test poses, which no fit saw; the hand-written first version of
//! `bench/mocap/webxr-back.toml` (weights read off the anchors) put the palm landmarks 2-3 cm
//! off on iwer's hand, which is why the weights are fitted.

use std::fmt::Write as _;

use glam::{DVec3, Vec3};

use super::dataset::{LandmarkAnchor, Layout, landmark_anchors, snap_to_skin};
use super::skeleton::{Digit, HandPose, PosedSkeleton};
use super::webxr::{JOINT_COUNT, JOINT_NAMES, skeleton_frame, webxr_index};
use crate::rig::{HandRig, Layers, RigScratch};

/// The suffix of a joint's dorsal point (module docs).
pub const DORSAL_SUFFIX: &str = "/dorsal";
/// The suffix of a joint's palmar point.
pub const PALMAR_SUFFIX: &str = "/palmar";
/// Markers per joint: centre, dorsal, palmar.
pub const MARKERS_PER_JOINT: usize = 3;
/// Ridge of the fit, relative to the mean squared spread of the candidates.
const RIDGE: f64 = 1e-3;
/// Weights are written to this many decimals.
const DECIMALS: i32 = 3;

/// The markers of a WebXR capture, in frame order: the [`JOINT_NAMES`], then each with
/// [`DORSAL_SUFFIX`], then each with [`PALMAR_SUFFIX`] (75 in all).
pub fn capture_markers() -> Vec<String> {
    let names = |suffix: &'static str| JOINT_NAMES.iter().map(move |n| format!("{n}{suffix}"));
    names("")
        .chain(names(DORSAL_SUFFIX))
        .chain(names(PALMAR_SUFFIX))
        .collect()
}

/// Which of a joint's three points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The centre.
    Centre,
    /// On the back of the hand.
    Dorsal,
    /// On the palm side.
    Palmar,
}

impl Side {
    /// Marker index of joint `j`'s point on this side in [`capture_markers`].
    pub const fn marker(self, j: usize) -> usize {
        match self {
            Side::Centre => j,
            Side::Dorsal => JOINT_COUNT + j,
            Side::Palmar => 2 * JOINT_COUNT + j,
        }
    }
}

/// The sweep hand's [`capture_markers`] in one pose: the posed skeleton's joint centres and the
/// skin vertices of `mesh` (the posed hand, `normals` its vertex normals) over them.
pub fn virtual_markers(posed: &PosedSkeleton, mesh: &[Vec3], normals: &[Vec3]) -> Vec<Vec3> {
    let mut out = vec![Vec3::ZERO; MARKERS_PER_JOINT * JOINT_COUNT];
    for j in 0..JOINT_COUNT {
        let frame = skeleton_frame(posed, j);
        let dorsal = frame.dorsal();
        out[Side::Centre.marker(j)] = frame.position;
        out[Side::Dorsal.marker(j)] = first_skin(frame.position, dorsal, mesh, normals);
        out[Side::Palmar.marker(j)] = first_skin(frame.position, -dorsal, mesh, normals);
    }
    out
}

/// Where the ray from `point` along `dir` (unit) first meets the skin: of the vertices facing
/// `dir` within [`RAY_RADIUS`] of the ray, the nearest along it (what a runtime's joint radius
/// measures: the skin right over the joint, never a neighbouring finger further along the ray
/// in a curled pose). The landmarks' own rule (`snap_to_skin`, closest to the ray) when no
/// vertex is that close.
fn first_skin(point: Vec3, dir: Vec3, mesh: &[Vec3], normals: &[Vec3]) -> Vec3 {
    let hit = (0..mesh.len())
        .filter_map(|i| {
            let r = mesh[i] - point;
            let t = r.dot(dir);
            (t > 0.0 && normals[i].dot(dir) > 0.3 && (r - t * dir).length() < RAY_RADIUS)
                .then_some((i, t))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1));
    match hit {
        Some((i, _)) => mesh[i],
        None => mesh[snap_to_skin(point, dir, mesh, normals)],
    }
}

/// How near the ray a vertex must lie to count as its hit (metres; the base hand's edges are
/// ~2-3 mm).
const RAY_RADIUS: f32 = 0.003;

/// One landmark's source: `(marker index, weight)` terms summing to 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Mix {
    /// The landmark (control point) name.
    pub name: String,
    /// The rest-mesh vertex it sits on.
    pub vertex: u32,
    /// Terms, marker indices into [`capture_markers`].
    pub terms: Vec<(usize, f32)>,
}

impl Mix {
    /// The mixed point of `markers`.
    pub fn apply(&self, markers: &[Vec3]) -> Vec3 {
        self.terms.iter().map(|&(m, w)| w * markers[m]).sum()
    }
}

/// The posed hands a map is fitted or checked on: per pose the virtual markers and the posed
/// mesh.
#[derive(Clone, Debug)]
pub struct PosedHands {
    /// Per pose, [`virtual_markers`].
    pub markers: Vec<Vec<Vec3>>,
    /// Per pose, the posed mesh's vertices.
    pub meshes: Vec<Vec<Vec3>>,
}

impl PosedHands {
    /// Poses `rig` in each of `poses` (base layers).
    pub fn new(rig: &HandRig, poses: &[HandPose]) -> PosedHands {
        let mut scratch = RigScratch::new();
        let triangles = &rig.rest().triangles;
        let (mut markers, mut meshes) = (Vec::new(), Vec::new());
        for pose in poses {
            let mut out = vec![Vec3::ZERO; rig.vertex_count()];
            rig.deform(pose, Layers::default(), &mut scratch, &mut out);
            let mesh = crease_core::mesh::Mesh {
                positions: out,
                triangles: triangles.clone(),
            };
            let normals = mesh.vertex_normals();
            markers.push(virtual_markers(
                &rig.skeleton().pose(pose),
                &mesh.positions,
                &normals,
            ));
            meshes.push(mesh.positions);
        }
        PosedHands { markers, meshes }
    }
}

/// The candidate joints of a landmark (module docs).
fn candidates(anchor: LandmarkAnchor) -> Vec<usize> {
    let joint = |d: Digit, chain: usize| if chain == 0 { 0 } else { webxr_index(d, chain) };
    match anchor {
        LandmarkAnchor::Bone { digit, from } => vec![joint(digit, from), joint(digit, from + 1)],
        LandmarkAnchor::Palm => {
            let mut c = vec![0];
            for d in Digit::FINGERS {
                c.push(webxr_index(d, 1));
                c.push(webxr_index(d, 2));
            }
            c
        }
    }
}

/// Least-squares affine weights (summing to 1) of `columns` (per sample, the candidate points)
/// reproducing `targets`, with a ridge (module docs). Solved as the KKT system of the
/// constrained problem by Gaussian elimination with partial pivoting, in f64.
fn fit_weights(columns: &[Vec<DVec3>], targets: &[DVec3]) -> Vec<f64> {
    let k = columns[0].len();
    let mut a = vec![vec![0.0f64; k + 1]; k + 1];
    let mut rhs = vec![0.0f64; k + 1];
    let mut spread = 0.0;
    for (cols, t) in columns.iter().zip(targets) {
        let mean = cols.iter().copied().sum::<DVec3>() / k as f64;
        for i in 0..k {
            let ci = cols[i] - mean;
            spread += ci.length_squared();
            rhs[i] += ci.dot(*t - mean);
            for j in 0..k {
                a[i][j] += ci.dot(cols[j] - mean);
            }
        }
    }
    let ridge = RIDGE * spread / k as f64;
    for (i, row) in a.iter_mut().enumerate().take(k) {
        row[i] += ridge;
        row[k] = 1.0;
    }
    a[k][..k].fill(1.0);
    rhs[k] = 1.0;
    // Gaussian elimination on [a | rhs].
    let n = k + 1;
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))
            .unwrap_or(col);
        a.swap(col, pivot);
        rhs.swap(col, pivot);
        let (top, below) = a.split_at_mut(col + 1);
        let pivot_row = &top[col];
        for (k, row) in below.iter_mut().enumerate() {
            let f = row[col] / pivot_row[col];
            for (x, p) in row[col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            rhs[col + 1 + k] -= f * rhs[col];
        }
    }
    let mut x = vec![0.0f64; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|c| a[row][c] * x[c]).sum();
        x[row] = (rhs[row] - s) / a[row][row];
    }
    x.truncate(k);
    x
}

/// Weights rounded to [`DECIMALS`], the rounding's remainder given to the largest, terms that
/// round to zero dropped.
fn rounded(terms: Vec<(usize, f64)>) -> Vec<(usize, f32)> {
    let scale = 10f64.powi(DECIMALS);
    let mut out: Vec<(usize, f64)> = terms
        .into_iter()
        .map(|(m, w)| (m, (w * scale).round() / scale))
        .filter(|t| t.1 != 0.0)
        .collect();
    let rest = 1.0 - out.iter().map(|t| t.1).sum::<f64>();
    if let Some(big) = out
        .iter_mut()
        .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
    {
        big.1 = ((big.1 + rest) * scale).round() / scale;
    }
    out.into_iter().map(|(m, w)| (m, w as f32)).collect()
}

/// The mixes of `layout`'s landmarks (on `rig`'s rest mesh) fitted over `hands` (module docs).
pub fn fit_joint_map(layout: Layout, rig: &HandRig, hands: &PosedHands) -> Vec<Mix> {
    fit_mixes(
        layout,
        rig,
        &hands.markers,
        &hands.meshes,
        |anchor, palmar| {
            let side = if palmar { Side::Palmar } else { Side::Dorsal };
            candidates(anchor)
                .into_iter()
                .map(|j| side.marker(j))
                .collect()
        },
    )
}

/// The mixes of `layout`'s landmarks over a capture's markers: per pose `markers` (that
/// capture's, in its order) and the posed mesh `meshes`; `candidates(anchor, palmar)` the
/// markers a landmark may mix (module docs). Shared by the WebXR and the VMC maps.
pub(crate) fn fit_mixes(
    layout: Layout,
    rig: &HandRig,
    markers: &[Vec<Vec3>],
    meshes: &[Vec<Vec3>],
    candidates: impl Fn(LandmarkAnchor, bool) -> Vec<usize>,
) -> Vec<Mix> {
    let normals = rig.rest().vertex_normals();
    landmark_anchors(layout, rig.skeleton(), rig.rest(), &normals)
        .into_iter()
        .map(|(landmark, anchor, palmar)| {
            let picked = candidates(anchor, palmar);
            let columns: Vec<Vec<DVec3>> = markers
                .iter()
                .map(|m| picked.iter().map(|&i| m[i].as_dvec3()).collect())
                .collect();
            let targets: Vec<DVec3> = meshes
                .iter()
                .map(|mesh| mesh[landmark.vertex as usize].as_dvec3())
                .collect();
            let w = fit_weights(&columns, &targets);
            Mix {
                name: landmark.name,
                vertex: landmark.vertex,
                terms: rounded(picked.into_iter().zip(w).collect()),
            }
        })
        .collect()
}

/// Distances of each mix to its landmark vertex, per pose of `hands`: `[pose][landmark]`.
pub fn mix_errors(mixes: &[Mix], hands: &PosedHands) -> Vec<Vec<f32>> {
    errors_over(mixes, &hands.markers, &hands.meshes)
}

/// Distances of each mix of a capture's `markers` (per pose) to its landmark vertex of the
/// posed `meshes`: `[pose][landmark]`.
pub(crate) fn errors_over(
    mixes: &[Mix],
    markers: &[Vec<Vec3>],
    meshes: &[Vec<Vec3>],
) -> Vec<Vec<f32>> {
    markers
        .iter()
        .zip(meshes)
        .map(|(markers, mesh)| {
            mixes
                .iter()
                .map(|m| m.apply(markers).distance(mesh[m.vertex as usize]))
                .collect()
        })
        .collect()
}

/// The marker map (TOML, `crease_mocap::map`) of `mixes`: the registration on `registration`
/// (landmark names, at least three), its scale fitted over `calibration_frames`, and a header
/// of `comment` lines.
pub fn joint_map_toml(
    mixes: &[Mix],
    registration: &[&str],
    calibration_frames: usize,
    comment: &str,
) -> String {
    map_toml(
        mixes,
        &capture_markers(),
        registration,
        calibration_frames,
        &[],
        comment,
    )
}

/// [`joint_map_toml`] for mixes whose terms index `names` (another capture's markers:
/// `crate::vmc_map`'s), with `bones` (`(marker, parent, length)`, indices into `names`; the
/// map's `[bones]`, `crease_mocap::map`) when the capture's joints are estimated. A map with
/// bones registers at scale 1 (the rebuilt hand is the fitted one's size) instead of fitting
/// the scale over `calibration_frames`.
pub fn map_toml(
    mixes: &[Mix],
    names: &[String],
    registration: &[&str],
    calibration_frames: usize,
    bones: &[(usize, usize, f32)],
    comment: &str,
) -> String {
    let mut s = String::new();
    for line in comment.lines() {
        let _ = writeln!(s, "{}", format!("# {line}").trim_end());
    }
    let points: Vec<String> = registration.iter().map(|p| format!("{p:?}")).collect();
    // A skeleton rebuilt on the fitted hand's bones has the fitted hand's size: scale 1.
    let scale = if bones.is_empty() {
        format!("calibration_frames = {calibration_frames}")
    } else {
        "scale = 1.0".to_owned()
    };
    let _ = writeln!(
        s,
        "\n[registration]\npoints = [{}]\n{scale}\n\n[markers]",
        points.join(", ")
    );
    for m in mixes {
        let terms: Vec<String> = m
            .terms
            .iter()
            .map(|&(i, w)| format!("{:?} = {w}", names[i]))
            .collect();
        let _ = writeln!(s, "{} = {{ {} }}", m.name, terms.join(", "));
    }
    s.push_str("\n[gaps]\nfill = \"neighbour\"\n");
    if !bones.is_empty() {
        s.push_str("\n[bones]\n");
        for &(m, parent, length) in bones {
            let _ = writeln!(
                s,
                "{} = {{ parent = {:?}, length = {length:.4} }}",
                names[m], names[parent]
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_recovers_an_exact_affine_mix_and_rounds_to_a_unit_sum() {
        // Samples whose target is exactly 0.7 a + 0.5 b - 0.2 c of three moving candidates.
        let want = [0.7, 0.5, -0.2];
        let (mut columns, mut targets) = (Vec::new(), Vec::new());
        for s in 0..20 {
            let t = s as f64 * 0.37;
            let cols = vec![
                DVec3::new(t.sin(), 0.3 * t, 1.0),
                DVec3::new(2.0 + t.cos(), -t.sin(), 0.5 * t.cos()),
                DVec3::new(0.2 * t, 1.0 + (2.0 * t).sin(), -1.0),
            ];
            targets.push(cols.iter().zip(want).map(|(c, w)| *c * w).sum());
            columns.push(cols);
        }
        let w = fit_weights(&columns, &targets);
        for (got, want) in w.iter().zip(want) {
            assert!((got - want).abs() < 5e-3, "{w:?}");
        }
        let r = rounded(vec![(0, 0.3334), (1, 0.3333), (2, 0.3333), (3, 0.0001)]);
        assert_eq!(r.len(), 3, "the zero term is dropped: {r:?}");
        let sum: f32 = r.iter().map(|t| t.1).sum();
        assert!((sum - 1.0).abs() < 1e-6, "{r:?}");
    }
}
