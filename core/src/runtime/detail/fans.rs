//! The detail layer's vertex normals by one-ring gather ([`VertexFans`]) and by triangle
//! scatter ([`scatter_normals`]), and the plain displacement ([`displace`]).

use glam::{Vec3, Vec3A};

use super::{DetailError, PARALLEL_CHUNK, check_len};
use crate::mesh::topology::accumulate_face_normals;
use crate::runtime::fill_rows;
#[cfg(feature = "parallel")]
use crate::runtime::use_pool;

/// Separates the chains of one vertex's fan in [`VertexFans`].
const BREAK: u32 = u32::MAX;

/// For every vertex, the triangles around it as chains of their other corners, in CSR form:
/// consecutive entries `r_i`, `r_i+1` of a chain are the other two corners of one incident
/// triangle in its winding order (the triangle is `[v, r_i, r_i+1]` up to rotation), so
/// `(p[r_i] - p[v]) × (p[r_i+1] - p[v])` is its face normal with twice its area as length.
///
/// On an oriented manifold each vertex's triangles form one chain, closed (first entry repeated
/// at the end) inside and open on the boundary: `n` triangles take `n + 1` entries and every
/// neighbour is loaded once, where a list of triangles would load each twice. Triangles that do
/// not chain (inconsistent winding, several fans) are stored as further chains after a
/// separator, so any triangle list gives the same normals as [`scatter_normals`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VertexFans {
    offsets: Vec<u32>,
    chains: Vec<u32>,
}

impl VertexFans {
    /// Builds the fans of `vertex_count` vertices from `triangles`.
    ///
    /// # Panics
    /// If a triangle index is `>= vertex_count`, or there are 2³² or more corners.
    pub fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> VertexFans {
        // The incident triangles of every vertex as (b, c) pairs, in CSR.
        let mut start = vec![0u32; vertex_count + 1];
        for t in triangles {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            start[v + 1] += start[v];
        }
        let mut fill = start[..vertex_count].to_vec();
        let mut pairs = vec![[0u32; 2]; triangles.len() * 3];
        for &[a, b, c] in triangles {
            for (v, pair) in [(a, [b, c]), (b, [c, a]), (c, [a, b])] {
                pairs[fill[v as usize] as usize] = pair;
                fill[v as usize] += 1;
            }
        }
        // Chain them per vertex (valences are small: the quadratic scans cost nothing).
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let mut chains = Vec::with_capacity(pairs.len() + vertex_count);
        offsets.push(0u32);
        let mut used = Vec::new();
        for v in 0..vertex_count {
            let fan = &pairs[start[v] as usize..start[v + 1] as usize];
            used.clear();
            used.resize(fan.len(), false);
            let mut left = fan.len();
            while left > 0 {
                if chains.len() > *offsets.last().expect("starts with 0") as usize {
                    chains.push(BREAK);
                }
                // Open chains start at a pair whose first corner no other pair ends at.
                let unused = |i: &usize| !used[*i];
                let first = (0..fan.len())
                    .filter(unused)
                    .find(|&i| {
                        !(0..fan.len()).any(|j| !used[j] && j != i && fan[j][1] == fan[i][0])
                    })
                    .or_else(|| (0..fan.len()).find(unused))
                    .expect("left > 0");
                used[first] = true;
                left -= 1;
                chains.extend(fan[first]);
                let mut end = fan[first][1];
                while let Some(i) = (0..fan.len()).find(|&i| !used[i] && fan[i][0] == end) {
                    used[i] = true;
                    left -= 1;
                    end = fan[i][1];
                    chains.push(end);
                }
            }
            offsets.push(u32::try_from(chains.len()).expect("fewer than 2^32 corners"));
        }
        VertexFans { offsets, chains }
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Stored entries (neighbour indices and separators), the table's size in `u32`s.
    pub fn len(&self) -> usize {
        self.chains.len()
    }

    /// Whether no vertex has a triangle.
    pub fn is_empty(&self) -> bool {
        self.chains.is_empty()
    }

    /// Area-weighted unit vertex normals of `positions` into `out` (one per vertex). A vertex
    /// whose triangles have no area (or that has none) gets `Vec3::ZERO`, as in
    /// [`crate::mesh::compute_vertex_normals`]: a displacement along it is no displacement.
    pub fn normals<P>(&self, positions: &[P], out: &mut [Vec3]) -> Result<(), DetailError>
    where
        P: Copy + Into<Vec3A> + Sync,
    {
        let n = self.vertex_count();
        check_len("positions", n, positions.len())?;
        check_len("normals", n, out.len())?;
        fill_rows(out, PARALLEL_CHUNK, |first, o| {
            self.normals_rows(positions, first, o)
        });
        Ok(())
    }

    /// [`VertexFans::normals`] for the vertices `first .. first + out.len()` only.
    ///
    /// # Panics
    /// If the range runs past [`VertexFans::vertex_count`] or a corner is outside `positions`.
    #[inline]
    pub fn normals_rows<P: Copy + Into<Vec3A>>(
        &self,
        positions: &[P],
        first: usize,
        out: &mut [Vec3],
    ) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.normal(positions, first + i).into();
        }
    }

    /// Normals and HZY11 eq. 4's displacement in one pass: for every vertex `v`,
    /// `normals[v] = n(v)` of `high` and `out[v] = high[v] + h[v] n(v)`. Reads `high` only, so
    /// every normal is that of the undisplaced mesh.
    pub fn normals_and_displace(
        &self,
        high: &[Vec3A],
        h: &[f32],
        normals: &mut [Vec3A],
        out: &mut [Vec3],
    ) -> Result<(), DetailError> {
        let n = self.vertex_count();
        check_len("positions", n, high.len())?;
        check_len("displacements h", n, h.len())?;
        check_len("normals", n, normals.len())?;
        check_len("output", n, out.len())?;
        #[cfg(feature = "parallel")]
        if use_pool(n, PARALLEL_CHUNK) {
            use rayon::prelude::*;
            out.par_chunks_mut(PARALLEL_CHUNK)
                .zip(normals.par_chunks_mut(PARALLEL_CHUNK))
                .enumerate()
                .for_each(|(c, (o, nm))| {
                    self.normals_and_displace_rows(high, h, c * PARALLEL_CHUNK, nm, o)
                });
            return Ok(());
        }
        self.normals_and_displace_rows(high, h, 0, normals, out);
        Ok(())
    }

    /// [`VertexFans::normals_and_displace`] for the vertices `first .. first + out.len()`
    /// (`normals` as long as `out`).
    ///
    /// # Panics
    /// If the range runs past [`VertexFans::vertex_count`], `h` or `high`.
    #[inline]
    pub fn normals_and_displace_rows(
        &self,
        high: &[Vec3A],
        h: &[f32],
        first: usize,
        normals: &mut [Vec3A],
        out: &mut [Vec3],
    ) {
        let rows = out.len();
        let iter = out
            .iter_mut()
            .zip(normals.iter_mut())
            .zip(&h[first..first + rows])
            .enumerate();
        for (i, ((o, nm), &hv)) in iter {
            let v = first + i;
            let n = self.normal(high, v);
            *nm = n;
            *o = (high[v] + hv * n).into();
        }
    }

    /// The unit area-weighted normal of vertex `v`: the sum of `d_i × d_i+1` along its chains,
    /// `d_i = p[r_i] - p[v]`.
    #[inline(always)]
    fn normal<P: Copy + Into<Vec3A>>(&self, positions: &[P], v: usize) -> Vec3A {
        let chain = &self.chains[self.offsets[v] as usize..self.offsets[v + 1] as usize];
        let p: Vec3A = positions[v].into();
        let mut it = chain.iter();
        let Some(&r) = it.next() else {
            return Vec3A::ZERO;
        };
        let mut q = positions[r as usize].into() - p;
        let mut n = Vec3A::ZERO;
        while let Some(&r) = it.next() {
            if r == BREAK {
                match it.next() {
                    Some(&r) => q = positions[r as usize].into() - p,
                    None => break,
                }
                continue;
            }
            let d = positions[r as usize].into() - p;
            n += q.cross(d);
            q = d;
        }
        n.normalize_or_zero()
    }
}

/// Area-weighted unit vertex normals by a scatter pass over the triangles (zero, accumulate each
/// face normal at its corners, normalise): the textbook method and the reference for
/// [`VertexFans::normals`]. Single-threaded; `out` must have one entry per position.
///
/// # Panics
/// If a triangle index is outside `positions`.
pub fn scatter_normals(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    out: &mut [Vec3],
) -> Result<(), DetailError> {
    check_len("normals", positions.len(), out.len())?;
    accumulate_face_normals(positions, triangles, out);
    for n in out.iter_mut() {
        *n = n.normalize_or_zero();
    }
    Ok(())
}

/// HZY11 eq. 4's second term: `positions[v] += h[v] * normals[v]` for every vertex.
pub fn displace(positions: &mut [Vec3], normals: &[Vec3], h: &[f32]) -> Result<(), DetailError> {
    check_len("normals", positions.len(), normals.len())?;
    check_len("displacements h", positions.len(), h.len())?;
    #[cfg(feature = "parallel")]
    if use_pool(positions.len(), PARALLEL_CHUNK) {
        use rayon::prelude::*;
        positions
            .par_chunks_mut(PARALLEL_CHUNK)
            .zip(normals.par_chunks(PARALLEL_CHUNK))
            .zip(h.par_chunks(PARALLEL_CHUNK))
            .for_each(|((p, n), h)| displace_kernel(p, n, h));
        return Ok(());
    }
    displace_kernel(positions, normals, h);
    Ok(())
}

#[inline]
fn displace_kernel(positions: &mut [Vec3], normals: &[Vec3], h: &[f32]) {
    for ((p, &n), &h) in positions.iter_mut().zip(normals).zip(h) {
        *p += h * n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;
    use crate::mesh::test_meshes::{grid, tetrahedron};

    /// The fans of `m` and their normals, checked against the triangle scatter's.
    fn fans_against_scatter(m: &Mesh) -> (VertexFans, Vec<Vec3>) {
        let fans = VertexFans::new(m.vertex_count(), &m.triangles);
        let mut a = vec![Vec3::NAN; m.vertex_count()];
        let mut b = vec![Vec3::NAN; m.vertex_count()];
        fans.normals(&m.positions, &mut a).unwrap();
        scatter_normals(&m.positions, &m.triangles, &mut b).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((*x - *y).length() < 1e-6, "{x} vs {y}");
        }
        (fans, a)
    }

    #[test]
    fn fan_normals_match_scatter_normals_with_degenerate_and_isolated_vertices() {
        let mut m = tetrahedron();
        // A zero-area triangle (collinear corners) and an isolated vertex.
        m.positions.push(Vec3::new(3.0, 0.0, 0.0));
        m.positions.push(Vec3::new(5.0, 0.0, 0.0));
        m.positions.push(Vec3::new(9.0, 9.0, 9.0));
        m.triangles.push([4, 5, 0]);
        m.positions[0] = Vec3::new(4.0, 0.0, 0.0);
        let (_, a) = fans_against_scatter(&m);
        assert_eq!(a[6], Vec3::ZERO);
        assert_eq!(a[4], Vec3::ZERO);
    }

    #[test]
    fn fan_normals_match_scatter_normals_with_inconsistent_winding() {
        // A 3 x 3 grid of quads with bumpy heights, one triangle flipped.
        let mut m = grid(4, 4, |i, j| {
            Vec3::new(i as f32, j as f32, ((i * 7 + j * 3) % 5) as f32 * 0.1)
        });
        m.triangles[7].swap(1, 2);
        let (fans, _) = fans_against_scatter(&m);
        // 18 triangles: 54 corners, plus one closing/separating entry per chain.
        assert!(fans.len() > 54, "{}", fans.len());
    }
}
