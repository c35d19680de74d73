// Loop subdivision steps rebuilt from a base mesh's triangles (issue 41): a palette stream's
// detail header sends the base triangles and the number of levels, and the decoder builds the
// one-level matrices S_1 .. S_L and the drawn triangles itself. They must be the server's bit
// for bit (the header's D rows are indexed by this numbering), so this is a port of
// core/src/mesh/subdivision.rs (`loop_steps`, `Level::build`, `push_row`, `count_fans`), checked
// against tests/vectors/loop-v1.json. The rules and the numbering (ARCHITECTURE.md, "Palette
// streams"):
//
// - vertices of a level: the coarser level's first, same ids; then one per edge, in the order
//   edges are first met walking the triangles in order, each [a, b, c] along ab, bc, ca;
// - triangles: each [a, b, c] becomes [a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca], in
//   place;
// - rows (weights computed as JS numbers, i.e. f64, each rounded once to f32; entries sorted by
//   column, a column met twice summed before rounding): an interior even vertex of valence n:
//   itself 1 - n beta, each neighbour beta (beta = 3 / (8 n) for n > 3, else 3/16, Warren); a
//   boundary even vertex (two boundary edges): itself 3/4, its two boundary neighbours 1/8
//   (Hoppe et al. 1994); an isolated vertex: itself 1; an interior edge (a, b) with opposite
//   vertices c, d: 3/8, 3/8, 1/8, 1/8 (Loop 1987); a boundary edge: 1/2, 1/2.
//
// A plain ES module without DOM or three.js: Node runs it as the page does. It allocates typed
// arrays per level, never an object per edge or vertex (the demo hand: 9,458 base vertices,
// 2 levels, 151,298 drawn vertices).
//
//   const { steps, triangles } = loopSteps(vertexCount, baseTriangles, levels);
//   // steps[l]: {rows, columns, rowPtr (Uint32Array, rows + 1), cols (Uint32Array),
//   //            weights (Float32Array)}; triangles: Uint32Array, 3 per drawn triangle

/** Most levels (core's MAX_LEVELS): each multiplies the triangles by 4. */
export const MAX_LEVELS = 3;

/** No second opposite vertex (a boundary edge), no rank yet, no vertex: core's NONE. -1 in
 * Int32Arrays rather than u32::MAX in Uint32Arrays: values of 2^31 and above are not small
 * integers to V8, and a cold (interpreted) run boxes each one it reads. */
const NONE = -1;

/** Buckets up to this long are sorted in place by insertion; longer ones (a vertex of very
 * high valence) by Array.prototype.sort, so a pathological fan stays O(k log k). */
const INSERTION_SORT_MAX = 32;

const f32 = Math.fround;

function loopError(message) {
  return new Error(`Loop subdivision: ${message}`);
}

/** Warren's beta for an interior even vertex of valence n. */
function warrenBeta(n) {
  return n > 3 ? 3 / (8 * n) : 3 / 16;
}

/**
 * The one-level Loop matrices of `levels` subdivisions of a topology (`vertexCount` vertices,
 * `triangles`: 3 indices per triangle, any array-like of integers) and the subdivided
 * triangles. Throws an Error as core's SubdivisionError reads (naming the triangle, edge or
 * vertex) for levels outside 1..=3, an index out of range, a degenerate triangle, an edge in
 * more than two triangles, a vertex with other than 0 or 2 boundary edges, or a vertex whose
 * triangles form several fans.
 */
export function loopSteps(vertexCount, triangles, levels) {
  if (!(Number.isInteger(levels) && levels >= 1 && levels <= MAX_LEVELS)) {
    throw loopError(`${levels} levels requested, expected 1..=${MAX_LEVELS}`);
  }
  if (!(Number.isInteger(vertexCount) && vertexCount >= 0)) {
    throw loopError(`vertex count ${vertexCount}, expected an integer >= 0`);
  }
  if (triangles.length % 3 !== 0) {
    throw loopError(`${triangles.length} triangle indices, not a multiple of 3`);
  }
  let n = vertexCount;
  let tris = triangles instanceof Uint32Array ? triangles : Uint32Array.from(triangles);
  const steps = [];
  for (let l = 0; l < levels; l++) {
    const level = buildLevel(n, tris);
    steps.push(level.step);
    n = level.step.rows;
    tris = level.triangles;
  }
  return { steps, triangles: tris };
}

/** Sorts entries lo..hi-1 of the parallel arrays `key`, `a`, `b` by (key, a). */
function sortBucket(key, a, b, lo, hi) {
  if (hi - lo <= INSERTION_SORT_MAX) {
    for (let i = lo + 1; i < hi; i++) {
      const k = key[i], x = a[i], y = b[i];
      let j = i - 1;
      while (j >= lo && (key[j] > k || (key[j] === k && a[j] > x))) {
        key[j + 1] = key[j];
        a[j + 1] = a[j];
        b[j + 1] = b[j];
        j--;
      }
      key[j + 1] = k;
      a[j + 1] = x;
      b[j + 1] = y;
    }
    return;
  }
  const order = [];
  for (let i = lo; i < hi; i++) order.push(i);
  order.sort((i, j) => key[i] - key[j] || a[i] - a[j]);
  const k2 = order.map((i) => key[i]), a2 = order.map((i) => a[i]), b2 = order.map((i) => b[i]);
  key.set(k2, lo);
  a.set(a2, lo);
  b.set(b2, lo);
}

/** One level: core's Level::build. Returns {step, triangles}. */
function buildLevel(n, tris) {
  const T = tris.length / 3;
  const H = 3 * T;
  // Every triangle's indices and corners first (core checks them all before the edges).
  for (let t = 0; t < T; t++) {
    const a = tris[3 * t], b = tris[3 * t + 1], c = tris[3 * t + 2];
    const bad = a >= n ? a : b >= n ? b : c >= n ? c : -1;
    if (bad >= 0) throw loopError(`triangle ${t} refers to vertex ${bad}, but there are only ${n} vertices`);
    if (a === b || b === c || c === a) throw loopError(`triangle ${t} [${a}, ${b}, ${c}] is degenerate (repeats a vertex)`);
  }

  // Half-edges h = 3 t + k (k: ab, bc, ca) bucketed by their smaller vertex, each bucket
  // sorted by (larger vertex, opposite vertex): core's sorted (lo, hi, c) triples.
  const start = new Uint32Array(n + 1);
  for (let h = 0; h < H; h++) {
    const t3 = h - (h % 3);
    const x = tris[h], y = tris[t3 + ((h + 1) % 3)];
    start[(x < y ? x : y) + 1]++;
  }
  for (let v = 0; v < n; v++) start[v + 1] += start[v];
  const fill = start.slice(0, n);
  const bHi = new Uint32Array(H);
  const bOpp = new Uint32Array(H);
  const bHalf = new Uint32Array(H);
  for (let h = 0; h < H; h++) {
    const t3 = h - (h % 3);
    const x = tris[h], y = tris[t3 + ((h + 1) % 3)], z = tris[t3 + ((h + 2) % 3)];
    const lo = x < y ? x : y;
    const at = fill[lo]++;
    bHi[at] = x < y ? y : x;
    bOpp[at] = z;
    bHalf[at] = h;
  }
  for (let v = 0; v < n; v++) if (start[v + 1] - start[v] > 1) sortBucket(bHi, bOpp, bHalf, start[v], start[v + 1]);

  // Edges in sorted order (lo, hi), their opposite vertices [smaller, larger or NONE], and
  // each half-edge's edge.
  const sA = new Uint32Array(H);
  const sB = new Uint32Array(H);
  const sC = new Uint32Array(H);
  const sD = new Int32Array(H);
  const edgeOfHalf = new Uint32Array(H);
  let E = 0;
  for (let lo = 0; lo < n; lo++) {
    const end = start[lo + 1];
    for (let p = start[lo]; p < end; ) {
      const hi = bHi[p];
      let q = p + 1;
      while (q < end && bHi[q] === hi) q++;
      if (q - p > 2) {
        throw loopError(`edge (${lo}, ${hi}) is shared by ${q - p} triangles (non-manifold edge; at most 2 allowed)`);
      }
      sA[E] = lo;
      sB[E] = hi;
      sC[E] = bOpp[p];
      sD[E] = q - p === 2 ? bOpp[p + 1] : NONE;
      for (let r = p; r < q; r++) edgeOfHalf[bHalf[r]] = E;
      E++;
      p = q;
    }
  }
  const rows = n + E;
  if (rows > 0x7fffffff) throw loopError(`${rows} vertices after subdivision exceed the indices this decoder handles (2^31 - 1)`);

  // New-vertex order: first appearance walking the triangles' half-edges in order.
  const rank = new Int32Array(E).fill(NONE);
  let next = 0;
  for (let h = 0; h < H; h++) {
    const e = edgeOfHalf[h];
    if (rank[e] === NONE) rank[e] = next++;
  }
  const A = new Uint32Array(E);
  const B = new Uint32Array(E);
  const C = new Uint32Array(E);
  const D = new Int32Array(E);
  for (let e = 0; e < E; e++) {
    const r = rank[e];
    A[r] = sA[e];
    B[r] = sB[e];
    C[r] = sC[e];
    D[r] = sD[e];
  }

  // Each vertex's ring (neighbour, edge rank), ascending by neighbour without a sort: in sorted
  // edge order, first every edge's lo into hi's ring (the neighbours below), then its hi into
  // lo's ring (the neighbours above).
  const ringStart = new Uint32Array(n + 1);
  for (let e = 0; e < E; e++) {
    ringStart[sA[e] + 1]++;
    ringStart[sB[e] + 1]++;
  }
  for (let v = 0; v < n; v++) ringStart[v + 1] += ringStart[v];
  const ringFill = ringStart.slice(0, n);
  const ringU = new Uint32Array(2 * E);
  const ringE = new Uint32Array(2 * E);
  for (let e = 0; e < E; e++) {
    const at = ringFill[sB[e]]++;
    ringU[at] = sA[e];
    ringE[at] = rank[e];
  }
  for (let e = 0; e < E; e++) {
    const at = ringFill[sA[e]]++;
    ringU[at] = sB[e];
    ringE[at] = rank[e];
  }
  // Ring positions visited by the fan walk, stamped with the vertex + 1 (no clearing).
  const visited = new Uint32Array(2 * E);

  /** Position of neighbour u in v's ring [s, e) (binary search; u is a neighbour). */
  const ringIndex = (s, e, u) => {
    let lo = s, hi = e;
    while (lo < hi) {
      const mid = (lo + hi) >>> 1;
      if (ringU[mid] < u) lo = mid + 1;
      else hi = mid;
    }
    return lo;
  };

  /** core's count_fans: the fans of triangles around v, walking its link from `first` (a
   * boundary neighbour) or from the first unvisited neighbour. */
  const countFans = (v, s, e, first) => {
    const stamp = v + 1;
    let fans = 0;
    let from = first;
    for (;;) {
      if (from === NONE) {
        for (let i = s; i < e; i++) {
          if (visited[i] !== stamp) {
            from = ringU[i];
            break;
          }
        }
        if (from === NONE) return fans;
      }
      fans++;
      let prev = NONE;
      let cur = from;
      for (;;) {
        const i = ringIndex(s, e, cur);
        if (visited[i] === stamp) break;
        visited[i] = stamp;
        const edge = ringE[i];
        const c = C[edge];
        const nx = c !== prev ? c : D[edge];
        if (nx === NONE) break;
        prev = cur;
        cur = nx;
      }
      from = NONE;
    }
  };

  // The matrix: even rows, then one odd row per edge. Entries: at most (valence + 1) per
  // even vertex (or 1 when isolated) and 4 per edge.
  const cap = n + 6 * E;
  const rowPtr = new Uint32Array(rows + 1);
  const cols = new Uint32Array(cap);
  const weights = new Float32Array(cap);
  let nnz = 0;
  for (let v = 0; v < n; v++) {
    const s = ringStart[v], e = ringStart[v + 1];
    if (s === e) {
      // Isolated: keeps its position.
      cols[nnz] = v;
      weights[nnz++] = 1;
      rowPtr[v + 1] = nnz;
      continue;
    }
    let boundary = 0;
    let b0 = NONE, b1 = NONE;
    for (let i = s; i < e; i++) {
      if (D[ringE[i]] === NONE) {
        if (boundary === 0) b0 = ringU[i];
        else if (boundary === 1) b1 = ringU[i];
        boundary++;
      }
    }
    if (boundary === 0) {
      const fans = countFans(v, s, e, NONE);
      if (fans !== 1) throw loopError(`the triangles around vertex ${v} form ${fans} separate fans (non-manifold vertex; expected 1)`);
      const k = e - s;
      const beta = warrenBeta(k);
      const self = f32(1 - k * beta);
      const w = f32(beta);
      let placed = false;
      for (let i = s; i < e; i++) {
        const u = ringU[i];
        if (!placed && u > v) {
          cols[nnz] = v;
          weights[nnz++] = self;
          placed = true;
        }
        cols[nnz] = u;
        weights[nnz++] = w;
      }
      if (!placed) {
        cols[nnz] = v;
        weights[nnz++] = self;
      }
    } else if (boundary === 2) {
      const fans = countFans(v, s, e, b0);
      if (fans !== 1) throw loopError(`the triangles around vertex ${v} form ${fans} separate fans (non-manifold vertex; expected 1)`);
      // b0 < b1 (ring order); v is neither.
      if (v < b0) {
        cols[nnz] = v;
        weights[nnz++] = 0.75;
      }
      cols[nnz] = b0;
      weights[nnz++] = 0.125;
      if (v > b0 && v < b1) {
        cols[nnz] = v;
        weights[nnz++] = 0.75;
      }
      cols[nnz] = b1;
      weights[nnz++] = 0.125;
      if (v > b1) {
        cols[nnz] = v;
        weights[nnz++] = 0.75;
      }
    } else {
      throw loopError(`vertex ${v} has ${boundary} boundary edges (non-manifold vertex; expected 0 or 2)`);
    }
    rowPtr[v + 1] = nnz;
  }
  const edgeSide = f32(0.375);
  for (let r = 0; r < E; r++) {
    const a = A[r], b = B[r], c = C[r], d = D[r];
    if (d === NONE) {
      // a < b: the edge's (lo, hi).
      cols[nnz] = a;
      weights[nnz++] = 0.5;
      cols[nnz] = b;
      weights[nnz++] = 0.5;
    } else {
      // Merge (a, b) at 3/8 and (c, d) at 1/8, both ascending; c and d are neither a nor b (no
      // degenerate triangles), and c = d (two triangles back to back) is one entry of
      // 1/8 + 1/8, summed before rounding.
      const same = c === d;
      const opposite = f32(same ? 0.125 + 0.125 : 0.125);
      let i0 = a, i1 = b, j0 = c, j1 = same ? Infinity : d;
      for (let k = same ? 3 : 4; k > 0; k--) {
        if (i0 < j0) {
          cols[nnz] = i0;
          weights[nnz++] = edgeSide;
          i0 = i1;
          i1 = Infinity;
        } else {
          cols[nnz] = j0;
          weights[nnz++] = opposite;
          j0 = j1;
          j1 = Infinity;
        }
      }
    }
    rowPtr[n + r + 1] = nnz;
  }

  // The subdivided triangles, four per triangle in place.
  const out = new Uint32Array(12 * T);
  for (let t = 0; t < T; t++) {
    const a = tris[3 * t], b = tris[3 * t + 1], c = tris[3 * t + 2];
    const ab = n + rank[edgeOfHalf[3 * t]];
    const bc = n + rank[edgeOfHalf[3 * t + 1]];
    const ca = n + rank[edgeOfHalf[3 * t + 2]];
    const o = 12 * t;
    out[o] = a;
    out[o + 1] = ab;
    out[o + 2] = ca;
    out[o + 3] = ab;
    out[o + 4] = b;
    out[o + 5] = bc;
    out[o + 6] = ca;
    out[o + 7] = bc;
    out[o + 8] = c;
    out[o + 9] = ab;
    out[o + 10] = bc;
    out[o + 11] = ca;
  }
  return {
    step: { rows, columns: n, rowPtr, cols: cols.slice(0, nnz), weights: weights.slice(0, nnz) },
    triangles: out,
  };
}
