//! Error measures shared by the evaluation ([`crate::eval`]) and the model selection
//! ([`crate::select`]): RMS vertex distances with the rest pose's largest bounding-box side
//! scaled to 1, the normalisation of HZY11 Table 2, so errors compare across meshes of any size.

use crease_core::glam::Vec3;

/// RMS vertex distance, normalised by `scale` (the rest pose's largest bounding-box side).
pub fn rms_normalized(a: &[Vec3], b: &[Vec3], scale: f32) -> f64 {
    let sse: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length_squared() as f64)
        .sum();
    (sse / a.len().max(1) as f64).sqrt() / scale as f64
}
