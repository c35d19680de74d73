//! [`HandCollider::build`]: everything computed once from the bound hand and its rest skin:
//! vertex classes, sphere arcs and radii, palm samples and their neighbours, the fold entries
//! and the vertex buckets of the cull.

use glam::Vec3;

use super::primitives::plane_normal;
use super::{
    Bucket, CollideError, CollisionSphere, FoldEntry, FoldPlane, HandCollider, MCP,
    MIN_WINDOW_VERTICES, Owner, PALM_BUCKET, PALM_NEIGHBOUR_OFFSET, PALM_REACH_FRACTION,
    PALM_SPACING, PALMAR_COS, PalmPlane, SPHERE_SPACING, SPHERE_START, SphereKind, TIP_INSET,
    VertexClass,
};
use crate::skeleton::{Digit, HandPose, MAX_CHAIN};
use crate::sweeps::{Sweep, SweepHand};
use crease_core::mesh::Mesh;

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
}
