//! Self-intersections and collisions of the sweep hand (LYK06 "Handling self-intersections and
//! collisions"): the folds at the interphalangeal joints, contacts among digits and palm, and
//! contacts with an external ball, all on a simple approximation of the hand by spheres and
//! planes that deforms with the sweeps.
//!
//! # Folding at joints ([`FoldPlane`])
//!
//! LYK06 "Folding at joints": at every IP (thumb), PIP and DIP joint the cross-sectional plane
//! of the posed sweep passes through `T(s_J)` with normal `R(s_J) +Y` (the sweep tangent; at the
//! joint centre the orientation is half-way through its knuckle slerp, so the plane bisects the
//! bend). A vertex with `s_V < s_J` on the distal side, or `s_V > s_J` on the proximal side, is
//! folded and is projected onto the plane.
//!
//! Which vertices are tested: those whose dominant influence is the joint's digit and whose
//! rest arc lies strictly between the previous and the next joint of the chain (the two bones
//! adjacent to the joint). Within those bones a vertex's side of the plane depends on this
//! joint's angle only (and, for the few vertices inside the neighbouring knuckle windows, on
//! part of the neighbouring bend, harmless: for a 110° PIP with an 80° DIP the palmar skin at
//! the end of the middle phalanx stays ~4 mm distal of the PIP plane, by a rigid-bone estimate). Beyond them it does not: in a fist the
//! curled distal phalanx lies on the proximal side of the PIP plane without being folded, and
//! an unrestricted test would flatten the fingertip onto it. A narrower window (e.g. the
//! knuckle window) would miss real folds: the palmar skin of a bone crosses the bisecting
//! plane up to `d tan(θ/2)` from the joint (14 mm for `d` = 1 cm at the 110° PIP limit), longer
//! than the knuckle half-width. So a middle-phalanx vertex is tested against both its PIP and
//! its DIP plane. The (vertex, plane, side) triples are precomputed by [`HandCollider::build`];
//! the per-frame pass is one loop over them.
//!
//! # Primitives ([`CollisionSphere`], [`PalmPlane`])
//!
//! LYK06 "Collision among fingers, thumb and palm":
//! - **Spheres** along every digit at sampled sweep parameters, from [`SPHERE_START`] past the
//!   MCP joint (nearer, the skins of adjacent fingers already touch through the web in the
//!   flat hand) to [`TIP_INSET`] short of the tip, every [`SPHERE_SPACING`], plus one at every
//!   IP / PIP / DIP joint (LYK06's red spheres). A sphere's radius is the median radial distance
//!   `d = |(o.x, o.z)|` (the binding's polar `d`, [`super::sweeps`]) of the rest vertices bound
//!   to the digit within half a spacing of its arc: the median follows the skin of the
//!   phalanx and ignores the few web and nail-edge vertices. Centres are `T(s)` of the posed
//!   sweep, recomputed every frame.
//! - **Palm planes**: there is no palm-control surface yet, so the tangent planes are sampled
//!   on the skin itself. At build time, palm vertices (not bound to a digit beyond its MCP)
//!   on the palmar side (rest normal within ~45° of `-Z`, `y >= 0`, i.e. palm not wrist) are
//!   sampled on a [`PALM_SPACING`] grid in the rest palm plane; each sample keeps four palmar
//!   neighbours about [`PALM_NEIGHBOUR_OFFSET`] away in `±X` and `±Y`. Every frame the plane
//!   passes through the deformed sample vertex with normal `(p₋ₓ - p₊ₓ) × (p₊ᵧ - p₋ᵧ)`
//!   normalised (outward, palmar), so the planes follow the sweep deformation of the palm. A
//!   plane acts as a patch: within [`PALM_PATCH_RADIUS`] of its point along the plane and
//!   [`PALM_DEPTH`] below it.
//!
//! # Detection ([`Contact`])
//!
//! LYK06 "we begin collision detection by checking the joint angles so as to exclude
//! unnecessary tests": a finger is tested against the palm only when the angle between its
//! metacarpal and its distal phalanx reaches [`PALM_CURL_MIN`] (a straighter finger points away
//! from the palm and cannot touch it). There is no joint-angle rule for digit pairs (two digits
//! touch at any angles when abducted or adducted); a bounding sphere per digit culls them.
//! - digit-digit: every pair of spheres of different digits (adjacent digits included: their
//!   sides are what touch when fingers are adducted, LYK06 Fig. 3(d));
//! - digit-palm: spheres beyond the middle of the digit's proximal phalanx
//!   ([`PALM_REACH_FRACTION`]) against the palm patches;
//! - object: an external [`Ball`] against every sphere and patch.
//!
//! # Resolution
//!
//! Skin vertices are pushed out of the primitives of other parts of the hand: a vertex bound to
//! digit `A` out of the spheres of every digit `B != A` (radially), a vertex of a digit beyond
//! its palm reach out of the palm patches (along the normal), a palm vertex out of the
//! palm-reaching spheres, and every vertex out of the ball. A vertex is pushed out of its
//! deepest primitive, then again, up to [`MAX_PUSHES`] times (overlapping primitives).
//!
//! Symmetry: each digit primitive in contact retracts by `share` times its deepest contact
//! ([`CollideOptions::share`]): a sphere's radius shrinks by `share * depth`, a palm plane
//! sinks by `share * depth`. With `share = 0.5` two touching digits each give way by half the
//! overlap and their skins meet in the middle instead of both being pushed the whole overlap
//! (which would open a gap); `share = 0` pushes out of the full primitives. The ball is rigid:
//! the hand always leaves it completely.
//!
//! Cull: vertices are grouped in buckets (a digit's vertices by their nearest sphere, palm
//! vertices by a [`PALM_BUCKET`] grid cell of their rest position); every frame each bucket
//! gets a bounding sphere (its anchor and the farthest member), and only the primitives
//! overlapping it grown by [`CULL_MARGIN`] are tested against its vertices; a vertex pushed
//! beyond that grown bound is tested again against every primitive. Per vertex, one pass of
//! squared distances rejects the vertices outside all candidates.
//!
//! Everything per frame writes into buffers allocated by [`HandCollider::build`]; the caller's
//! contact list is cleared and refilled, so after the first frames it no longer grows.

use glam::Vec3;

use super::skeleton::{Digit, HandPose, HandSkeleton, MAX_CHAIN, PosedSkeleton};
use super::sweeps::{Sweep, SweepHand};
use crease_core::mesh::Mesh;

/// Arc length past the MCP joint centre where a digit's spheres begin (metres). At the MCP
/// the skins of adjacent fingers are 0.3–2 mm apart in the flat hand (1 cm knuckle radii on a
/// ~2.2 cm spacing) and joined by the web; 1 cm further the splay and the taper have opened the
/// gap to a few millimetres, so the flat hand has no contact.
pub const SPHERE_START: f32 = 0.010;
/// Arc spacing of the sampled spheres (metres): about a phalanx radius, so that neighbouring
/// spheres overlap by most of their radius and the dents between them stay shallow (~1 mm).
pub const SPHERE_SPACING: f32 = 0.008;
/// The last sampled sphere sits this far short of the tip (metres): about the pulp radius,
/// so the sphere ends near the end of the skin instead of a radius beyond it.
pub const TIP_INSET: f32 = 0.006;
/// Fewest rest vertices in a sphere's window for its own median; sparser windows take the
/// radius of the nearest sphere that has enough.
const MIN_WINDOW_VERTICES: usize = 6;
/// Fraction of the proximal phalanx (thumb: its proximal phalanx too) past the MCP beyond which
/// spheres and skin are tested against the palm: the base of a flexed proximal phalanx rises
/// straight off the palm edge, and nearer than this the palm patches at the knuckles would
/// catch the finger's own base.
pub const PALM_REACH_FRACTION: f32 = 0.5;
/// Smallest angle between a finger's metacarpal and distal phalanx (radians) at which it is
/// tested against the palm (LYK06's joint-angle early-out). A finger curled less than 60°
/// points away from the palm; the tip reaches the palm only beyond ~150°.
pub const PALM_CURL_MIN: f32 = std::f32::consts::FRAC_PI_3;
/// Grid spacing of the palm-plane samples in the rest palm (metres): five or six samples
/// across the ~8 cm palm, a fingertip's width.
pub const PALM_SPACING: f32 = 0.015;
/// Radius of a palm patch along its plane (metres): 0.8 of the spacing, beyond the half
/// diagonal (0.71) so neighbouring patches overlap and cover the palm without holes.
pub const PALM_PATCH_RADIUS: f32 = 0.8 * PALM_SPACING;
/// Depth below a palm plane down to which a point counts as inside the palm (metres): half
/// the ~2.5 cm palm, so a digit pressed deep into it is still pushed out of the palmar side
/// while the dorsal side is never mistaken for it.
pub const PALM_DEPTH: f32 = 0.012;
/// Distance of a palm sample's four normal neighbours (metres): about two base-mesh edges, so
/// the normal averages out the mesh's small-scale facets.
pub const PALM_NEIGHBOUR_OFFSET: f32 = 0.008;
/// Cell size of the palm vertex buckets (metres).
pub const PALM_BUCKET: f32 = 0.02;
/// Margin added to a bucket's bound when culling primitives (metres): a vertex pushed
/// further out than this is tested again against every primitive, which is rare with 5 mm.
pub const CULL_MARGIN: f32 = 0.005;
/// Most successive pushes of one vertex (out of the deepest primitive each time).
pub const MAX_PUSHES: usize = 32;
/// How far past a primitive's surface a push puts a vertex (metres): 10 µm, invisible, but it
/// ends the ping-pong of a vertex in the wedge between two touching primitives, which an exact
/// push leaves micrometres inside one of them after [`MAX_PUSHES`].
pub const PUSH_SLACK: f32 = 1e-5;
/// Chain index of the MCP joint (wrist 0, CMC 1, MCP 2) for every digit.
const MCP: usize = 2;
/// Smallest `-n.z` of a rest normal for a palm vertex to count as palmar (~45°).
const PALMAR_COS: f32 = 0.7;

/// Errors of [`HandCollider::build`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CollideError {
    /// The rest mesh is not the one the hand was bound to.
    #[error("rest mesh has {mesh} vertices, the sweep hand binds {hand}")]
    VertexCount {
        /// Vertices bound by the [`SweepHand`].
        hand: usize,
        /// Vertices of the rest mesh.
        mesh: usize,
    },
    /// A digit has no bound skin to size its spheres from.
    #[error("no skin vertex is bound to the {0} beyond its MCP")]
    EmptyDigit(&'static str),
}

/// Why a [`CollisionSphere`] exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SphereKind {
    /// Sampled along the sweep every [`SPHERE_SPACING`].
    Sampled,
    /// At an IP / PIP / DIP joint (LYK06's extra joint spheres).
    Joint,
}

/// A collision sphere on a digit's sweep (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollisionSphere {
    /// The digit whose sweep carries it.
    pub digit: Digit,
    /// Arc length on the digit's sweep (metres; the same in every pose).
    pub arc: f32,
    /// Radius (metres).
    pub radius: f32,
    /// Centre `T(arc)`: in the last pose given to [`HandCollider::apply`] (the rest pose before).
    pub center: Vec3,
    /// Sampled or at a joint.
    pub kind: SphereKind,
    /// Whether it is tested against the palm ([`PALM_REACH_FRACTION`]).
    pub palm_reach: bool,
}

/// A tangent plane of the palm, acting within [`PALM_PATCH_RADIUS`] of its point (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PalmPlane {
    /// The skin vertex the plane passes through.
    pub vertex: u32,
    /// Point on the plane: the deformed sample vertex (last pose; rest before).
    pub point: Vec3,
    /// Unit normal out of the palmar skin.
    pub normal: Vec3,
}

/// The cross-sectional plane of a sweep at an IP / PIP / DIP joint (LYK06 "Folding at joints").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FoldPlane {
    /// The digit.
    pub digit: Digit,
    /// Index of the joint in the digit's chain (3: PIP or thumb IP, 4: DIP).
    pub chain_index: usize,
    /// Arc length `s_J` of the joint on the sweep.
    pub arc: f32,
    /// `T(s_J)` in the last pose (rest before).
    pub point: Vec3,
    /// The sweep direction `R(s_J) +Y` (towards the tip) in the last pose.
    pub normal: Vec3,
}

/// An external rigid ball (LYK06 "Collision detection with other objects").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    /// Centre, metres, in the hand frame.
    pub center: Vec3,
    /// Radius, metres.
    pub radius: f32,
}

/// What [`HandCollider::apply`] does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollideOptions {
    /// Project folded vertices onto the joint planes.
    pub fix_folds: bool,
    /// Detect (and with `resolve`, resolve) contacts between digits.
    pub digits: bool,
    /// Detect (and resolve) contacts between digits and palm.
    pub palm: bool,
    /// An external ball to detect (and resolve) contacts with.
    pub object: Option<Ball>,
    /// Push penetrating skin vertices out (otherwise contacts are only reported).
    pub resolve: bool,
    /// Fraction of a contact's depth by which each hand primitive gives way (module docs,
    /// "Symmetry"), in `[0, 1]`.
    pub share: f32,
}

impl Default for CollideOptions {
    fn default() -> Self {
        CollideOptions {
            fix_folds: true,
            digits: true,
            palm: true,
            object: None,
            resolve: true,
            share: 0.5,
        }
    }
}

/// The primitives of a [`Contact`] (indices into [`HandCollider::spheres`] and
/// [`HandCollider::palm_planes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactKind {
    /// Spheres of two different digits (`a`'s digit before `b`'s in [`Digit::ALL`]).
    DigitDigit {
        /// First sphere.
        a: usize,
        /// Second sphere.
        b: usize,
    },
    /// A digit sphere and a palm plane.
    DigitPalm {
        /// The sphere.
        sphere: usize,
        /// The plane.
        plane: usize,
    },
    /// The ball and a digit sphere.
    ObjectDigit {
        /// The sphere.
        sphere: usize,
    },
    /// The ball and a palm plane.
    ObjectPalm {
        /// The plane.
        plane: usize,
    },
}

/// One contact between two primitives (LYK06's red points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Which primitives.
    pub kind: ContactKind,
    /// Contact point: digit-digit, the middle of the overlap on the line of centres;
    /// digit-palm, the sphere centre projected onto the plane; object, the deepest point of
    /// the ball inside the hand primitive (on the ball's surface).
    pub point: Vec3,
    /// Overlap depth (metres, > 0).
    pub depth: f32,
    /// Unit normal: digit-digit from sphere `a` towards `b`; digit-palm the palm's outward
    /// normal; object from the ball towards the hand (the way the hand is pushed).
    pub normal: Vec3,
}

/// Counts of one [`HandCollider::apply`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CollideStats {
    /// Projections onto joint planes (a vertex between two joints can count twice).
    pub folded: usize,
    /// Contacts reported.
    pub contacts: usize,
    /// Vertices moved by the push-out.
    pub pushed: usize,
}

/// Which part of the hand a skin vertex belongs to, for collisions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexClass {
    /// Dominant influence on this digit's sweep at an arc beyond its MCP joint centre.
    Digit {
        /// The digit.
        digit: Digit,
        /// Rest arc length on the digit's sweep (metres).
        arc: f32,
    },
    /// Everything else: palm, back of the hand, wrist, the webs' bases.
    Palm,
}

/// One entry of the fold pass: a vertex, its joint plane and the side it belongs on.
#[derive(Clone, Copy, Debug, PartialEq)]
struct FoldEntry {
    vertex: u32,
    plane: u16,
    /// `+1` if the vertex belongs distal of the plane, `-1` proximal.
    side: f32,
}

/// A group of vertices sharing one bounding sphere per frame.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Bucket {
    owner: Owner,
    /// Range in `HandCollider::members`.
    start: u32,
    end: u32,
    /// Vertex whose position anchors the bound (palm buckets).
    anchor_vertex: u32,
    /// Tested against the palm (digit buckets beyond the palm reach).
    palm_reach: bool,
}

/// Owner of a bucket or a primitive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Owner {
    /// A digit; for a bucket, the sphere whose centre anchors it.
    Digit {
        digit: u8,
        sphere: u16,
    },
    Palm,
    Object,
}

/// A primitive as the push-out sees it this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Shape {
    /// Centre and (effective) radius.
    Sphere(Vec3, f32),
    /// Point, outward normal, sink (the plane's surface is at `-sink` along the normal).
    Plane(Vec3, Vec3, f32),
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Obstacle {
    shape: Shape,
    owner: Owner,
    /// Spheres: whether they reach the palm (and their digit passes the curl early-out).
    palm_reach: bool,
}

/// The collision model of a [`SweepHand`] and its per-frame buffers (module docs).
#[derive(Clone, Debug)]
pub struct HandCollider {
    skeleton: HandSkeleton,
    posed: PosedSkeleton,
    classes: Vec<VertexClass>,
    spheres: Vec<CollisionSphere>,
    /// Per digit, the range of its spheres.
    sphere_range: [(usize, usize); 5],
    palm_planes: Vec<PalmPlane>,
    /// Per palm plane, its `-X, +X, -Y, +Y` neighbours.
    plane_neighbours: Vec<[u32; 4]>,
    fold_planes: Vec<FoldPlane>,
    fold_entries: Vec<FoldEntry>,
    buckets: Vec<Bucket>,
    members: Vec<u32>,
    // Per-frame buffers.
    sphere_depth: Vec<f32>,
    plane_depth: Vec<f32>,
    bucket_bound: Vec<(Vec3, f32)>,
    obstacles: Vec<Obstacle>,
    candidates: Vec<u32>,
    /// The spherical candidates as (centre, squared radius), for the fast rejection.
    round: Vec<(Vec3, f32)>,
    /// The planar candidates of the bucket.
    flat: Vec<Shape>,
}

/// The `q`-quantile of `values` (sorted in place); `None` if empty.
fn quantile(values: &mut [f32], q: f32) -> Option<f32> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f32::total_cmp);
    let k = ((values.len() - 1) as f32 * q).round() as usize;
    Some(values[k])
}

impl HandCollider {
    /// Builds the primitives, the fold entries and the buckets of `hand`, whose rest skin is
    /// `rest` (the mesh given to [`SweepHand::bind`]).
    pub fn build(hand: &SweepHand, rest: &Mesh) -> Result<HandCollider, CollideError> {
        let n = hand.vertex_count();
        if rest.positions.len() != n {
            return Err(CollideError::VertexCount {
                hand: n,
                mesh: rest.positions.len(),
            });
        }
        let skeleton = hand.skeleton().clone();
        let posed = skeleton.pose(&HandPose::FLAT);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&posed, d));
        let lengths = sweeps.map(|s| s.length());
        let mut joint_arcs = [[0.0f32; MAX_CHAIN]; 5];
        for d in Digit::ALL {
            for (j, a) in joint_arcs[d.index()][..d.chain_len()]
                .iter_mut()
                .enumerate()
            {
                *a = sweeps[d.index()].joint_arc(j);
            }
        }
        // Dominant influence of every vertex: (digit, arc, radial d).
        let dominant: Vec<(Digit, f32, f32)> = (0..n)
            .map(|i| {
                hand.influences(i)
                    .max_by(|a, b| a.weight.total_cmp(&b.weight))
                    .map_or((Digit::Middle, 0.0, f32::INFINITY), |inf| {
                        let arc = inf.t * lengths[inf.digit.index()];
                        let d = (inf.offset.x * inf.offset.x + inf.offset.z * inf.offset.z).sqrt();
                        (inf.digit, arc, d)
                    })
            })
            .collect();
        let classes: Vec<VertexClass> = dominant
            .iter()
            .map(|&(digit, arc, _)| {
                if arc > joint_arcs[digit.index()][MCP] {
                    VertexClass::Digit { digit, arc }
                } else {
                    VertexClass::Palm
                }
            })
            .collect();

        // Spheres (LYK06 "Collision among fingers, thumb and palm").
        let mut spheres = Vec::new();
        let mut sphere_range = [(0, 0); 5];
        for d in Digit::ALL {
            let arcs = &joint_arcs[d.index()];
            let last = d.chain_len() - 1;
            let (mcp, tip) = (arcs[MCP], arcs[last]);
            let start = mcp + SPHERE_START;
            let end = tip - TIP_INSET;
            let count = ((end - start) / SPHERE_SPACING).ceil().max(1.0) as usize;
            let first = spheres.len();
            let reach = mcp + PALM_REACH_FRACTION * (arcs[MCP + 1] - mcp);
            let mut push = |arc: f32, kind| {
                spheres.push(CollisionSphere {
                    digit: d,
                    arc,
                    radius: 0.0,
                    center: sweeps[d.index()].frame_at_arc(arc).position,
                    kind,
                    palm_reach: arc >= reach,
                });
            };
            for k in 0..=count {
                push(
                    start + (end - start) * k as f32 / count as f32,
                    SphereKind::Sampled,
                );
            }
            for &arc in &arcs[MCP + 1..last] {
                push(arc, SphereKind::Joint);
            }
            let range = (first, spheres.len());
            // Radii: median d of the digit's vertices within half a spacing (module docs).
            let mut window = Vec::new();
            let mut radii: Vec<Option<f32>> = spheres[range.0..range.1]
                .iter()
                .map(|s| {
                    window.clear();
                    window.extend(dominant.iter().filter_map(|&(dd, arc, r)| {
                        (dd == d && (arc - s.arc).abs() <= 0.5 * SPHERE_SPACING && arc < tip)
                            .then_some(r)
                    }));
                    if window.len() < MIN_WINDOW_VERTICES {
                        None
                    } else {
                        quantile(&mut window, 0.5)
                    }
                })
                .collect();
            let known: Vec<(f32, f32)> = spheres[range.0..range.1]
                .iter()
                .zip(&radii)
                .filter_map(|(s, r)| r.map(|r| (s.arc, r)))
                .collect();
            if known.is_empty() {
                return Err(CollideError::EmptyDigit(d.name()));
            }
            for (s, r) in spheres[range.0..range.1].iter_mut().zip(&mut radii) {
                s.radius = r.unwrap_or_else(|| {
                    known
                        .iter()
                        .min_by(|a, b| (a.0 - s.arc).abs().total_cmp(&(b.0 - s.arc).abs()))
                        .map_or(0.0, |k| k.1)
                });
            }
            sphere_range[d.index()] = range;
        }

        // Palm planes: palmar palm vertices sampled on a grid, with four neighbours each.
        let normals = rest.vertex_normals();
        let palmar: Vec<usize> = (0..n)
            .filter(|&i| {
                classes[i] == VertexClass::Palm
                    && -normals[i].z >= PALMAR_COS
                    && rest.positions[i].y >= 0.0
            })
            .collect();
        let nearest_palmar = |target: Vec3, within: f32| -> Option<usize> {
            palmar
                .iter()
                .map(|&i| (i, (rest.positions[i] - target).truncate().length()))
                .filter(|&(_, dist)| dist <= within)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        };
        let mut palm_planes = Vec::new();
        let mut plane_neighbours = Vec::new();
        if !palmar.is_empty() {
            let (lo, hi) = palmar.iter().fold(
                (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |(lo, hi), &i| (lo.min(rest.positions[i]), hi.max(rest.positions[i])),
            );
            let cells = ((hi - lo) / PALM_SPACING).ceil();
            for cy in 0..cells.y as usize {
                for cx in 0..cells.x as usize {
                    let c = lo + Vec3::new(cx as f32 + 0.5, cy as f32 + 0.5, 0.0) * PALM_SPACING;
                    let Some(v) = nearest_palmar(c, 0.5 * PALM_SPACING) else {
                        continue;
                    };
                    let p = rest.positions[v];
                    let offsets = [-Vec3::X, Vec3::X, -Vec3::Y, Vec3::Y];
                    let ring = offsets.map(|o| {
                        nearest_palmar(p + o * PALM_NEIGHBOUR_OFFSET, 0.5 * PALM_NEIGHBOUR_OFFSET)
                    });
                    let [Some(a), Some(b), Some(e), Some(f)] = ring else {
                        continue;
                    };
                    let ring = [a as u32, b as u32, e as u32, f as u32];
                    let normal = plane_normal(&rest.positions, &ring);
                    if normal.dot(normals[v]) < PALMAR_COS {
                        continue;
                    }
                    palm_planes.push(PalmPlane {
                        vertex: v as u32,
                        point: p,
                        normal,
                    });
                    plane_neighbours.push(ring);
                }
            }
        }

        // Fold planes and entries (LYK06 "Folding at joints").
        let mut fold_planes = Vec::new();
        let mut fold_entries = Vec::new();
        for d in Digit::ALL {
            let arcs = &joint_arcs[d.index()];
            for j in MCP + 1..d.chain_len() - 1 {
                let plane = fold_planes.len() as u16;
                let f = sweeps[d.index()].frame_at_arc(arcs[j]);
                fold_planes.push(FoldPlane {
                    digit: d,
                    chain_index: j,
                    arc: arcs[j],
                    point: f.position,
                    normal: f.rotation * Vec3::Y,
                });
                for (i, &(dd, arc, _)) in dominant.iter().enumerate() {
                    if dd == d && arc > arcs[j - 1] && arc < arcs[j + 1] && arc != arcs[j] {
                        fold_entries.push(FoldEntry {
                            vertex: i as u32,
                            plane,
                            side: if arc > arcs[j] { 1.0 } else { -1.0 },
                        });
                    }
                }
            }
        }

        // Buckets: digit vertices by nearest sphere, palm vertices by grid cell.
        let mut keyed: Vec<(Owner, u32)> = classes
            .iter()
            .enumerate()
            .map(|(i, c)| match *c {
                VertexClass::Digit { digit, arc } => {
                    let (a, b) = sphere_range[digit.index()];
                    let k = (a..b)
                        .min_by(|&x, &y| {
                            (spheres[x].arc - arc)
                                .abs()
                                .total_cmp(&(spheres[y].arc - arc).abs())
                        })
                        .unwrap_or(a);
                    (
                        Owner::Digit {
                            digit: digit.index() as u8,
                            sphere: k as u16,
                        },
                        i as u32,
                    )
                }
                VertexClass::Palm => (Owner::Palm, i as u32),
            })
            .collect();
        let cell = |i: u32| -> (i32, i32, i32) {
            let p = (rest.positions[i as usize] / PALM_BUCKET).floor();
            (p.x as i32, p.y as i32, p.z as i32)
        };
        let key = |o: &(Owner, u32)| match o.0 {
            Owner::Digit { sphere, .. } => (0, sphere as i32, 0, 0),
            _ => {
                let (x, y, z) = cell(o.1);
                (1, x, y, z)
            }
        };
        keyed.sort_by_key(|o| (key(o), o.1));
        let members: Vec<u32> = keyed.iter().map(|o| o.1).collect();
        let mut buckets = Vec::new();
        let mut start = 0;
        while start < keyed.len() {
            let k = key(&keyed[start]);
            let end = start + keyed[start..].iter().take_while(|o| key(o) == k).count();
            let owner = keyed[start].0;
            let group = &members[start..end];
            let mean = group
                .iter()
                .map(|&i| rest.positions[i as usize])
                .sum::<Vec3>()
                / group.len() as f32;
            let anchor = group
                .iter()
                .copied()
                .min_by(|&a, &b| {
                    (rest.positions[a as usize] - mean)
                        .length_squared()
                        .total_cmp(&(rest.positions[b as usize] - mean).length_squared())
                })
                .unwrap_or(group[0]);
            let palm_reach = match owner {
                Owner::Digit { sphere, .. } => spheres[sphere as usize].palm_reach,
                _ => false,
            };
            buckets.push(Bucket {
                owner,
                start: start as u32,
                end: end as u32,
                anchor_vertex: anchor,
                palm_reach,
            });
            start = end;
        }

        Ok(HandCollider {
            skeleton,
            posed,
            sphere_depth: vec![0.0; spheres.len()],
            plane_depth: vec![0.0; palm_planes.len()],
            bucket_bound: vec![(Vec3::ZERO, 0.0); buckets.len()],
            obstacles: Vec::with_capacity(spheres.len() + palm_planes.len() + 1),
            candidates: Vec::with_capacity(spheres.len() + palm_planes.len() + 1),
            round: Vec::with_capacity(spheres.len() + 1),
            flat: Vec::with_capacity(palm_planes.len()),
            classes,
            spheres,
            sphere_range,
            palm_planes,
            plane_neighbours,
            fold_planes,
            fold_entries,
            buckets,
            members,
        })
    }

    /// Number of skin vertices.
    pub fn vertex_count(&self) -> usize {
        self.classes.len()
    }

    /// The collision class of vertex `i`.
    pub fn vertex_class(&self, i: usize) -> VertexClass {
        self.classes[i]
    }

    /// The collision spheres (centres in the last pose), digit by digit (for drawing).
    pub fn spheres(&self) -> &[CollisionSphere] {
        &self.spheres
    }

    /// The spheres of one digit.
    pub fn digit_spheres(&self, digit: Digit) -> &[CollisionSphere] {
        let (a, b) = self.sphere_range[digit.index()];
        &self.spheres[a..b]
    }

    /// The palm planes (in the last pose).
    pub fn palm_planes(&self) -> &[PalmPlane] {
        &self.palm_planes
    }

    /// The joint planes of the fold test (in the last pose).
    pub fn fold_planes(&self) -> &[FoldPlane] {
        &self.fold_planes
    }

    /// Number of (vertex, joint plane) pairs tested per frame by the fold pass.
    pub fn fold_tests(&self) -> usize {
        self.fold_entries.len()
    }

    /// [`HandCollider::apply`] for joint angles: poses the skeleton (into a buffer of the
    /// collider) first. `positions` must be the sweep deformation of the same pose.
    pub fn apply_pose(
        &mut self,
        pose: &HandPose,
        positions: &mut [Vec3],
        options: &CollideOptions,
        contacts: &mut Vec<Contact>,
    ) -> CollideStats {
        let mut posed = self.posed;
        self.skeleton.pose_into(pose, &mut posed);
        self.posed = posed;
        self.apply(&posed, positions, options, contacts)
    }

    /// One frame: poses the primitives along the sweeps of `posed`, projects folded vertices
    /// onto the joint planes, detects contacts (written to `contacts`, cleared first) and, with
    /// [`CollideOptions::resolve`], pushes penetrating vertices out. `positions` is the skin
    /// deformed by [`SweepHand::deform_into`] for the same pose; it is modified in place.
    /// Allocates nothing once `contacts` has grown to the frame's count.
    ///
    /// # Panics
    /// If `positions.len()` differs from [`HandCollider::vertex_count`].
    pub fn apply(
        &mut self,
        posed: &PosedSkeleton,
        positions: &mut [Vec3],
        options: &CollideOptions,
        contacts: &mut Vec<Contact>,
    ) -> CollideStats {
        assert_eq!(positions.len(), self.classes.len(), "positions length");
        contacts.clear();
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(posed, d));
        let mut stats = CollideStats::default();

        // LYK06 "Folding at joints": project folded vertices onto the joint planes.
        for p in &mut self.fold_planes {
            let f = sweeps[p.digit.index()].frame_at_arc(p.arc);
            p.point = f.position;
            p.normal = f.rotation * Vec3::Y;
        }
        if options.fix_folds {
            for e in &self.fold_entries {
                let p = &self.fold_planes[e.plane as usize];
                let v = &mut positions[e.vertex as usize];
                let h = p.normal.dot(*v - p.point);
                if h * e.side < 0.0 {
                    *v -= h * p.normal;
                    stats.folded += 1;
                }
            }
        }

        // Posed primitives.
        for s in &mut self.spheres {
            s.center = sweeps[s.digit.index()].frame_at_arc(s.arc).position;
        }
        for (p, ring) in self.palm_planes.iter_mut().zip(&self.plane_neighbours) {
            p.point = positions[p.vertex as usize];
            p.normal = plane_normal(positions, ring);
        }
        self.sphere_depth.fill(0.0);
        self.plane_depth.fill(0.0);
        let bounds = Digit::ALL.map(|d| {
            let (a, b) = self.sphere_range[d.index()];
            bound_of(self.spheres[a..b].iter().map(|s| (s.center, s.radius)))
        });
        let palm_bound = bound_of(
            self.palm_planes
                .iter()
                .map(|p| (p.point, PALM_PATCH_RADIUS + PALM_DEPTH)),
        );
        // LYK06: joint angles first. A finger curled less than PALM_CURL_MIN cannot reach
        // the palm; the thumb reaches it by opposition at any curl, so only its bound culls it.
        let palm_active = Digit::ALL.map(|d| {
            let chain = posed.chain(d);
            let metacarpal = chain[1].axis();
            let distal = chain[d.chain_len() - 2].axis();
            d == Digit::Thumb || metacarpal.dot(distal) <= PALM_CURL_MIN.cos()
        });

        // Digit-digit: sphere pairs of different digits whose digit bounds overlap.
        if options.digits {
            for da in 0..5 {
                for db in da + 1..5 {
                    if !overlaps(bounds[da], bounds[db]) {
                        continue;
                    }
                    let (a0, a1) = self.sphere_range[da];
                    let (b0, b1) = self.sphere_range[db];
                    for i in a0..a1 {
                        let (ca, ra) = (self.spheres[i].center, self.spheres[i].radius);
                        for j in b0..b1 {
                            let (cb, rb) = (self.spheres[j].center, self.spheres[j].radius);
                            let dist = (cb - ca).length();
                            let depth = ra + rb - dist;
                            if depth <= 0.0 {
                                continue;
                            }
                            let normal = if dist > 0.0 {
                                (cb - ca) / dist
                            } else {
                                Vec3::X
                            };
                            contacts.push(Contact {
                                kind: ContactKind::DigitDigit { a: i, b: j },
                                point: ca + normal * (ra - 0.5 * depth),
                                depth,
                                normal,
                            });
                            self.sphere_depth[i] = self.sphere_depth[i].max(depth);
                            self.sphere_depth[j] = self.sphere_depth[j].max(depth);
                        }
                    }
                }
            }
        }

        // Digit-palm: palm-reaching spheres against the palm patches.
        if options.palm {
            for d in Digit::ALL {
                if !palm_active[d.index()] || !overlaps(bounds[d.index()], palm_bound) {
                    continue;
                }
                let (a, b) = self.sphere_range[d.index()];
                for i in a..b {
                    let s = self.spheres[i];
                    if !s.palm_reach {
                        continue;
                    }
                    for (k, p) in self.palm_planes.iter().enumerate() {
                        let Some(h) = patch_height(p.point, p.normal, s.center) else {
                            continue;
                        };
                        let depth = s.radius - h;
                        if depth <= 0.0 || h < -PALM_DEPTH {
                            continue;
                        }
                        contacts.push(Contact {
                            kind: ContactKind::DigitPalm {
                                sphere: i,
                                plane: k,
                            },
                            point: s.center - h * p.normal,
                            depth,
                            normal: p.normal,
                        });
                        self.sphere_depth[i] = self.sphere_depth[i].max(depth);
                        self.plane_depth[k] = self.plane_depth[k].max(depth);
                    }
                }
            }
        }

        // LYK06 "Collision detection with other objects": the ball against every primitive.
        if let Some(ball) = options.object {
            for (i, s) in self.spheres.iter().enumerate() {
                let dist = (s.center - ball.center).length();
                let depth = ball.radius + s.radius - dist;
                if depth > 0.0 {
                    let normal = if dist > 0.0 {
                        (s.center - ball.center) / dist
                    } else {
                        Vec3::Z
                    };
                    contacts.push(Contact {
                        kind: ContactKind::ObjectDigit { sphere: i },
                        point: ball.center + normal * ball.radius,
                        depth,
                        normal,
                    });
                }
            }
            for (k, p) in self.palm_planes.iter().enumerate() {
                let Some(h) = patch_height(p.point, p.normal, ball.center) else {
                    continue;
                };
                let depth = ball.radius - h;
                if depth > 0.0 && h > -PALM_DEPTH - ball.radius {
                    contacts.push(Contact {
                        kind: ContactKind::ObjectPalm { plane: k },
                        point: ball.center - ball.radius * p.normal,
                        depth,
                        normal: -p.normal,
                    });
                }
            }
        }
        stats.contacts = contacts.len();

        if options.resolve && (options.digits || options.palm || options.object.is_some()) {
            stats.pushed = self.push_out(positions, options, palm_active, &bounds, palm_bound);
        }
        stats
    }

    /// The push-out pass (module docs, "Resolution"); returns the number of vertices moved.
    fn push_out(
        &mut self,
        positions: &mut [Vec3],
        options: &CollideOptions,
        palm_active: [bool; 5],
        digit_bounds: &[(Vec3, f32); 5],
        palm_bound: (Vec3, f32),
    ) -> usize {
        let share = options.share.clamp(0.0, 1.0);
        self.obstacles.clear();
        for (s, depth) in self.spheres.iter().zip(&self.sphere_depth) {
            let d = s.digit.index();
            self.obstacles.push(Obstacle {
                shape: Shape::Sphere(s.center, (s.radius - share * depth).max(0.0)),
                owner: Owner::Digit {
                    digit: d as u8,
                    sphere: 0,
                },
                palm_reach: s.palm_reach && palm_active[d],
            });
        }
        if options.palm {
            for (p, depth) in self.palm_planes.iter().zip(&self.plane_depth) {
                self.obstacles.push(Obstacle {
                    shape: Shape::Plane(p.point, p.normal, share * depth),
                    owner: Owner::Palm,
                    palm_reach: false,
                });
            }
        }
        if let Some(ball) = options.object {
            self.obstacles.push(Obstacle {
                shape: Shape::Sphere(ball.center, ball.radius),
                owner: Owner::Object,
                palm_reach: false,
            });
        }
        // Bucket bounds: anchor and farthest member.
        for (b, bound) in self.buckets.iter().zip(&mut self.bucket_bound) {
            let anchor = match b.owner {
                Owner::Digit { sphere, .. } => self.spheres[sphere as usize].center,
                _ => positions[b.anchor_vertex as usize],
            };
            let r2 = self.members[b.start as usize..b.end as usize]
                .iter()
                .map(|&i| (positions[i as usize] - anchor).length_squared())
                .fold(0.0f32, f32::max);
            *bound = (anchor, r2.sqrt());
        }
        let mut pushed = 0;
        // Obstacles: the spheres, then (with `options.palm`) the planes, then the ball.
        let planes_in = if options.palm {
            self.palm_planes.len()
        } else {
            0
        };
        let palm_planes = self.spheres.len()..self.spheres.len() + planes_in;
        for (b, &(anchor, radius)) in self.buckets.iter().zip(&self.bucket_bound) {
            // Cull with a margin, so that the usual pushes (a few millimetres) stay inside it.
            let bound = (anchor, radius + CULL_MARGIN);
            self.candidates.clear();
            // Spheres digit by digit, behind the digit's bound.
            for (d, &(a, e)) in self.sphere_range.iter().enumerate() {
                let wanted = match b.owner {
                    Owner::Digit { digit, .. } => options.digits && digit as usize != d,
                    _ => options.palm && palm_active[d],
                };
                if !wanted || !overlaps(digit_bounds[d], bound) {
                    continue;
                }
                for k in a..e {
                    let o = &self.obstacles[k];
                    if relevant(b, o, options, palm_active) && shape_near(o.shape, bound) {
                        self.candidates.push(k as u32);
                    }
                }
            }
            let planes = options.palm && overlaps(palm_bound, bound);
            let rest = if planes {
                palm_planes.start..self.obstacles.len()
            } else {
                palm_planes.end..self.obstacles.len()
            };
            for k in rest {
                let o = &self.obstacles[k];
                if relevant(b, o, options, palm_active) && shape_near(o.shape, bound) {
                    self.candidates.push(k as u32);
                }
            }
            if self.candidates.is_empty() {
                continue;
            }
            self.round.clear();
            self.flat.clear();
            for &k in &self.candidates {
                match self.obstacles[k as usize].shape {
                    Shape::Sphere(c, r) => self.round.push((c, r * r)),
                    plane => self.flat.push(plane),
                }
            }
            for &i in &self.members[b.start as usize..b.end as usize] {
                let v = &mut positions[i as usize];
                // Fast rejection: most vertices of a bucket touch none of its candidates.
                if self
                    .round
                    .iter()
                    .all(|&(c, r2)| (*v - c).length_squared() >= r2)
                    && self.flat.iter().all(|&p| penetration(p, *v).is_none())
                {
                    continue;
                }
                let obstacles = &self.obstacles;
                let mut moved =
                    push_vertex(v, self.candidates.iter().map(|&k| obstacles[k as usize]));
                if moved && (*v - anchor).length_squared() > bound.1 * bound.1 {
                    // Pushed beyond the cull's bound: the primitives culled for the bucket
                    // may now hold it.
                    moved |= push_vertex(
                        v,
                        obstacles
                            .iter()
                            .copied()
                            .filter(|o| relevant(b, o, options, palm_active)),
                    );
                }
                pushed += usize::from(moved);
            }
        }
        pushed
    }
}

/// Whether the vertices of bucket `b` are pushed out of obstacle `o` (module docs,
/// "Resolution").
fn relevant(b: &Bucket, o: &Obstacle, options: &CollideOptions, palm_active: [bool; 5]) -> bool {
    match (b.owner, o.owner) {
        (_, Owner::Object) => true,
        (Owner::Digit { digit: a, .. }, Owner::Digit { digit: d, .. }) => options.digits && a != d,
        (Owner::Digit { digit, .. }, Owner::Palm) => b.palm_reach && palm_active[digit as usize],
        (Owner::Palm, Owner::Digit { .. }) => options.palm && o.palm_reach,
        _ => false,
    }
}

/// Pushes `v` out of the deepest of `obstacles`, again and again up to [`MAX_PUSHES`] times;
/// whether it moved.
fn push_vertex(v: &mut Vec3, obstacles: impl Iterator<Item = Obstacle> + Clone) -> bool {
    let mut moved = false;
    for _ in 0..MAX_PUSHES {
        let mut deepest = (0.0f32, Vec3::ZERO);
        for o in obstacles.clone() {
            match penetration(o.shape, *v) {
                Some((pen, dir)) if pen > deepest.0 => deepest = (pen, dir),
                _ => {}
            }
        }
        if deepest.0 <= 0.0 {
            break;
        }
        *v += (deepest.0 + PUSH_SLACK) * deepest.1;
        moved = true;
    }
    moved
}

/// Outward palm normal from a sample's `-X, +X, -Y, +Y` neighbours: `Y × X` is `-Z` in the
/// rest palm, i.e. palmar.
fn plane_normal(positions: &[Vec3], ring: &[u32; 4]) -> Vec3 {
    let [mx, px, my, py] = ring.map(|i| positions[i as usize]);
    (py - my).cross(px - mx).normalize_or_zero()
}

/// Bounding sphere of some spheres: centred on the mean centre.
fn bound_of(spheres: impl Iterator<Item = (Vec3, f32)> + Clone) -> (Vec3, f32) {
    let (sum, count) = spheres
        .clone()
        .fold((Vec3::ZERO, 0usize), |(s, c), (p, _)| (s + p, c + 1));
    if count == 0 {
        return (Vec3::ZERO, -1.0);
    }
    let c = sum / count as f32;
    let r = spheres.fold(0.0f32, |r, (p, pr)| r.max((p - c).length() + pr));
    (c, r)
}

fn overlaps(a: (Vec3, f32), b: (Vec3, f32)) -> bool {
    a.1 >= 0.0 && b.1 >= 0.0 && (a.0 - b.0).length() < a.1 + b.1
}

/// Height of `x` above a palm patch, `None` outside the patch's radius along the plane.
fn patch_height(point: Vec3, normal: Vec3, x: Vec3) -> Option<f32> {
    let r = x - point;
    let h = normal.dot(r);
    (r.length_squared() - h * h < PALM_PATCH_RADIUS * PALM_PATCH_RADIUS).then_some(h)
}

/// Whether a primitive can touch any point of the bound `(centre, radius)`.
fn shape_near(shape: Shape, (c, r): (Vec3, f32)) -> bool {
    match shape {
        Shape::Sphere(p, pr) => (p - c).length_squared() < (pr + r) * (pr + r),
        Shape::Plane(p, n, sink) => {
            let d = c - p;
            let h = n.dot(d);
            let t2 = d.length_squared() - h * h;
            let reach = PALM_PATCH_RADIUS + r;
            h < r - sink && h > -PALM_DEPTH - r && t2 < reach * reach
        }
    }
}

/// Penetration depth of `v` into a primitive and the unit direction that pushes it out.
fn penetration(shape: Shape, v: Vec3) -> Option<(f32, Vec3)> {
    match shape {
        Shape::Sphere(c, r) => {
            let d = v - c;
            let l2 = d.length_squared();
            if l2 >= r * r {
                return None;
            }
            let l = l2.sqrt();
            let dir = if l > 0.0 { d / l } else { Vec3::Z };
            Some((r - l, dir))
        }
        Shape::Plane(p, n, sink) => {
            let h = patch_height(p, n, v)?;
            (h < -sink && h > -PALM_DEPTH).then_some((-sink - h, n))
        }
    }
}
