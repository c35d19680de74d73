//! The rest surface of the sweep hand (LYK06 §2 needs a skin mesh to bind to the sweeps; the
//! paper used a scanned hand, this project builds its own): a smooth signed distance function
//! (SDF) of the flat adult hand, polygonised by Naive Surface Nets and smoothed.
//!
//! # The signed distance function ([`HandSdf`])
//!
//! Built from the flat-pose skeleton ([`HandSkeleton::pose`] with [`HandPose::FLAT`]), in the
//! skeleton's frame (metres; wrist at the origin, `+Y` to the middle finger, `+Z` dorsal):
//! - each digit is a chain of *round cones* (spheres swept along a bone with a linearly varying
//!   radius), one per bone from the CMC to the tip, radii tapering from the knuckle to the pulp;
//!   the last cone ends one tip radius short of the skeleton tip so the skin ends at the tip.
//!   Cones of one digit share the radius at their common joint and are united by a hard `min`;
//! - the palm is a rounded slab: a planar polygon spanning the metacarpals, inflated by half the
//!   palm thickness (the exact distance to a flat polygon minus a radius), plus a flattened
//!   wrist stub (a capsule across the wrist);
//! - palm and wrist are united by a polynomial smooth minimum (blend radius [`BLEND_RADIUS`]),
//!   and each digit is blended with that body separately, the five results united by a hard
//!   `min`: the fillets grow the webs at the knuckles and the thenar web, but two fingers
//!   never blend with each other along their phalanges. (Blending the digits with each other
//!   filled the 2-3 mm gaps between the proximal phalanges with thin sheets of skin that the
//!   sweeps stretched up to 19x when neighbouring fingers bent differently; per-digit
//!   fillets keep the worst edge stretch of the named poses at 3-6x, in the thenar web, as
//!   measured by `cargo run --release -p crease-core --example sweep_stretch`.)
//!
//! Every piece is an exact distance (or 1-Lipschitz bound), and `min` / the polynomial smooth
//! minimum keep the result 1-Lipschitz: `|f(p) - f(q)| <= |p - q|`. Polygonisation relies on
//! that to skip grid blocks far from the surface.
//!
//! # Polygonisation ([`HandSurface::build`])
//!
//! Naive Surface Nets (Gibson 1998, "Constrained elastic surface nets"; the dual of marching
//! cubes): the SDF is sampled on a regular grid (only in a narrow band: 4^3-cell blocks whose
//! centre is farther from the surface than their half-diagonal plus one cell are filled with the
//! centre's sign), every cell whose corners change sign gets one vertex at the mean of its edge
//! crossings, and every sign-changing grid edge gives one quad joining the four cells around it,
//! oriented so that its normal points from inside (`f < 0`) to outside, split along its shorter
//! diagonal. A few Taubin smoothing steps (λ|μ, Taubin 1995) remove the grid terracing, then
//! each vertex is projected back onto the zero set by Newton steps along the SDF gradient;
//! the corners of any triangle folded by the projection are relaxed and projected again.
//!
//! The result is checked to be a closed, edge- and vertex-manifold surface; an ambiguous grid
//! configuration (two sheets through one cell, possible where a web narrows below a cell) would
//! break that, so the grid is then shifted by a fraction of a cell and rebuilt.

use glam::{Vec2, Vec3};

use super::skeleton::{Digit, HandPose, HandSkeleton};
use crease_core::mesh::Mesh;

/// Blend radius of the smooth minimum between palm, wrist and digits, metres. 8 mm is about
/// the depth of the webs between adult fingers at the knuckles; smaller gives pinched webs,
/// larger fills the gaps between the proximal phalanges.
pub const BLEND_RADIUS: f32 = 0.008;

/// Half the palm thickness, metres (palm 2.5 cm thick at the metacarpals before blending; the
/// blend with the thenar cone and the knuckles adds a few millimetres).
const PALM_HALF_THICKNESS: f32 = 0.0125;

/// Height of the palm's mid-plane, metres: slightly palmar of the bones (`z = 0`), because the
/// palmar soft tissue is thicker than the dorsal.
const PALM_MID_Z: f32 = -0.003;

/// The palm polygon in the `z = PALM_MID_Z` plane (x, y), metres, before inflation by
/// [`PALM_HALF_THICKNESS`]: wrist corners, hypothenar side, the knuckle line (index MCP high,
/// little MCP low) and the thenar side. Chosen so that the inflated slab reaches the finger MCP
/// joints and is ~8 cm wide across the knuckles (adult hand breadth).
const PALM_POLYGON: [[f32; 2]; 6] = [
    [-0.016, -0.005],
    [0.020, -0.005],
    [0.033, 0.040],
    [0.036, 0.074],
    [-0.020, 0.088],
    [-0.026, 0.045],
];

/// Wrist stub: a capsule across the wrist (ends, radius), metres; ~6 cm wide, 3.6 cm thick,
/// ending ~3.3 cm proximal of the wrist joint centre.
const WRIST_STUB: ([f32; 3], [f32; 3], f32) =
    ([-0.010, -0.015, -0.002], [0.014, -0.015, -0.002], 0.018);

/// Digit radii at the CMC, MCP, PIP (thumb: IP), DIP and tip of an average finger, metres. The
/// per-digit scale [`digit_scale`] adjusts them.
const FINGER_RADII: [f32; 5] = [0.0080, 0.0100, 0.0090, 0.0080, 0.0072];

/// Thumb radii at the CMC (the thenar eminence), MCP, IP and tip, metres.
const THUMB_RADII: [f32; 4] = [0.0140, 0.0115, 0.0100, 0.0085];

/// Relative thickness of each finger (middle thickest, little thinnest).
fn digit_scale(digit: Digit) -> f32 {
    match digit {
        Digit::Thumb => 1.0,
        Digit::Index => 1.0,
        Digit::Middle => 1.03,
        Digit::Ring => 0.96,
        Digit::Little => 0.86,
    }
}

/// Errors of this module.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    /// The grid spacing is not a positive finite number, or gives an unreasonably large grid.
    #[error("grid spacing {spacing} m is invalid or gives too many grid points ({points})")]
    BadSpacing {
        /// The requested spacing, metres.
        spacing: f32,
        /// Number of grid points it would need.
        points: u64,
    },
    /// Every grid offset tried gave a surface that is not a closed manifold.
    #[error(
        "surface nets gave a non-manifold surface at spacing {spacing} m for every grid offset tried"
    )]
    NonManifold {
        /// The grid spacing, metres.
        spacing: f32,
    },
}

/// Polynomial smooth minimum (Quílez, "smooth minimum", quadratic variant): equals `min(a, b)`
/// when `|a - b| >= k`, otherwise dips below it by at most `k / 4`. C1, and its gradient is a
/// convex combination of those of `a` and `b`, so it stays 1-Lipschitz.
fn smin(a: f32, b: f32, k: f32) -> f32 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

/// A sphere swept along the segment `a..b` with a radius varying linearly from `ra` to `rb`
/// (the convex hull of the two end spheres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoundCone {
    /// Start point, metres.
    pub a: Vec3,
    /// End point, metres.
    pub b: Vec3,
    /// Radius at `a`, metres.
    pub ra: f32,
    /// Radius at `b`, metres.
    pub rb: f32,
}

impl RoundCone {
    /// Exact signed distance (Quílez, "distance functions", round cone): the nearest point is
    /// on sphere `a`, sphere `b`, or the tangent cone between them, decided by comparing the
    /// point's angle to the cone's half-angle, with one square root.
    pub fn distance(&self, p: Vec3) -> f32 {
        let ba = self.b - self.a;
        let l2 = ba.length_squared();
        if l2 <= f32::EPSILON * f32::EPSILON {
            return (p - self.a).length() - self.ra.max(self.rb);
        }
        let rr = self.ra - self.rb;
        let a2 = l2 - rr * rr;
        let il2 = 1.0 / l2;
        let pa = p - self.a;
        let y = pa.dot(ba);
        let z = y - l2;
        let x2 = (pa * l2 - ba * y).length_squared();
        let y2 = y * y * l2;
        let z2 = z * z * l2;
        let k = rr.signum() * rr * rr * x2;
        if z.signum() * a2 * z2 > k {
            return (x2 + z2).sqrt() * il2 - self.rb;
        }
        if y.signum() * a2 * y2 < k {
            return (x2 + y2).sqrt() * il2 - self.ra;
        }
        ((x2 * a2 * il2).sqrt() + y * rr) * il2 - self.ra
    }
}

/// Most cones in one digit (CMC->MCP, MCP->PIP, PIP->DIP, DIP->tip).
const MAX_CONES: usize = 4;

/// The signed distance function of the rest (flat) hand; negative inside. See the module docs.
#[derive(Clone, Debug, PartialEq)]
pub struct HandSdf {
    /// Per digit, its cones from the CMC outwards; `cone_count[d]` of them are used.
    cones: [[RoundCone; MAX_CONES]; 5],
    cone_count: [usize; 5],
    /// The palm polygon (mid-plane, x/y), its plane height and half thickness.
    palm: [Vec2; PALM_POLYGON.len()],
    palm_z: f32,
    palm_radius: f32,
    /// The wrist stub capsule.
    wrist: RoundCone,
    /// Smooth-minimum blend radius.
    blend: f32,
}

impl Default for HandSdf {
    fn default() -> Self {
        HandSdf::adult_right()
    }
}

impl HandSdf {
    /// The SDF of [`HandSkeleton::adult_right`] in the flat pose.
    pub fn adult_right() -> Self {
        HandSdf::from_skeleton(&HandSkeleton::adult_right())
    }

    /// The SDF of `skeleton` in [`HandPose::FLAT`]. The palm and wrist geometry are fixed
    /// (sized for the adult skeleton); the digits follow the skeleton.
    pub fn from_skeleton(skeleton: &HandSkeleton) -> Self {
        let posed = skeleton.pose(&HandPose::FLAT);
        let empty = RoundCone {
            a: Vec3::ZERO,
            b: Vec3::ZERO,
            ra: 0.0,
            rb: 0.0,
        };
        let mut cones = [[empty; MAX_CONES]; 5];
        let mut cone_count = [0; 5];
        for digit in Digit::ALL {
            let chain = posed.chain(digit);
            let s = digit_scale(digit);
            let radii: &[f32] = match digit {
                Digit::Thumb => &THUMB_RADII,
                _ => &FINGER_RADII,
            };
            // chain = wrist, CMC, ..., tip: one cone per bone from the CMC on.
            let joints = &chain[1..];
            let n = joints.len() - 1;
            for k in 0..n {
                let ra = radii[k] * s;
                let rb = radii[k + 1] * s;
                let a = joints[k].position;
                let mut b = joints[k + 1].position;
                if k + 1 == n {
                    // End the pulp at the skeleton tip, not one radius beyond it.
                    b -= joints[k].axis() * rb;
                }
                cones[digit.index()][k] = RoundCone { a, b, ra, rb };
            }
            cone_count[digit.index()] = n;
        }
        let (wa, wb, wr) = WRIST_STUB;
        HandSdf {
            cones,
            cone_count,
            palm: PALM_POLYGON.map(Vec2::from),
            palm_z: PALM_MID_Z,
            palm_radius: PALM_HALF_THICKNESS,
            wrist: RoundCone {
                a: Vec3::from(wa),
                b: Vec3::from(wb),
                ra: wr,
                rb: wr,
            },
            blend: BLEND_RADIUS,
        }
    }

    /// The cones of one digit, from the CMC outwards.
    pub fn cones(&self, digit: Digit) -> &[RoundCone] {
        &self.cones[digit.index()][..self.cone_count[digit.index()]]
    }

    /// Signed distance of the palm slab: distance to the flat polygon minus the half thickness.
    fn palm_distance(&self, p: Vec3) -> f32 {
        let q = Vec2::new(p.x, p.y);
        let mut d2 = f32::INFINITY;
        let mut inside = false;
        let n = self.palm.len();
        for i in 0..n {
            let a = self.palm[i];
            let b = self.palm[(i + 1) % n];
            let e = b - a;
            let t = ((q - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
            d2 = d2.min((q - a - e * t).length_squared());
            // Even-odd crossing test of the ray +X from q.
            if (a.y > q.y) != (b.y > q.y) && q.x < a.x + (q.y - a.y) / (b.y - a.y) * e.x {
                inside = !inside;
            }
        }
        let planar = if inside { 0.0 } else { d2 };
        let dz = p.z - self.palm_z;
        (planar + dz * dz).sqrt() - self.palm_radius
    }

    /// Signed distance (metres, negative inside) of the rest hand at `p`; 1-Lipschitz.
    pub fn distance(&self, p: Vec3) -> f32 {
        let body = smin(self.palm_distance(p), self.wrist.distance(p), self.blend);
        let mut d = body;
        for digit in Digit::ALL {
            let dd = self
                .cones(digit)
                .iter()
                .map(|c| c.distance(p))
                .fold(f32::INFINITY, f32::min);
            d = d.min(smin(body, dd, self.blend));
        }
        d
    }

    /// Gradient of [`HandSdf::distance`] by central differences with step `eps` metres (unit
    /// length almost everywhere, outward on the surface).
    pub fn gradient(&self, p: Vec3, eps: f32) -> Vec3 {
        let dx = Vec3::X * eps;
        let dy = Vec3::Y * eps;
        let dz = Vec3::Z * eps;
        Vec3::new(
            self.distance(p + dx) - self.distance(p - dx),
            self.distance(p + dy) - self.distance(p - dy),
            self.distance(p + dz) - self.distance(p - dz),
        ) / (2.0 * eps)
    }

    /// An axis-aligned box `(min, max)` containing the whole solid (every piece's bounds grown
    /// by the blend radius, which bounds how far the smooth minimum can grow the union).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let mut add = |c: Vec3, r: f32| {
            lo = lo.min(c - Vec3::splat(r));
            hi = hi.max(c + Vec3::splat(r));
        };
        for digit in Digit::ALL {
            for c in self.cones(digit) {
                add(c.a, c.ra);
                add(c.b, c.rb);
            }
        }
        add(self.wrist.a, self.wrist.ra);
        add(self.wrist.b, self.wrist.rb);
        for v in self.palm {
            add(v.extend(self.palm_z), self.palm_radius);
        }
        (lo - Vec3::splat(self.blend), hi + Vec3::splat(self.blend))
    }
}

/// The two mesh resolutions of the rest hand (issue 4: base ≈ 8K vertices, detailed ≥ 150K).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Resolution {
    /// About 9.5K vertices (6K..10K): two Loop subdivision levels then give ≥ 150K (issue 5).
    Base,
    /// At least 150K vertices.
    Detailed,
}

impl Resolution {
    /// Grid spacing, metres. Surface Nets gives about one vertex per grid cell the surface
    /// crosses, so the count scales as `1 / spacing²`; these values were measured to give 9,458
    /// and 180,460 vertices on [`HandSdf::adult_right`].
    pub const fn spacing(self) -> f32 {
        match self {
            Resolution::Base => 0.00252,
            Resolution::Detailed => 0.00058,
        }
    }
}

/// A polygonised rest hand surface.
#[derive(Clone, Debug, PartialEq)]
pub struct HandSurface {
    /// The closed, manifold, outward-oriented triangle mesh (metres, skeleton frame).
    pub mesh: Mesh,
    /// The grid spacing it was built at, metres.
    pub spacing: f32,
}

/// Taubin smoothing steps (each one λ pass and one μ pass).
const TAUBIN_STEPS: usize = 4;
/// Taubin λ (shrink) and μ (inflate) factors: the classic 0.5 / -0.53 pair, pass band ~0.1.
const TAUBIN_LAMBDA: f32 = 0.5;
const TAUBIN_MU: f32 = -0.53;
/// Newton projection steps onto the zero set after smoothing.
const PROJECTION_STEPS: usize = 3;
/// Rounds of local relaxation of folded triangles after projection.
const REPAIR_ROUNDS: usize = 5;
/// Side of the narrow-band blocks, in cells.
const BLOCK: usize = 4;
/// Most grid points accepted (≈ 1.6 GB of field + cell index), a guard against a tiny spacing.
const MAX_GRID_POINTS: u64 = 200_000_000;
/// Grid offsets tried, in cells, when a build is not manifold.
const GRID_OFFSETS: [f32; 4] = [0.0, 0.37, 0.61, 0.19];

impl HandSurface {
    /// The adult right rest hand ([`HandSdf::adult_right`]) at `resolution`.
    pub fn build(resolution: Resolution) -> Result<HandSurface, SurfaceError> {
        HandSurface::build_from(&HandSdf::adult_right(), resolution.spacing())
    }

    /// Polygonise `sdf` on a grid of `spacing` metres, smooth, project (module docs). Returns
    /// a closed, edge- and vertex-manifold mesh whose every triangle faces along the SDF
    /// gradient (outward), with no triangle of near-zero area.
    pub fn build_from(sdf: &HandSdf, spacing: f32) -> Result<HandSurface, SurfaceError> {
        for offset in GRID_OFFSETS {
            let mut mesh = surface_nets(sdf, spacing, offset)?;
            if !is_closed_manifold(&mesh) {
                continue;
            }
            smooth_and_project(&mut mesh, sdf, spacing);
            if has_degenerate(&mesh, spacing)
                || !folded_vertices(&mesh, sdf, 0.05 * spacing).is_empty()
            {
                continue;
            }
            return Ok(HandSurface { mesh, spacing });
        }
        Err(SurfaceError::NonManifold { spacing })
    }
}

/// A regular grid of SDF samples over the SDF's bounds.
struct Grid {
    origin: Vec3,
    h: f32,
    n: [usize; 3],
    values: Vec<f32>,
}

impl Grid {
    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.n[0] * (j + self.n[1] * k)
    }

    fn point(&self, i: usize, j: usize, k: usize) -> Vec3 {
        self.origin + Vec3::new(i as f32, j as f32, k as f32) * self.h
    }

    /// Samples `sdf` exactly within the narrow band and by block sign elsewhere (module docs).
    fn sample(sdf: &HandSdf, h: f32, offset: f32) -> Result<Grid, SurfaceError> {
        let bad = |points| SurfaceError::BadSpacing { spacing: h, points };
        if !(h.is_finite() && h > 0.0) {
            return Err(bad(0));
        }
        let (lo, hi) = sdf.bounds();
        // Two cells of padding, so the grid border is outside and every sign-changing edge
        // has its four cells.
        let origin = lo - Vec3::splat(2.0 * h) - Vec3::splat(offset * h);
        let cells = ((hi + Vec3::splat(2.0 * h) - origin) / h).ceil();
        let n = [
            cells.x as usize + 1,
            cells.y as usize + 1,
            cells.z as usize + 1,
        ];
        let points = n.iter().map(|&x| x as u64).product::<u64>();
        if points > MAX_GRID_POINTS {
            return Err(bad(points));
        }
        let mut grid = Grid {
            origin,
            h,
            n,
            values: vec![f32::NAN; points as usize],
        };
        // Exact samples are needed only where |f| <= h (the ends of sign-changing edges); by
        // 1-Lipschitz continuity a block whose centre value exceeds its half-diagonal plus
        // one cell holds no such point and has one sign throughout.
        let half_diag = 0.5 * (BLOCK as f32) * h * 3f32.sqrt();
        let mut exact = vec![false; points as usize];
        let blocks = n.map(|x| (x - 1).div_ceil(BLOCK));
        for bk in 0..blocks[2] {
            for bj in 0..blocks[1] {
                for bi in 0..blocks[0] {
                    let start = [bi * BLOCK, bj * BLOCK, bk * BLOCK];
                    let end = [
                        (start[0] + BLOCK).min(n[0] - 1),
                        (start[1] + BLOCK).min(n[1] - 1),
                        (start[2] + BLOCK).min(n[2] - 1),
                    ];
                    let centre = grid.origin
                        + Vec3::new(
                            (start[0] + end[0]) as f32,
                            (start[1] + end[1]) as f32,
                            (start[2] + end[2]) as f32,
                        ) * (0.5 * h);
                    let fc = sdf.distance(centre);
                    let far = fc.abs() > (half_diag + h) * 1.01;
                    for k in start[2]..=end[2] {
                        for j in start[1]..=end[1] {
                            for i in start[0]..=end[0] {
                                let idx = grid.index(i, j, k);
                                if far {
                                    if !exact[idx] {
                                        grid.values[idx] = fc;
                                    }
                                } else if !exact[idx] {
                                    grid.values[idx] = sdf.distance(grid.point(i, j, k));
                                    exact[idx] = true;
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(grid)
    }
}

/// Naive Surface Nets on `sdf` at spacing `h`, grid shifted by `offset` cells (module docs).
fn surface_nets(sdf: &HandSdf, h: f32, offset: f32) -> Result<Mesh, SurfaceError> {
    let grid = Grid::sample(sdf, h, offset)?;
    let [nx, ny, nz] = grid.n;
    let (cx, cy) = (nx - 1, ny - 1);
    let cell_index = |i: usize, j: usize, k: usize| i + cx * (j + cy * k);
    let mut cell_vertex = vec![u32::MAX; cx * cy * (nz - 1)];
    let mut positions = Vec::new();
    // The 8 corners of a cell, as (di, dj, dk) bits, and its 12 edges as corner pairs.
    const CORNERS: [[usize; 3]; 8] = [
        [0, 0, 0],
        [1, 0, 0],
        [0, 1, 0],
        [1, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [0, 1, 1],
        [1, 1, 1],
    ];
    const EDGES: [[usize; 2]; 12] = [
        [0, 1],
        [2, 3],
        [4, 5],
        [6, 7],
        [0, 2],
        [1, 3],
        [4, 6],
        [5, 7],
        [0, 4],
        [1, 5],
        [2, 6],
        [3, 7],
    ];
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let mut f = [0f32; 8];
                let mut inside = 0;
                for (c, corner) in CORNERS.iter().enumerate() {
                    f[c] = grid.values[grid.index(i + corner[0], j + corner[1], k + corner[2])];
                    if f[c] < 0.0 {
                        inside += 1;
                    }
                }
                if inside == 0 || inside == 8 {
                    continue;
                }
                let mut sum = Vec3::ZERO;
                let mut count = 0;
                for [a, b] in EDGES {
                    if (f[a] < 0.0) != (f[b] < 0.0) {
                        let t = f[a] / (f[a] - f[b]);
                        let pa = Vec3::from(CORNERS[a].map(|x| x as f32));
                        let pb = Vec3::from(CORNERS[b].map(|x| x as f32));
                        sum += pa + (pb - pa) * t;
                        count += 1;
                    }
                }
                cell_vertex[cell_index(i, j, k)] = positions.len() as u32;
                positions.push(grid.point(i, j, k) + sum / count as f32 * h);
            }
        }
    }
    let mut triangles = Vec::with_capacity(positions.len() * 2);
    // A sign-changing edge along axis `a` from grid point (i, j, k) is shared by the four cells
    // offset by -1/0 along the other two axes u = a+1, v = a+2 (cyclic). Listed as
    // (u,v) = (-,-), (0,-), (0,0), (-,0) they run counter-clockwise seen from +a, so the quad's
    // normal is +a: right when the edge goes from inside to outside, reversed otherwise.
    for k in 1..nz - 1 {
        for j in 1..ny - 1 {
            for i in 1..nx - 1 {
                let p = [i, j, k];
                let f0 = grid.values[grid.index(i, j, k)];
                for a in 0..3 {
                    let mut q = p;
                    q[a] += 1;
                    if q[a] >= grid.n[a] {
                        continue;
                    }
                    let f1 = grid.values[grid.index(q[0], q[1], q[2])];
                    if (f0 < 0.0) == (f1 < 0.0) {
                        continue;
                    }
                    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
                    let mut quad = [0u32; 4];
                    for (slot, (du, dv)) in [(1, 1), (0, 1), (0, 0), (1, 0)].into_iter().enumerate()
                    {
                        let mut c = p;
                        c[u] -= du;
                        c[v] -= dv;
                        quad[slot] = cell_vertex[cell_index(c[0], c[1], c[2])];
                    }
                    if f0 >= 0.0 {
                        quad.reverse();
                    }
                    let [v0, v1, v2, v3] = quad;
                    let pos = |x: u32| positions[x as usize];
                    let d02 = pos(v0).distance_squared(pos(v2));
                    let d13 = pos(v1).distance_squared(pos(v3));
                    if d02 <= d13 {
                        triangles.push([v0, v1, v2]);
                        triangles.push([v0, v2, v3]);
                    } else {
                        triangles.push([v1, v2, v3]);
                        triangles.push([v1, v3, v0]);
                    }
                }
            }
        }
    }
    Ok(Mesh {
        positions,
        triangles,
    })
}

/// Taubin smoothing (uniform Laplacian), then Newton projection onto the zero set.
fn smooth_and_project(mesh: &mut Mesh, sdf: &HandSdf, h: f32) {
    let adjacency = mesh.vertex_adjacency();
    let mut next = mesh.positions.clone();
    for step in 0..2 * TAUBIN_STEPS {
        let factor = if step % 2 == 0 {
            TAUBIN_LAMBDA
        } else {
            TAUBIN_MU
        };
        for (v, out) in next.iter_mut().enumerate() {
            let nb = adjacency.neighbors(v);
            let p = mesh.positions[v];
            if nb.is_empty() {
                *out = p;
                continue;
            }
            let mean =
                nb.iter().map(|&w| mesh.positions[w as usize]).sum::<Vec3>() / nb.len() as f32;
            *out = p + (mean - p) * factor;
        }
        std::mem::swap(&mut mesh.positions, &mut next);
    }
    let eps = 0.05 * h;
    for p in &mut mesh.positions {
        *p = project(sdf, *p, eps);
    }
    // Projection can fold a triangle where the surface bends sharply within a cell (the web
    // crotches); relax the corners of folded triangles to their neighbours' mean and project
    // again.
    for _ in 0..REPAIR_ROUNDS {
        let folded = folded_vertices(mesh, sdf, eps);
        if folded.is_empty() {
            break;
        }
        for v in folded {
            let nb = adjacency.neighbors(v);
            let mean =
                nb.iter().map(|&w| mesh.positions[w as usize]).sum::<Vec3>() / nb.len() as f32;
            mesh.positions[v] = project(sdf, mean, eps);
        }
    }
}

/// `p` moved onto the zero set by Newton steps along the gradient.
fn project(sdf: &HandSdf, mut p: Vec3, eps: f32) -> Vec3 {
    for _ in 0..PROJECTION_STEPS {
        let f = sdf.distance(p);
        let g = sdf.gradient(p, eps);
        let g2 = g.length_squared();
        if g2 > 1e-12 {
            p -= g * (f / g2);
        }
    }
    p
}

/// Corners (sorted, unique) of the triangles whose normal does not agree with the SDF gradient
/// at their centroid.
fn folded_vertices(mesh: &Mesh, sdf: &HandSdf, eps: f32) -> Vec<usize> {
    let mut out: Vec<usize> = mesh
        .triangles
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            (b - a)
                .cross(c - a)
                .dot(sdf.gradient((a + b + c) / 3.0, eps))
                <= 0.0
        })
        .flat_map(|t| t.map(|i| i as usize))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Whether some triangle has (almost) no area: less than a thousandth of a grid cell face.
fn has_degenerate(mesh: &Mesh, h: f32) -> bool {
    let min_double_area = 2e-3 * h * h;
    mesh.triangles.iter().any(|t| {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        (b - a).cross(c - a).length() < min_double_area
    })
}

/// Closed and manifold: every directed edge appears once and its reverse once (so every edge
/// has two triangles, oppositely oriented), and the triangles around each vertex form a single
/// fan (no pinched vertices).
fn is_closed_manifold(mesh: &Mesh) -> bool {
    let mut directed: Vec<(u32, u32)> = Vec::with_capacity(mesh.triangles.len() * 3);
    for t in &mesh.triangles {
        for e in 0..3 {
            directed.push((t[e], t[(e + 1) % 3]));
        }
    }
    directed.sort_unstable();
    if directed.windows(2).any(|w| w[0] == w[1]) {
        return false;
    }
    if directed
        .iter()
        .any(|&(a, b)| a == b || directed.binary_search(&(b, a)).is_err())
    {
        return false;
    }
    // One fan per vertex: following "next edge" (a->b then the triangle with b->... around a)
    // from one outgoing edge must visit all of the vertex's outgoing edges.
    let n = mesh.positions.len();
    let mut start = vec![0usize; n + 1];
    for &(a, _) in &directed {
        start[a as usize + 1] += 1;
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    // Map each outgoing edge a->b to the third vertex c of its triangle (a, b, c); the next
    // outgoing edge of a around its fan is a->c (it exists: the twin of c->a).
    let mut third = vec![u32::MAX; directed.len()];
    for t in &mesh.triangles {
        for e in 0..3 {
            let (a, b, c) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
            let slot = &directed[start[a as usize]..start[a as usize + 1]];
            if let Ok(pos) = slot.binary_search(&(a, b)) {
                third[start[a as usize] + pos] = c;
            }
        }
    }
    for v in 0..n {
        let slot = &directed[start[v]..start[v + 1]];
        if slot.is_empty() {
            return false;
        }
        let mut b = slot[0].1;
        let mut seen = 0;
        loop {
            let Ok(pos) = slot.binary_search(&(v as u32, b)) else {
                return false;
            };
            b = third[start[v] + pos];
            seen += 1;
            if b == slot[0].1 || seen > slot.len() {
                break;
            }
        }
        if seen != slot.len() {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_cone_matches_capsule_and_spheres() {
        let c = RoundCone {
            a: Vec3::ZERO,
            b: Vec3::Y,
            ra: 0.2,
            rb: 0.2,
        };
        assert!((c.distance(Vec3::new(1.0, 0.5, 0.0)) - 0.8).abs() < 1e-6);
        assert!((c.distance(Vec3::new(0.0, 2.0, 0.0)) - 0.8).abs() < 1e-6);
        let t = RoundCone {
            a: Vec3::ZERO,
            b: Vec3::Y,
            ra: 0.3,
            rb: 0.1,
        };
        // Beyond the small end: distance to sphere b.
        assert!((t.distance(Vec3::new(0.0, 3.0, 0.0)) - 1.9).abs() < 1e-5);
        // Beyond the big end: distance to sphere a.
        assert!((t.distance(Vec3::new(0.0, -2.0, 0.0)) - 1.7).abs() < 1e-5);
        // Centre of the big sphere: -ra.
        assert!((t.distance(Vec3::ZERO) + 0.3).abs() < 1e-5);
    }

    #[test]
    fn round_cone_side_distance_matches_brute_force() {
        let t = RoundCone {
            a: Vec3::new(0.1, -0.2, 0.3),
            b: Vec3::new(0.4, 0.9, -0.1),
            ra: 0.25,
            rb: 0.08,
        };
        // The round cone is the union of spheres along the segment with interpolated radius:
        // its exact distance outside is min over s of |p - c(s)| - r(s).
        for p in [
            Vec3::new(1.0, 0.3, 0.2),
            Vec3::new(-0.5, 0.0, 0.0),
            Vec3::new(0.3, 1.5, 0.4),
        ] {
            let brute = (0..=20_000)
                .map(|i| {
                    let s = i as f32 / 20_000.0;
                    (p - t.a.lerp(t.b, s)).length() - (t.ra + (t.rb - t.ra) * s)
                })
                .fold(f32::INFINITY, f32::min);
            assert!(
                (t.distance(p) - brute).abs() < 1e-4,
                "{p}: {} vs {brute}",
                t.distance(p)
            );
        }
    }

    #[test]
    fn pinched_vertex_is_not_manifold() {
        // Two tetrahedra sharing one vertex: every edge is fine, the shared vertex is not.
        let tet = |o: u32| {
            [
                [o, o + 2, o + 1],
                [o, o + 1, o + 3],
                [o + 1, o + 2, o + 3],
                [o, o + 3, o + 2],
            ]
        };
        let mut positions = vec![Vec3::ZERO; 7];
        for (i, p) in positions.iter_mut().enumerate() {
            *p = Vec3::splat(i as f32);
        }
        let mut triangles: Vec<[u32; 3]> = tet(0).to_vec();
        assert!(is_closed_manifold(&Mesh {
            positions: positions[..4].to_vec(),
            triangles: triangles.clone(),
        }));
        triangles.extend(tet(3));
        assert!(!is_closed_manifold(&Mesh {
            positions,
            triangles,
        }));
    }
}
