//! Automatic control points (FKY08 §3, after Meyer & Anderson 2007): PCA of the examples'
//! vertex positions, varimax rotation of the loadings into localised components, and two
//! representative vertices per component.
//!
//! Steps ([`auto_control_points_with`]):
//!
//! 1. **PCA.** The data matrix `D` (`n` examples x `3V` coordinates) minus the mean shape. Its
//!    principal directions come from the small `n x n` Gram matrix `D D^T = U L U^T`; the
//!    loadings are `D^T U` (`3V x r`, column `k` = `sqrt(l_k)` times the `k`-th principal
//!    direction). `r` is the smallest count explaining
//!    [`ControlOptions::variance_fraction`] of the variance, raised to `ceil(count / 2)` so two
//!    points per component can fill `count`, and capped at the rank.
//! 2. **Varimax** (Kaiser 1958), the standard SVD iteration: rotate the loadings by the
//!    orthogonal `R` maximising the variance of the squared loadings per component, so each
//!    rotated component moves one region. No Kaiser row normalisation: a static vertex has
//!    (almost) zero communality, and normalising it would give its noise the weight of real
//!    motion.
//! 3. **Representatives** ("two representative points with largest differences", FKY08 §3). The
//!    rotated component `k` moves vertex `v` by the 3-vector `(l_3v, l_3v+1, l_3v+2)`; its length
//!    `m_k(v)` is how strongly `v` takes part. Components are visited in order of rotated
//!    variance (largest first), in two rounds; each visit picks the component's vertex of
//!    largest `m_k` among those at least [`ControlOptions::min_separation`] (rest pose, Euclidean)
//!    from every point chosen so far. Round one so takes each component's peak, round two its
//!    strongest vertex away from the peak: two points spanning what the component moves rather
//!    than two neighbours, and no second point on a feature another component already holds. A
//!    candidate must carry at least [`ControlOptions::min_relative_loading`] of its component's
//!    largest `m_k` (else it does not represent the component). Ties go to the lower vertex
//!    index. Rounds stop once `count` points are chosen.
//! 4. **Fill.** If the components yield fewer than `count` points, the rest are the vertices of
//!    largest displacement variance across the examples, at least the separation from every
//!    chosen point; the separation halves until enough qualify (finally 0), so `count <= V`
//!    always succeeds.
//!
//! FKY08 then lets a user pick among the representatives near one semantic feature; the minimum
//! separation plays that part automatically. Everything is deterministic: the result depends only
//! on the input, in order of selection.

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use nalgebra::DMatrix;

use crate::par;

/// Options of [`auto_control_points_with`].
#[derive(Clone, Debug, PartialEq)]
pub struct ControlOptions {
    /// Number of control points `n_c` (FKY08 Table 1: 2 to 8).
    pub count: usize,
    /// Fraction of the examples' variance the kept principal components explain. 0.95 keeps the
    /// components that matter and drops the tail, where noise would get its own representative.
    pub variance_fraction: f64,
    /// Minimum rest-pose distance between any two chosen points (relaxed only when filling), as
    /// a fraction of the rest pose's largest bounding-box side. 5% keeps
    /// two points off one feature (FKY08 §3 has a user choose one of several points near the same
    /// feature) while a finger or a hoof is still long enough to hold two.
    pub min_separation: f32,
    /// Smallest loading magnitude a representative may have, as a fraction of its component's
    /// largest: below a tenth, a vertex barely moves with the component and does not represent
    /// it.
    pub min_relative_loading: f64,
    /// Cap on varimax iterations (it usually converges in well under 50).
    pub varimax_iterations: usize,
    /// Varimax stops when its criterion grows by less than this fraction per iteration.
    pub varimax_tolerance: f64,
}

impl Default for ControlOptions {
    fn default() -> Self {
        Self {
            count: 8,
            variance_fraction: 0.95,
            min_separation: 0.05,
            min_relative_loading: 0.1,
            varimax_iterations: 200,
            varimax_tolerance: 1e-10,
        }
    }
}

/// Why control points could not be chosen.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// `count` is 0 or more than the vertices.
    #[error("control point count must be in 1..={vertices}, got {count}")]
    BadCount {
        /// Requested count.
        count: usize,
        /// Vertices of the mesh.
        vertices: usize,
    },
    /// PCA needs at least two shapes (the rest pose among them).
    #[error("need at least 2 frames (the rest pose among them), got {0}")]
    TooFewFrames(usize),
    /// A frame's vertex count differs from the rest mesh.
    #[error("frame {frame}: {got} vertices, the rest mesh has {expected}")]
    VertexCount {
        /// Frame index.
        frame: usize,
        /// Rest mesh vertex count.
        expected: usize,
        /// The frame's vertex count.
        got: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("frame {frame}, vertex {vertex}: non-finite coordinate")]
    NonFinite {
        /// Frame index.
        frame: usize,
        /// Vertex index.
        vertex: usize,
    },
    /// Every frame has the same shape: there is no deformation to control.
    #[error("the frames do not differ: no deformation to place control points on")]
    NoMotion,
    /// An option is out of range.
    #[error("invalid option {field}: {reason}")]
    InvalidOption {
        /// Field of [`ControlOptions`].
        field: &'static str,
        /// What is wrong with it.
        reason: &'static str,
    },
}

/// `count` control vertices chosen automatically from example frames (FKY08 §3), with default
/// [`ControlOptions`]. `frames` are all example shapes, the rest pose included, in the rest
/// mesh's vertex order.
pub fn auto_control_points(
    rest: &Mesh,
    frames: &[&[Vec3]],
    count: usize,
) -> Result<Vec<u32>, ControlError> {
    auto_control_points_with(
        rest,
        frames,
        &ControlOptions {
            count,
            ..ControlOptions::default()
        },
    )
}

/// Control vertices by PCA, varimax and two representatives per component (FKY08 §3; the
/// module docs give the exact rule), distinct, in order of selection.
pub fn auto_control_points_with(
    rest: &Mesh,
    frames: &[&[Vec3]],
    opts: &ControlOptions,
) -> Result<Vec<u32>, ControlError> {
    let nv = rest.vertex_count();
    check_input(nv, frames, opts)?;
    let n = frames.len();

    // Step 1: centred data, Gram matrix, principal components (FKY08 §3 PCA).
    let mean: Vec<Vec3> = (0..nv)
        .map(|v| frames.iter().map(|f| f[v]).sum::<Vec3>() / n as f32)
        .collect();
    let d = DMatrix::<f64>::from_fn(n, 3 * nv, |t, c| {
        f64::from(frames[t][c / 3][c % 3]) - f64::from(mean[c / 3][c % 3])
    });
    let gram = gram_rows(&d);
    let eig = gram.symmetric_eigen();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| {
        eig.eigenvalues[j]
            .total_cmp(&eig.eigenvalues[i])
            .then(i.cmp(&j))
    });
    let top = eig.eigenvalues[order[0]];
    // Same relative rank cut as the kernel CCA (f64 eigen noise is ~n * 1e-16 of the top).
    let rank = order
        .iter()
        .take_while(|&&i| top > 0.0 && eig.eigenvalues[i] > 1e-10 * top)
        .count();
    if rank == 0 {
        return Err(ControlError::NoMotion);
    }
    let total: f64 = order[..rank].iter().map(|&i| eig.eigenvalues[i]).sum();
    let mut explained = 0.0;
    let r_var = order[..rank]
        .iter()
        .position(|&i| {
            explained += eig.eigenvalues[i];
            explained >= opts.variance_fraction * total
        })
        .map_or(rank, |k| k + 1);
    let r = r_var.max(opts.count.div_ceil(2)).min(rank);
    let u = DMatrix::from_fn(n, r, |t, k| eig.eigenvectors[(t, order[k])]);
    let loadings = d.transpose() * u;

    // Step 2: varimax (Kaiser 1958).
    let rotation = varimax(&loadings, opts.varimax_iterations, opts.varimax_tolerance);
    let rotated = loadings * rotation;

    // Step 3: representatives per rotated component, by rotated variance.
    let magnitudes: Vec<Vec<f64>> = (0..r)
        .map(|k| {
            let col = rotated.column(k);
            (0..nv)
                .map(|v| {
                    (col[3 * v].powi(2) + col[3 * v + 1].powi(2) + col[3 * v + 2].powi(2)).sqrt()
                })
                .collect()
        })
        .collect();
    let variance: Vec<f64> = (0..r).map(|k| rotated.column(k).norm_squared()).collect();
    let mut components: Vec<usize> = (0..r).collect();
    components.sort_by(|&a, &b| variance[b].total_cmp(&variance[a]).then(a.cmp(&b)));
    let scale = rest.bbox_diagonal_scale();
    let min_sep = opts.min_separation * scale;
    let mut chosen: Vec<u32> = Vec::with_capacity(opts.count);
    let far_enough = |chosen: &[u32], v: usize, sep: f32| {
        chosen
            .iter()
            .all(|&c| rest.positions[c as usize].distance(rest.positions[v]) >= sep)
    };
    'rounds: for _round in 0..2 {
        for &k in &components {
            let m = &magnitudes[k];
            let peak = m.iter().copied().fold(0.0f64, f64::max);
            // Largest magnitude first, lower index on ties.
            let best = (0..nv)
                .filter(|&v| m[v] > 0.0 && m[v] >= opts.min_relative_loading * peak)
                .filter(|&v| !chosen.contains(&(v as u32)) && far_enough(&chosen, v, min_sep))
                .fold(None, |best: Option<usize>, v| match best {
                    Some(b) if m[b] >= m[v] => Some(b),
                    _ => Some(v),
                });
            if let Some(v) = best {
                chosen.push(v as u32);
                if chosen.len() == opts.count {
                    break 'rounds;
                }
            }
        }
    }

    // Step 4: fill by displacement variance with a relaxing separation.
    if chosen.len() < opts.count {
        let var: Vec<f64> = (0..nv)
            .map(|v| (0..3).map(|c| d.column(3 * v + c).norm_squared()).sum())
            .collect();
        let mut by_var: Vec<usize> = (0..nv).collect();
        by_var.sort_by(|&a, &b| var[b].total_cmp(&var[a]).then(a.cmp(&b)));
        let mut sep = min_sep;
        while chosen.len() < opts.count {
            for &v in &by_var {
                if chosen.len() == opts.count {
                    break;
                }
                if !chosen.contains(&(v as u32)) && far_enough(&chosen, v, sep) {
                    chosen.push(v as u32);
                }
            }
            // Below a millionth of the model's size any two vertices are "apart": stop halving.
            sep = if sep > 1e-6 * scale { sep / 2.0 } else { 0.0 };
        }
    }
    Ok(chosen)
}

/// The orthogonal `r x r` rotation `R` maximising the varimax criterion of `loadings * R`
/// (Kaiser 1958; the SVD iteration of e.g. R's `stats::varimax`, without row normalisation):
/// repeat `B = L^T (Λ^3 - Λ diag(1^T Λ^2) / p)`, `B = U S V^T`, `R = U V^T` with `Λ = L R`,
/// until `sum(S)` grows by less than `tolerance` (relative) or `max_iterations` is reached.
pub fn varimax(loadings: &DMatrix<f64>, max_iterations: usize, tolerance: f64) -> DMatrix<f64> {
    let (p, r) = loadings.shape();
    let mut rotation = DMatrix::<f64>::identity(r, r);
    if r < 2 || p == 0 {
        return rotation;
    }
    let mut criterion = 0.0;
    for _ in 0..max_iterations {
        let lambda = loadings * &rotation;
        let col_ss: Vec<f64> = (0..r).map(|k| lambda.column(k).norm_squared()).collect();
        let z = DMatrix::from_fn(p, r, |i, k| {
            let l = lambda[(i, k)];
            l * l * l - l * col_ss[k] / p as f64
        });
        let b = loadings.transpose() * z;
        let svd = b.svd(true, true);
        let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
            break;
        };
        rotation = u * v_t;
        let new = svd.singular_values.sum();
        if new <= criterion * (1.0 + tolerance) {
            break;
        }
        criterion = new;
    }
    rotation
}

/// `D D^T` for a wide `n x m` matrix, one row pair per task (the product is most of the PCA's
/// cost on a large mesh).
fn gram_rows(d: &DMatrix<f64>) -> DMatrix<f64> {
    let n = d.nrows();
    let pairs: Vec<(usize, usize)> = (0..n).flat_map(|i| (i..n).map(move |j| (i, j))).collect();
    let values = par::map_range(
        pairs.len(),
        || (),
        |_, k| {
            let (i, j) = pairs[k];
            d.row(i).dot(&d.row(j))
        },
    );
    let mut g = DMatrix::zeros(n, n);
    for (&(i, j), &v) in pairs.iter().zip(&values) {
        g[(i, j)] = v;
        g[(j, i)] = v;
    }
    g
}

/// Validates counts, shapes, finiteness and options.
fn check_input(nv: usize, frames: &[&[Vec3]], opts: &ControlOptions) -> Result<(), ControlError> {
    if opts.count == 0 || opts.count > nv {
        return Err(ControlError::BadCount {
            count: opts.count,
            vertices: nv,
        });
    }
    if frames.len() < 2 {
        return Err(ControlError::TooFewFrames(frames.len()));
    }
    for (frame, f) in frames.iter().enumerate() {
        if f.len() != nv {
            return Err(ControlError::VertexCount {
                frame,
                expected: nv,
                got: f.len(),
            });
        }
        if let Some(vertex) = f.iter().position(|p| !p.is_finite()) {
            return Err(ControlError::NonFinite { frame, vertex });
        }
    }
    if !(opts.variance_fraction > 0.0 && opts.variance_fraction <= 1.0) {
        return Err(ControlError::InvalidOption {
            field: "variance_fraction",
            reason: "must be in (0, 1]",
        });
    }
    if !(opts.min_separation.is_finite() && opts.min_separation >= 0.0) {
        return Err(ControlError::InvalidOption {
            field: "min_separation",
            reason: "must be finite and >= 0",
        });
    }
    if !(0.0..=1.0).contains(&opts.min_relative_loading) {
        return Err(ControlError::InvalidOption {
            field: "min_relative_loading",
            reason: "must be in [0, 1]",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Varimax criterion: sum over columns of the variance of the squared loadings.
    fn criterion(l: &DMatrix<f64>) -> f64 {
        let p = l.nrows() as f64;
        (0..l.ncols())
            .map(|k| {
                let sq: Vec<f64> = l.column(k).iter().map(|v| v * v).collect();
                let mean = sq.iter().sum::<f64>() / p;
                sq.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / p
            })
            .sum()
    }

    #[test]
    fn varimax_recovers_a_rotated_simple_structure() {
        // Simple structure: rows 0..4 load on factor 0 only, rows 4..8 on factor 1 only.
        let simple = DMatrix::from_fn(8, 2, |i, k| {
            if (i < 4) == (k == 0) {
                1.0 + 0.1 * i as f64
            } else {
                0.0
            }
        });
        let t = 0.6f64;
        let mixing = DMatrix::from_row_slice(2, 2, &[t.cos(), -t.sin(), t.sin(), t.cos()]);
        let mixed = &simple * &mixing;
        let r = varimax(&mixed, 100, 1e-12);
        // R is orthogonal, and undoes the mixing up to column sign and order.
        assert!((r.transpose() * &r - DMatrix::identity(2, 2)).norm() < 1e-10);
        let got = &mixed * &r;
        assert!(criterion(&got) >= criterion(&mixed));
        for k in 0..2 {
            let col = got.column(k);
            // The criterion is flat at its maximum: angle error ~ sqrt(tolerance).
            let zeros = (0..8).filter(|&i| col[i].abs() < 1e-4).count();
            assert_eq!(zeros, 4, "column {k} is not simple: {got}");
        }
    }

    #[test]
    fn varimax_of_one_column_is_identity() {
        let l = DMatrix::from_element(5, 1, 2.0);
        assert_eq!(varimax(&l, 10, 1e-9), DMatrix::identity(1, 1));
    }
}
