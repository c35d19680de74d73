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
//! - **Palm planes**: the tangent planes are sampled on the skin itself (not on the
//!   palm-control surface of [`crate::palm`]). At build time, palm vertices (not bound to a
//!   digit beyond its MCP) on the palmar side (rest normal within ~45° of `-Z`, `y >= 0`,
//!   i.e. palm not wrist) are sampled on a [`PALM_SPACING`] grid in the rest palm plane; each
//!   sample keeps four palmar neighbours about [`PALM_NEIGHBOUR_OFFSET`] away in `±X` and `±Y`.
//!   Every frame the plane passes through the deformed sample vertex with normal
//!   `(p₋ₓ - p₊ₓ) × (p₊ᵧ - p₋ᵧ)` normalised (outward, palmar), so the planes follow the sweep
//!   deformation of the palm. A plane acts as a patch: within [`PALM_PATCH_RADIUS`] of its
//!   point along the plane and [`PALM_DEPTH`] below it.
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
//!
//! Layout:
//! - `primitives`: the hand's primitives ([`CollisionSphere`], [`PalmPlane`], [`FoldPlane`]),
//!   the external [`Ball`], and the geometry of the push-out (penetration, patch height,
//!   bounding spheres).
//! - `build`: [`HandCollider::build`]: spheres sized from the rest skin, palm samples, fold
//!   entries and vertex buckets, computed once.
//! - `detect`: the per-frame [`HandCollider::apply`] (folds, posed primitives, [`Contact`]s)
//!   and its options and counts ([`CollideOptions`], [`CollideStats`]).
//! - `resolve`: the push-out of penetrating skin vertices (module docs, "Resolution").
//! - here: the constants, [`HandCollider`] and its accessors, [`VertexClass`].

use glam::Vec3;

use super::skeleton::{Digit, HandSkeleton, PosedSkeleton};

mod build;
mod detect;
mod primitives;
mod resolve;

pub use detect::{CollideOptions, CollideStats, Contact, ContactKind};
pub use primitives::{Ball, CollisionSphere, FoldPlane, PalmPlane, SphereKind};
use primitives::{Obstacle, Shape};

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
        ///
        /// [`SweepHand`]: crate::sweeps::SweepHand
        hand: usize,
        /// Vertices of the rest mesh.
        mesh: usize,
    },
    /// A digit has no bound skin to size its spheres from.
    #[error("no skin vertex is bound to the {0} beyond its MCP")]
    EmptyDigit(&'static str),
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

/// The collision model of a [`SweepHand`] and its per-frame buffers (module docs).
///
/// [`SweepHand`]: crate::sweeps::SweepHand
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

impl HandCollider {
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
}
