//! Hand-written SIMD kernels of the per-frame path, chosen at run time (issue 23): AVX2 with
//! fused multiply-adds (x86-64-v3) where the CPU has it, the portable loop of the caller
//! elsewhere. The workspace forbids `unsafe`: `pulp`'s CPU-feature token ([`Fma`]) makes the
//! intrinsics safe to call, and [`Fma::vectorize`] compiles what it runs for those features.
//!
//! Each kernel here has a portable twin in its caller and a test against an independent
//! computation (f64 dense sums); the FMA kernels round differently from the portable loops (one
//! rounding per multiply-add, another summation order), within a few ulps.
//!
//! - [`dot_rows`]: `out = m xi + b`, `m` row-major, for [`super::predict::LinearOperator`]
//!   (the rotation regressors, FKY08 eq. 8, and the detail regressor, HZY11 §5.2);
//! - [`block_rows8`]: the same product on `D` in blocks of eight rows stored column by
//!   column, no horizontal sums (the detail regressor's per-frame form);
//! - [`rotate_sum`]: `acc_a = sum_p R_{idx_p} k_p` over a sparse row structure, the
//!   right-hand side of the translation solve (FKY08 eq. 11);
//! - [`lower_solve4`]: that solve's forward and backward substitutions, the three coordinates
//!   at once ([`super::lower_factor`]);
//! - [`sparse_rows4`]: the detail layer's sparse `S · base` on 4-lane positions
//!   (`runtime::detail`);
//! - `compiled_twice!`: a pass written in plain Rust, run compiled for AVX2 + FMA where the
//!   CPU has them (the detail layer's stencils, normal scatter and displacement);
//!
//! The packed LBS kernel lives beside its private layout in `skin::packed`.

/// The CPU-feature token of the FMA kernels: AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
pub(crate) type Fma = pulp::x86::V3;

/// [`Fma`] if this CPU has AVX2 and FMA (detected once, then cached by pulp) and the
/// environment does not say `CREASE_SIMD=portable` (read once: A/B runs of one binary, and a
/// way out should a kernel misbehave on some CPU).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn fma() -> Option<Fma> {
    static PORTABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if *PORTABLE.get_or_init(|| std::env::var("CREASE_SIMD").is_ok_and(|v| v == "portable")) {
        return None;
    }
    Fma::try_new()
}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy, Debug)]
pub(crate) enum Fma {}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
#[inline]
pub(crate) fn fma() -> Option<Fma> {
    None
}

/// `out[r] = m[r] . xi + b[r]` for the rows of the row-major `m` (`out.len()` rows of
/// `xi.len()` columns), with FMA: per row, 8 columns at a time in one accumulator, the last 8
/// columns of the row loaded whole and multiplied by `xi` with its already-counted columns
/// zeroed (so no row reads past its end), then the 8 lanes summed. Rows shorter than 8 columns
/// return `false` (the caller's portable loop runs them).
#[cfg(target_arch = "x86_64")]
pub(crate) fn dot_rows(simd: Fma, m: &[f32], xi: &[f32], b: &[f32], out: &mut [f32]) -> bool {
    let cols = xi.len();
    if cols < 8 || m.len() != out.len() * cols || b.len() != out.len() {
        return false;
    }
    let full = cols / 8;
    // The tail chunk covers columns cols-8..cols; of those, the first 8-(cols-8*full) were
    // counted by the last full chunk (none when cols is a multiple of 8: the tail is then the
    // last full chunk, and full drops by one).
    let (full, counted) = if cols.is_multiple_of(8) {
        (full - 1, 0)
    } else {
        (full, 8 - cols % 8)
    };
    let mut tail_x = [0.0f32; 8];
    tail_x[counted..].copy_from_slice(&xi[cols - 8 + counted..]);
    simd.vectorize(DotRows {
        simd,
        m,
        xi,
        b,
        out,
        full,
        tail_x,
    });
    true
}

/// [`dot_rows`]' loop, inlined into pulp's AVX2 + FMA context: a closure's body that is not
/// inlined there is compiled without those features, and every intrinsic in it becomes a call
/// (what the detail regressor's frame measured, 147 instructions a row, until this was split
/// out; pulp: "the given function must be inlined").
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn dot_rows_body(
    simd: Fma,
    m: &[f32],
    xi: &[f32],
    b: &[f32],
    out: &mut [f32],
    full: usize,
    tail_x: [f32; 8],
) {
    use std::arch::x86_64::__m256;
    let cols = xi.len();
    let avx = simd.avx;
    let tail_x: __m256 = bytemuck::cast(tail_x);
    for ((row, o), &bias) in m.chunks_exact(cols).zip(out.iter_mut()).zip(b) {
        let mut acc = avx._mm256_setzero_ps();
        for c in 0..full {
            let a: [f32; 8] = row[8 * c..8 * c + 8].try_into().expect("8 columns");
            let x: [f32; 8] = xi[8 * c..8 * c + 8].try_into().expect("8 columns");
            acc = simd
                .fma
                ._mm256_fmadd_ps(bytemuck::cast(a), bytemuck::cast(x), acc);
        }
        let a: [f32; 8] = row[cols - 8..].try_into().expect("8 columns");
        acc = simd.fma._mm256_fmadd_ps(bytemuck::cast(a), tail_x, acc);
        *o = sum8(simd, acc) + bias;
    }
}

/// The kernels' arguments as [`Fma::vectorize`]'s operation: a struct whose `call` is
/// `#[inline(always)]`, so that the kernel's body is compiled inside pulp's AVX2 + FMA context.
/// A closure handed over instead is called through `FnOnce::call_once`, which the compiler did
/// not inline once the kernel's body was inlined into it: the body was then compiled without
/// the features and every intrinsic in it became a call (the detail regressor measured 147
/// instructions a row so; pulp: "the given function must be inlined").
///
/// `Name { fields } => body` is a kernel of intrinsics, called as `body(simd, fields..)`;
/// `@plain Name { fields } => body` is plain Rust, called as `body(fields..)`
/// ([`compiled_twice!`]).
#[cfg(target_arch = "x86_64")]
macro_rules! vectorized {
    ($name:ident { $($field:ident: $ty:ty),* $(,)? } => $body:path) => {
        vectorized!(@plain $name { simd: Fma, $($field: $ty),* } => $body);
    };
    (@plain $name:ident { $($field:ident: $ty:ty),* $(,)? } => $body:path) => {
        struct $name<'a> {
            $($field: $ty),*
        }

        impl pulp::NullaryFnOnce for $name<'_> {
            type Output = ();

            #[inline(always)]
            fn call(self) {
                $body($(self.$field),*)
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
pub(crate) use vectorized;

/// `fn $name` running `$body` (plain Rust, `#[inline(always)]`, glam's vectors and arrays the
/// compiler vectorises) compiled a second time for AVX2 + FMA where the CPU has them ([`fma`]):
/// three-operand instructions instead of SSE2's register copies, 8-wide array operations. The
/// arguments travel to pulp's feature context as a [`vectorized!`] struct; elsewhere `$body`
/// runs as it is. The same arithmetic either way (no fused multiply-adds appear that the source
/// does not write), so the results do not depend on the CPU. Arguments share one lifetime `'a`.
macro_rules! compiled_twice {
    ($(#[$doc:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) => $body:path) => {
        $(#[$doc])*
        $vis fn $name<'a>($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = $crate::runtime::simd::fma() {
                $crate::runtime::simd::vectorized!(@plain Run { $($arg: $ty),* } => $body);
                simd.vectorize(Run { $($arg),* });
                return;
            }
            $body($($arg),*)
        }
    };
}
pub(crate) use compiled_twice;

#[cfg(target_arch = "x86_64")]
vectorized!(DotRows {
    m: &'a [f32],
    xi: &'a [f32],
    b: &'a [f32],
    out: &'a mut [f32],
    full: usize,
    tail_x: [f32; 8],
} => dot_rows_body);

#[cfg(target_arch = "x86_64")]
vectorized!(BlockRows8 {
    blocks: &'a [[f32; 8]],
    xi: &'a [f32],
    b: &'a [f32],
    out: &'a mut [f32],
} => block_rows8_body);

#[cfg(target_arch = "x86_64")]
vectorized!(RotateSum {
    ptr: &'a [usize],
    idx: &'a [u32],
    val: &'a [glam::DVec3],
    rot: &'a [[f64; 12]],
    acc: &'a mut [glam::DVec3],
} => rotate_sum_body);

#[cfg(target_arch = "x86_64")]
vectorized!(SparseRows4 {
    ptr: &'a [u32],
    cols: &'a [u32],
    vals: &'a [f32],
    x: &'a [glam::Vec3A],
    out: &'a mut [glam::Vec3A],
} => sparse_rows4_body);

#[cfg(target_arch = "x86_64")]
vectorized!(LowerSolve4 {
    col_ptr: &'a [u32],
    row_idx: &'a [u32],
    val: &'a [f64],
    inv_diag: &'a [f64],
    y: &'a mut [[f64; 4]],
} => lower_solve4_body);

/// The 8 lanes of `v` summed: `(v0+v4) + (v1+v5)` and `(v2+v6) + (v3+v7)`, then those two.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sum8(simd: Fma, v: std::arch::x86_64::__m256) -> f32 {
    let lo = simd.avx._mm256_castps256_ps128(v);
    let hi = simd.avx._mm256_extractf128_ps::<1>(v);
    let s = simd.sse._mm_add_ps(lo, hi);
    let s = simd.sse3._mm_hadd_ps(s, s);
    let s = simd.sse3._mm_hadd_ps(s, s);
    simd.sse._mm_cvtss_f32(s)
}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn dot_rows(simd: Fma, _m: &[f32], _xi: &[f32], _b: &[f32], _out: &mut [f32]) -> bool {
    match simd {}
}

/// `out = b + sum_l blocks[.., l] xi_l` for whole blocks of eight rows stored column by column
/// (`runtime::displacement::BlockedRows`): per block and column one broadcast and one 8-wide
/// fused multiply-add (two chains, even and odd columns), per block one store.
#[cfg(target_arch = "x86_64")]
pub(crate) fn block_rows8(simd: Fma, blocks: &[[f32; 8]], xi: &[f32], b: &[f32], out: &mut [f32]) {
    simd.vectorize(BlockRows8 {
        simd,
        blocks,
        xi,
        b,
        out,
    });
}

/// [`block_rows8`]'s loop, inlined into pulp's AVX2 + FMA context (see [`dot_rows_body`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn block_rows8_body(simd: Fma, blocks: &[[f32; 8]], xi: &[f32], b: &[f32], out: &mut [f32]) {
    let cols = xi.len();
    let outs = out.chunks_exact_mut(8).zip(b.chunks_exact(8));
    for ((o, b), block) in outs.zip(blocks.chunks_exact(cols)) {
        let b: &[f32; 8] = b.try_into().expect("chunks of 8");
        let mut even: std::arch::x86_64::__m256 = bytemuck::cast(*b);
        let mut odd = simd.avx._mm256_setzero_ps();
        let mut pairs = block.chunks_exact(2).zip(xi.chunks_exact(2));
        for (c, x) in &mut pairs {
            even =
                simd.fma
                    ._mm256_fmadd_ps(bytemuck::cast(c[0]), simd.avx._mm256_set1_ps(x[0]), even);
            odd =
                simd.fma
                    ._mm256_fmadd_ps(bytemuck::cast(c[1]), simd.avx._mm256_set1_ps(x[1]), odd);
        }
        if cols % 2 == 1 {
            even = simd.fma._mm256_fmadd_ps(
                bytemuck::cast(block[cols - 1]),
                simd.avx._mm256_set1_ps(xi[cols - 1]),
                even,
            );
        }
        let sum: [f32; 8] = bytemuck::cast(simd.avx._mm256_add_ps(even, odd));
        o.copy_from_slice(&sum);
    }
}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn block_rows8(
    simd: Fma,
    _blocks: &[[f32; 8]],
    _xi: &[f32],
    _b: &[f32],
    _out: &mut [f32],
) {
    match simd {}
}

/// `acc[a] = sum over p in ptr[a]..ptr[a+1] of R_{idx[p]} val[p]` with FMA, where `rot` holds
/// each rotation's three columns padded to four lanes (`[c0x c0y c0z 0 c1x .. c2z 0]`): per
/// entry three broadcasts and three 4-wide fused multiply-adds. The sizes are the caller's
/// (every `idx` below `rot.len()`, `ptr` one longer than `acc`).
#[cfg(target_arch = "x86_64")]
pub(crate) fn rotate_sum(
    simd: Fma,
    ptr: &[usize],
    idx: &[u32],
    val: &[glam::DVec3],
    rot: &[[f64; 12]],
    acc: &mut [glam::DVec3],
) {
    simd.vectorize(RotateSum {
        simd,
        ptr,
        idx,
        val,
        rot,
        acc,
    });
}

/// [`rotate_sum`]'s loop, inlined into pulp's AVX2 + FMA context (see [`dot_rows_body`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn rotate_sum_body(
    simd: Fma,
    ptr: &[usize],
    idx: &[u32],
    val: &[glam::DVec3],
    rot: &[[f64; 12]],
    acc: &mut [glam::DVec3],
) {
    let avx = simd.avx;
    // One accumulator per column and per entry parity: six independent chains of fused
    // multiply-adds (one chain would wait out the FMA's latency three times per entry).
    for (a, s) in acc.iter_mut().enumerate() {
        let zero = avx._mm256_setzero_pd();
        let mut even = [zero; 3];
        let mut odd = [zero; 3];
        // The row's entries as slices, so that only the rotation lookup is bounds-checked.
        let (idx, val) = (&idx[ptr[a]..ptr[a + 1]], &val[ptr[a]..ptr[a + 1]]);
        let mut pairs = idx.chunks_exact(2).zip(val.chunks_exact(2));
        for (i, v) in &mut pairs {
            rotate_entry(simd, &rot[i[0] as usize], v[0], &mut even);
            rotate_entry(simd, &rot[i[1] as usize], v[1], &mut odd);
        }
        if idx.len() % 2 == 1 {
            let last = idx.len() - 1;
            rotate_entry(simd, &rot[idx[last] as usize], val[last], &mut even);
        }
        let sum = avx._mm256_add_pd(
            avx._mm256_add_pd(
                avx._mm256_add_pd(even[0], odd[0]),
                avx._mm256_add_pd(even[1], odd[1]),
            ),
            avx._mm256_add_pd(even[2], odd[2]),
        );
        let s4: [f64; 4] = bytemuck::cast(sum);
        *s = glam::DVec3::new(s4[0], s4[1], s4[2]);
    }
}

/// `sum[c] += column c of the padded rotation * v[c]`, one broadcast and FMA a column.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn rotate_entry(
    simd: Fma,
    rot: &[f64; 12],
    v: glam::DVec3,
    sum: &mut [std::arch::x86_64::__m256d; 3],
) {
    let cols: &[[f64; 4]; 3] = bytemuck::cast_ref(rot);
    for (s, (c, x)) in sum.iter_mut().zip(cols.iter().zip([v.x, v.y, v.z])) {
        *s = simd
            .fma
            ._mm256_fmadd_pd(bytemuck::cast(*c), simd.avx._mm256_set1_pd(x), *s);
    }
}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn rotate_sum(
    simd: Fma,
    _ptr: &[usize],
    _idx: &[u32],
    _val: &[glam::DVec3],
    _rot: &[[f64; 12]],
    _acc: &mut [glam::DVec3],
) {
    match simd {}
}

/// `L y' = y` then `L^T x = y'` in place on 4-lane rows, `L` in compressed columns with the
/// diagonal first in each column and its reciprocals in `inv_diag`
/// ([`super::lower_factor`]): per stored entry one broadcast and
/// one 4-wide fused multiply-add. The forward pass scatters column `j` into the rows below it;
/// the backward pass gathers them into row `j` in two accumulators (independent chains).
#[cfg(target_arch = "x86_64")]
pub(crate) fn lower_solve4(
    simd: Fma,
    col_ptr: &[u32],
    row_idx: &[u32],
    val: &[f64],
    inv_diag: &[f64],
    y: &mut [[f64; 4]],
) {
    simd.vectorize(LowerSolve4 {
        simd,
        col_ptr,
        row_idx,
        val,
        inv_diag,
        y,
    });
}

/// [`lower_solve4`]'s passes, inlined into pulp's AVX2 + FMA context (see [`dot_rows_body`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lower_solve4_body(
    simd: Fma,
    col_ptr: &[u32],
    row_idx: &[u32],
    val: &[f64],
    inv_diag: &[f64],
    y: &mut [[f64; 4]],
) {
    use std::arch::x86_64::__m256d;
    let n = y.len();
    let avx = simd.avx;
    let fma = simd.fma;
    // Each column's off-diagonal entries as slices, so that only the `y` accesses are
    // bounds-checked.
    let below = |j: usize| {
        let (start, end) = (col_ptr[j] as usize + 1, col_ptr[j + 1] as usize);
        (&row_idx[start..end], &val[start..end])
    };
    for j in 0..n {
        let yj = avx._mm256_mul_pd(bytemuck::cast(y[j]), avx._mm256_set1_pd(inv_diag[j]));
        y[j] = bytemuck::cast(yj);
        let (rows, vals) = below(j);
        for (&r, &v) in rows.iter().zip(vals) {
            let yi = &mut y[r as usize];
            let t: __m256d = fma._mm256_fnmadd_pd(avx._mm256_set1_pd(v), yj, bytemuck::cast(*yi));
            *yi = bytemuck::cast(t);
        }
    }
    for j in (0..n).rev() {
        let zero = avx._mm256_setzero_pd();
        let (mut even, mut odd) = (zero, zero);
        let (rows, vals) = below(j);
        let mut pairs = rows.chunks_exact(2).zip(vals.chunks_exact(2));
        for (r, v) in &mut pairs {
            let a: __m256d = bytemuck::cast(y[r[0] as usize]);
            let b: __m256d = bytemuck::cast(y[r[1] as usize]);
            even = fma._mm256_fmadd_pd(avx._mm256_set1_pd(v[0]), a, even);
            odd = fma._mm256_fmadd_pd(avx._mm256_set1_pd(v[1]), b, odd);
        }
        if rows.len() % 2 == 1 {
            let a: __m256d = bytemuck::cast(y[rows[rows.len() - 1] as usize]);
            even = fma._mm256_fmadd_pd(avx._mm256_set1_pd(vals[vals.len() - 1]), a, even);
        }
        let s = avx._mm256_sub_pd(bytemuck::cast(y[j]), avx._mm256_add_pd(even, odd));
        y[j] = bytemuck::cast(avx._mm256_mul_pd(s, avx._mm256_set1_pd(inv_diag[j])));
    }
}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn lower_solve4(
    simd: Fma,
    _col_ptr: &[u32],
    _row_idx: &[u32],
    _val: &[f64],
    _inv_diag: &[f64],
    _y: &mut [[f64; 4]],
) {
    match simd {}
}

/// `m`'s columns padded to four lanes, as [`rotate_sum`] reads them (the tests' layout
/// reference; frames build theirs with [`padded_rotation`]).
#[cfg(test)]
pub(crate) fn pad_columns(m: &glam::DMat3) -> [f64; 12] {
    let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
    [x.x, x.y, x.z, 0.0, y.x, y.y, y.z, 0.0, z.x, z.y, z.z, 0.0]
}

/// `out[r] = sum over p in ptr[r]..ptr[r+1] of vals[p] * x[cols[p]]` with FMA on 4-lane rows
/// (all four lanes summed): per stored entry one 16-byte load, one broadcast and one fused
/// multiply-add, per row one 16-byte store (the compressed rows of the detail layer's
/// `S · base`, its Loop vertex points: `runtime::detail`).
#[cfg(target_arch = "x86_64")]
pub(crate) fn sparse_rows4(
    simd: Fma,
    ptr: &[u32],
    cols: &[u32],
    vals: &[f32],
    x: &[glam::Vec3A],
    out: &mut [glam::Vec3A],
) {
    simd.vectorize(SparseRows4 {
        simd,
        ptr,
        cols,
        vals,
        x,
        out,
    });
}

/// [`sparse_rows4`]'s loop, inlined into pulp's AVX2 + FMA context (see [`dot_rows_body`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sparse_rows4_body(
    simd: Fma,
    ptr: &[u32],
    cols: &[u32],
    vals: &[f32],
    x: &[glam::Vec3A],
    out: &mut [glam::Vec3A],
) {
    let mut start = ptr[0] as usize;
    for (o, &end) in out.iter_mut().zip(&ptr[1..]) {
        let end = end as usize;
        let mut acc = simd.sse._mm_setzero_ps();
        for (&c, &w) in cols[start..end].iter().zip(&vals[start..end]) {
            acc = simd
                .fma
                ._mm_fmadd_ps(simd.sse._mm_set1_ps(w), x[c as usize].into(), acc);
        }
        *o = acc.into();
        start = end;
    }
}

/// Off x86-64 there is no FMA kernel.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn sparse_rows4(
    simd: Fma,
    _ptr: &[u32],
    _cols: &[u32],
    _vals: &[f32],
    _x: &[glam::Vec3A],
    _out: &mut [glam::Vec3A],
) {
    match simd {}
}

/// The rotation of `q` (any non-zero length: divided out, in f64), its three columns padded
/// to four lanes (`[c0x c0y c0z 0 c1x .. c2z 0]`, as [`rotate_sum`] reads them): the unit quaternion's matrix without its square root (`s = 2 / |q|^2` where the unit
/// form has 2). A zero or non-finite `q` gives non-finite entries.
#[inline]
pub(crate) fn padded_rotation(q: glam::Quat) -> [f64; 12] {
    let q = q.as_dquat();
    let s = 2.0 / q.length_squared();
    let (x2, y2, z2) = (q.x * s, q.y * s, q.z * s);
    let (xx, xy, xz) = (q.x * x2, q.x * y2, q.x * z2);
    let (yy, yz, zz) = (q.y * y2, q.y * z2, q.z * z2);
    let (wx, wy, wz) = (q.w * x2, q.w * y2, q.w * z2);
    [
        1.0 - (yy + zz),
        xy + wz,
        xz - wy,
        0.0,
        xy - wz,
        1.0 - (xx + zz),
        yz + wx,
        0.0,
        xz + wy,
        yz - wx,
        1.0 - (xx + yy),
        0.0,
    ]
}

/// The matrix whose columns [`padded_rotation`] padded (exactly).
#[inline]
pub(crate) fn unpad_columns(c: &[f64; 12]) -> glam::DMat3 {
    glam::DMat3::from_cols_array(&[c[0], c[1], c[2], c[4], c[5], c[6], c[8], c[9], c[10]])
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use glam::{DMat3, DQuat, DVec3};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    #[test]
    fn dot_rows_equal_f64_sums_for_every_column_count() {
        let Some(simd) = fma() else {
            eprintln!("dot_rows not checked: this CPU lacks AVX2 + FMA");
            return;
        };
        let mut rng = StdRng::seed_from_u64(3);
        for cols in 1..=41 {
            let rows = 37;
            let m: Vec<f32> = (0..rows * cols)
                .map(|_| rng.random_range(-2.0..2.0))
                .collect();
            let xi: Vec<f32> = (0..cols).map(|_| rng.random_range(0.0..1.0)).collect();
            let b: Vec<f32> = (0..rows).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut out = vec![f32::NAN; rows];
            let ran = dot_rows(simd, &m, &xi, &b, &mut out);
            assert_eq!(ran, cols >= 8, "{cols} columns");
            if !ran {
                continue;
            }
            for (r, &got) in out.iter().enumerate() {
                let row = &m[r * cols..(r + 1) * cols];
                let want: f64 = row
                    .iter()
                    .zip(&xi)
                    .map(|(&a, &x)| f64::from(a) * f64::from(x))
                    .sum::<f64>()
                    + f64::from(b[r]);
                let scale: f64 = row
                    .iter()
                    .zip(&xi)
                    .map(|(&a, &x)| f64::from((a * x).abs()))
                    .sum::<f64>()
                    + f64::from(b[r].abs());
                let err = (f64::from(got) - want).abs();
                assert!(
                    err <= 4.0 * f64::from(f32::EPSILON) * scale,
                    "{cols} columns, row {r}: {got} vs {want} (error {err:e}, scale {scale})"
                );
            }
        }
        // Wrong sizes are refused, not read out of bounds.
        assert!(!dot_rows(
            simd,
            &[0.0; 15],
            &[0.0; 8],
            &[0.0; 2],
            &mut [0.0; 2]
        ));
    }

    #[test]
    fn padded_rotation_is_the_normalised_quaternions_matrix() {
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..200 {
            let q = glam::Quat::from_xyzw(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * rng.random_range(0.01..100.0);
            let want = DMat3::from_quat(q.as_dquat().normalize());
            let got = unpad_columns(&padded_rotation(q));
            assert!(
                (got - want)
                    .abs()
                    .to_cols_array()
                    .iter()
                    .all(|e| *e <= 1e-14),
                "{q}: {got} vs {want}"
            );
            let p = padded_rotation(q);
            assert_eq!([p[3], p[7], p[11]], [0.0; 3], "pad lanes");
        }
        assert!(!padded_rotation(glam::Quat::from_xyzw(0.0, 0.0, 0.0, 0.0))[0].is_finite());
    }

    #[test]
    fn rotate_sum_equals_the_matrix_products() {
        let Some(simd) = fma() else {
            eprintln!("rotate_sum not checked: this CPU lacks AVX2 + FMA");
            return;
        };
        let mut rng = StdRng::seed_from_u64(4);
        let bones = 23;
        let mats: Vec<DMat3> = (0..bones)
            .map(|_| {
                let q = DQuat::from_xyzw(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
                .normalize();
                DMat3::from_quat(q)
            })
            .collect();
        let rot: Vec<[f64; 12]> = mats.iter().map(pad_columns).collect();
        for (r, m) in rot.iter().zip(&mats) {
            assert_eq!(unpad_columns(r), *m, "padding round trip");
        }
        let (mut ptr, mut idx, mut val) = (vec![0], Vec::new(), Vec::new());
        for a in 0..bones {
            // Row a: 0 to 9 entries, repeats allowed.
            for _ in 0..(a * 7) % 10 {
                idx.push(rng.random_range(0..bones as u32));
                val.push(DVec3::new(
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                ));
            }
            ptr.push(idx.len());
        }
        let mut acc = vec![DVec3::NAN; bones];
        rotate_sum(simd, &ptr, &idx, &val, &rot, &mut acc);
        for a in 0..bones {
            let want: DVec3 = (ptr[a]..ptr[a + 1])
                .map(|p| mats[idx[p] as usize] * val[p])
                .sum();
            assert!(
                (acc[a] - want).abs().max_element() <= 1e-13,
                "row {a}: {} vs {want}",
                acc[a]
            );
        }
        assert_eq!(acc[0], DVec3::ZERO, "an empty row sums to zero");
    }
}
