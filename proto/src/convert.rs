//! The small conversions between wire messages and core types: points, boxes, a room's One
//! Euro filter, refinement and skinning, levels, and model descriptions. Control frames are in [`crate::control`], the
//! mesh stream in [`crate::mesh`].

use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_core::predictor::Refinement;
use crease_core::runtime::filter::OneEuroParams;
use crease_core::runtime::skin::Skinning;

use crate::errors::WireError;
use crate::v1;

/// The wire form of a point.
impl From<Vec3> for v1::Vec3 {
    fn from(p: Vec3) -> Self {
        Self {
            x: p.x,
            y: p.y,
            z: p.z,
        }
    }
}

/// A wire point as a core point.
impl From<v1::Vec3> for Vec3 {
    fn from(p: v1::Vec3) -> Self {
        Vec3::new(p.x, p.y, p.z)
    }
}

/// The wire form of a room's control-point filter.
impl From<OneEuroParams> for v1::MarkerFilter {
    fn from(p: OneEuroParams) -> Self {
        Self {
            min_cutoff_hz: p.min_cutoff_hz,
            beta: p.beta,
            d_cutoff_hz: p.d_cutoff_hz,
        }
    }
}

/// A wire filter as core parameters (check [`OneEuroParams::is_valid`] before use).
impl From<v1::MarkerFilter> for OneEuroParams {
    fn from(f: v1::MarkerFilter) -> Self {
        Self {
            min_cutoff_hz: f.min_cutoff_hz,
            beta: f.beta,
            d_cutoff_hz: f.d_cutoff_hz,
        }
    }
}

/// The wire form of a room's bone-level refinement.
impl From<Refinement> for v1::Refine {
    fn from(r: Refinement) -> Self {
        Self {
            iterations: u32::try_from(r.iterations).unwrap_or(u32::MAX),
            strength: r.strength,
        }
    }
}

/// A wire refinement as core settings (check [`Refinement::validate`] before use; a room's
/// refinement always has the regression prior).
impl From<v1::Refine> for Refinement {
    fn from(r: v1::Refine) -> Self {
        Self {
            iterations: r.iterations as usize,
            strength: r.strength,
            from_rest: false,
        }
    }
}

/// The wire form of a skinning (never `SKINNING_UNSPECIFIED`).
impl From<Skinning> for v1::Skinning {
    fn from(s: Skinning) -> Self {
        match s {
            Skinning::Lbs => v1::Skinning::Lbs,
            Skinning::Dqs => v1::Skinning::Dqs,
        }
    }
}

/// A request's `skinning` field in `message_type`: `None` for `SKINNING_UNSPECIFIED` (the
/// model's default).
///
/// # Errors
/// [`WireError`] naming `{message_type}.skinning` for a value that is not a `Skinning`.
pub fn skinning_from_wire(
    message_type: &'static str,
    skinning: i32,
) -> Result<Option<Skinning>, WireError> {
    match v1::Skinning::try_from(skinning) {
        Ok(v1::Skinning::Unspecified) => Ok(None),
        Ok(v1::Skinning::Lbs) => Ok(Some(Skinning::Lbs)),
        Ok(v1::Skinning::Dqs) => Ok(Some(Skinning::Dqs)),
        Err(_) => Err(WireError::new(
            message_type,
            "skinning",
            format!("{skinning} is not a Skinning (0 unspecified, 1 lbs, 2 dqs)"),
        )),
    }
}

/// A box from its corners.
pub fn box3(min: Vec3, max: Vec3) -> v1::Box3 {
    v1::Box3 {
        min: Some(min.into()),
        max: Some(max.into()),
    }
}

/// The public description of a trained model named `name`.
pub fn model_info(name: &str, model: &TrainedModel) -> v1::ModelInfo {
    let rest = &model.rig.rest;
    let (min, max) = rest.bounding_box();
    let (detail_vertices, detail_triangles) = match &model.detail {
        Some(d) => (
            d.regressor.vertex_count() as u32,
            (rest.triangles.len() << (2 * d.levels)) as u32,
        ),
        None => (0, 0),
    };
    v1::ModelInfo {
        name: name.to_owned(),
        base_vertices: rest.vertex_count() as u32,
        base_triangles: rest.triangles.len() as u32,
        detail_vertices,
        detail_triangles,
        control_points: model
            .controls
            .iter()
            .enumerate()
            .map(|(i, c)| v1::ControlPoint {
                id: i as u32,
                name: c.name.clone(),
                vertex: c.vertex,
                rest: Some(rest.positions[c.vertex as usize].into()),
            })
            .collect(),
        bounds: Some(box3(min, max)),
        method: model.method.clone(),
        default_beta: model.beta,
        bones: model.rig.bone_count as u32,
        skinning: v1::Skinning::from(model.skinning) as i32,
    }
}

/// Which mesh a stream carries: the domain side of `crease.v1.Level`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Level {
    /// The skinned base mesh.
    Base,
    /// The detail layer on top (models with one).
    Detail,
}

impl Level {
    /// Both levels, base first (an index per level: `level as usize`).
    pub const ALL: [Level; 2] = [Level::Base, Level::Detail];

    /// The level of a request's `level` field (`LEVEL_UNSPECIFIED` is the base mesh) in
    /// `message_type`.
    ///
    /// # Errors
    /// [`WireError`] naming `{message_type}.level` for a value that is not a `Level`.
    pub fn from_wire(message_type: &'static str, level: i32) -> Result<Level, WireError> {
        match v1::Level::try_from(level) {
            Ok(v1::Level::Unspecified | v1::Level::Base) => Ok(Level::Base),
            Ok(v1::Level::Detail) => Ok(Level::Detail),
            Err(_) => Err(WireError::new(
                message_type,
                "level",
                format!("{level} is not a Level (0 unspecified, 1 base, 2 detail)"),
            )),
        }
    }

    /// The level's name, as `?level=` spells it: `base` or `detail`.
    pub fn name(self) -> &'static str {
        match self {
            Level::Base => "base",
            Level::Detail => "detail",
        }
    }

    /// The level of a WebSocket's `?level=` query (`base` when absent).
    ///
    /// # Errors
    /// [`WireError`] naming `level` for anything but `base` or `detail`.
    pub fn from_query(level: Option<&str>) -> Result<Level, WireError> {
        match level {
            None | Some("base") => Ok(Level::Base),
            Some("detail") => Ok(Level::Detail),
            Some(other) => Err(WireError::new(
                "query",
                "level",
                format!("{other:?}, expected base or detail"),
            )),
        }
    }
}

/// How a stream carries its frames: the domain side of `crease.v1.Encoding` (issue 18).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// Every vertex, quantised (`core::codec`): today's frames, the default.
    #[default]
    Vertices,
    /// The bone transforms and the detail kernel vector (`core::codec::palette`).
    Palette,
}

impl Encoding {
    /// Both encodings, vertices first (an index per encoding: `encoding as usize`).
    pub const ALL: [Encoding; 2] = [Encoding::Vertices, Encoding::Palette];

    /// The encoding of a request's `encoding` field (`ENCODING_UNSPECIFIED` is vertices) in
    /// `message_type`.
    ///
    /// # Errors
    /// [`WireError`] naming `{message_type}.encoding` for a value that is not an `Encoding`.
    pub fn from_wire(message_type: &'static str, encoding: i32) -> Result<Encoding, WireError> {
        match v1::Encoding::try_from(encoding) {
            Ok(v1::Encoding::Unspecified | v1::Encoding::Vertices) => Ok(Encoding::Vertices),
            Ok(v1::Encoding::Palette) => Ok(Encoding::Palette),
            Err(_) => Err(WireError::new(
                message_type,
                "encoding",
                format!("{encoding} is not an Encoding (0 unspecified, 1 vertices, 2 palette)"),
            )),
        }
    }

    /// The encoding's name, as `?encoding=` spells it: `vertices` or `palette`.
    pub fn name(self) -> &'static str {
        match self {
            Encoding::Vertices => "vertices",
            Encoding::Palette => "palette",
        }
    }

    /// The encoding of a WebSocket's `?encoding=` query (`vertices` when absent).
    ///
    /// # Errors
    /// [`WireError`] naming `encoding` for anything but `vertices` or `palette`.
    pub fn from_query(encoding: Option<&str>) -> Result<Encoding, WireError> {
        match encoding {
            None | Some("vertices") => Ok(Encoding::Vertices),
            Some("palette") => Ok(Encoding::Palette),
            Some(other) => Err(WireError::new(
                "query",
                "encoding",
                format!("{other:?}, expected vertices or palette"),
            )),
        }
    }
}

impl From<Encoding> for v1::Encoding {
    fn from(e: Encoding) -> Self {
        match e {
            Encoding::Vertices => v1::Encoding::Vertices,
            Encoding::Palette => v1::Encoding::Palette,
        }
    }
}

impl From<Level> for v1::Level {
    fn from(level: Level) -> Self {
        match level {
            Level::Base => v1::Level::Base,
            Level::Detail => v1::Level::Detail,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodings_convert_both_ways_and_bad_ones_name_the_field() {
        for e in Encoding::ALL {
            assert_eq!(
                Encoding::from_wire("SubscribeRequest", v1::Encoding::from(e) as i32),
                Ok(e)
            );
            assert_eq!(Encoding::from_query(Some(e.name())), Ok(e));
        }
        assert_eq!(
            Encoding::from_wire("SubscribeRequest", 0),
            Ok(Encoding::Vertices)
        );
        assert_eq!(Encoding::from_query(None), Ok(Encoding::Vertices));
        // The wire integers are the proto's: 1 vertices, 2 palette.
        assert_eq!(v1::Encoding::from(Encoding::Palette) as i32, 2);
        let e = Encoding::from_wire("SubscribeRequest", 9).unwrap_err();
        assert_eq!(
            e.to_string(),
            "SubscribeRequest.encoding: 9 is not an Encoding (0 unspecified, 1 vertices, 2 palette)"
        );
        let e = Encoding::from_query(Some("Palette")).unwrap_err();
        assert_eq!(e.field, "encoding");
        assert!(e.message.contains("expected vertices or palette"), "{e}");
    }

    #[test]
    fn skinnings_convert_both_ways_and_bad_ones_name_the_field() {
        for s in Skinning::ALL {
            assert_eq!(
                skinning_from_wire("OpenRoomRequest", v1::Skinning::from(s) as i32),
                Ok(Some(s))
            );
        }
        assert_eq!(skinning_from_wire("OpenRoomRequest", 0), Ok(None));
        // The wire integers are the proto's: 1 lbs, 2 dqs.
        assert_eq!(v1::Skinning::from(Skinning::Lbs) as i32, 1);
        assert_eq!(v1::Skinning::from(Skinning::Dqs) as i32, 2);
        let e = skinning_from_wire("SynthesizeRequest", 5).unwrap_err();
        assert_eq!(
            e.to_string(),
            "SynthesizeRequest.skinning: 5 is not a Skinning (0 unspecified, 1 lbs, 2 dqs)"
        );
    }

    #[test]
    fn levels_convert_both_ways_and_bad_ones_name_the_field() {
        assert_eq!(Level::from_wire("SubscribeRequest", 0), Ok(Level::Base));
        assert_eq!(Level::from_wire("SubscribeRequest", 1), Ok(Level::Base));
        assert_eq!(Level::from_wire("SubscribeRequest", 2), Ok(Level::Detail));
        let e = Level::from_wire("SynthesizeRequest", 7).unwrap_err();
        assert_eq!(
            e.to_string(),
            "SynthesizeRequest.level: 7 is not a Level (0 unspecified, 1 base, 2 detail)"
        );
        // The wire integers are the proto's: 1 base, 2 detail.
        assert_eq!(v1::Level::from(Level::Base) as i32, 1);
        assert_eq!(v1::Level::from(Level::Detail) as i32, 2);
        for l in Level::ALL {
            assert_eq!(Level::from_wire("X", v1::Level::from(l) as i32), Ok(l));
        }
        assert_eq!(Level::from_query(None), Ok(Level::Base));
        assert_eq!(Level::from_query(Some("base")), Ok(Level::Base));
        assert_eq!(Level::from_query(Some("detail")), Ok(Level::Detail));
        let e = Level::from_query(Some("Detail")).unwrap_err();
        assert_eq!(e.field, "level");
        assert!(e.message.contains("expected base or detail"), "{e}");
    }
}
