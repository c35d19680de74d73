//! A small software rasteriser for pictures of meshes (PNG). Being written.
