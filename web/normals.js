// Vertex normals of an indexed triangle mesh, exactly as three.js's
// BufferGeometry.computeVertexNormals + normalizeNormals compute them (r187: per triangle
// [a, b, c] the cross product (c - b) x (a - b) in f64, added to each corner's f32 sum, read
// for all three corners before any is written; then each sum times 1 / its length, or 1 for a
// zero sum), so that the decode worker's normals are the main thread's to the bit. Pure:
// writes `normals` (Float32Array, 3 per vertex) from `positions` (same size) and `index`.

export function vertexNormals(positions, index, normals) {
  normals.fill(0);
  for (let i = 0; i < index.length; i += 3) {
    const a = 3 * index[i];
    const b = 3 * index[i + 1];
    const c = 3 * index[i + 2];
    const bx = positions[b];
    const by = positions[b + 1];
    const bz = positions[b + 2];
    const cbx = positions[c] - bx;
    const cby = positions[c + 1] - by;
    const cbz = positions[c + 2] - bz;
    const abx = positions[a] - bx;
    const aby = positions[a + 1] - by;
    const abz = positions[a + 2] - bz;
    const nx = cby * abz - cbz * aby;
    const ny = cbz * abx - cbx * abz;
    const nz = cbx * aby - cby * abx;
    // Read all three sums before writing any (a triangle may name a vertex twice).
    const ax0 = normals[a] + nx, ay0 = normals[a + 1] + ny, az0 = normals[a + 2] + nz;
    const bx0 = normals[b] + nx, by0 = normals[b + 1] + ny, bz0 = normals[b + 2] + nz;
    const cx0 = normals[c] + nx, cy0 = normals[c + 1] + ny, cz0 = normals[c + 2] + nz;
    normals[a] = ax0;
    normals[a + 1] = ay0;
    normals[a + 2] = az0;
    normals[b] = bx0;
    normals[b + 1] = by0;
    normals[b + 2] = bz0;
    normals[c] = cx0;
    normals[c + 1] = cy0;
    normals[c + 2] = cz0;
  }
  for (let i = 0; i < normals.length; i += 3) {
    const x = normals[i];
    const y = normals[i + 1];
    const z = normals[i + 2];
    const s = 1 / (Math.sqrt(x * x + y * y + z * z) || 1);
    normals[i] = x * s;
    normals[i + 1] = y * s;
    normals[i + 2] = z * s;
  }
  return normals;
}
