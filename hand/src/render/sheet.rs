//! Contact sheets: [`SheetLayout`] (where each pose's tiles and label go) and
//! [`contact_sheet`] / [`contact_sheet_with`], which render poses x views into a labelled grid.

use glam::Vec3;

use crease_core::mesh::Mesh;

use super::{
    Camera, GLYPH_ADVANCE, GLYPH_HEIGHT, Image, RenderSettings, Renderer, TILE_MARGIN, View,
};

/// Pixels between cells and around the border of a contact sheet.
pub const SHEET_GAP: u32 = 8;
/// Pixels between the view tiles of one pose: enough to see where one tile ends.
pub const VIEW_GAP: u32 = 2;
/// Background of a contact sheet outside the tiles (white, so the grey tiles stand out).
pub const SHEET_BACKGROUND: [u8; 3] = [255, 255, 255];
/// Colour of pose labels.
pub const LABEL_COLOR: [u8; 3] = [30, 30, 30];
/// Colour of the view name in a tile's corner (quiet, so it does not compete with the mesh).
pub const VIEW_LABEL_COLOR: [u8; 3] = [120, 122, 128];

/// Where things go on a contact sheet: one cell per pose, holding its view tiles side by side
/// (separated by [`VIEW_GAP`]) with the pose label under them, cells in a grid
/// of `columns` cells per row, [`SHEET_GAP`] between cells and around the border.
///
/// `width = gap + columns * (cell_width + gap)` with `cell_width = views * tile_size + (views - 1)
/// * VIEW_GAP`, and `height = gap + rows * (tile_size + label_height + gap)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SheetLayout {
    /// Number of poses (cells).
    pub poses: u32,
    /// Number of views (tiles per cell).
    pub views: u32,
    /// Side of a square tile in pixels.
    pub tile_size: u32,
    /// Cells per row: the requested number, at least 1 and at most `poses` (when there are any).
    pub columns: u32,
    /// Rows of cells.
    pub rows: u32,
    /// Font scale of the labels: 1 up to 399-pixel tiles, 2 from 400, and so on.
    pub label_scale: u32,
    /// Height of the label strip under each cell.
    pub label_height: u32,
}

impl SheetLayout {
    /// The layout of `poses` poses x `views` views in tiles of `tile_size` pixels, `columns`
    /// cells per row.
    pub fn new(poses: usize, views: usize, tile_size: u32, columns: u32) -> SheetLayout {
        let poses = poses as u32;
        let columns = columns.clamp(1, poses.max(1));
        let label_scale = (tile_size / 200).max(1);
        SheetLayout {
            poses,
            views: views as u32,
            tile_size,
            columns,
            rows: poses.div_ceil(columns),
            label_scale,
            label_height: (GLYPH_HEIGHT + 4) * label_scale,
        }
    }

    /// Width of one cell: its tiles and the gaps between them.
    pub fn cell_width(&self) -> u32 {
        self.views * self.tile_size + self.views.saturating_sub(1) * VIEW_GAP
    }

    /// Width of the sheet.
    pub fn width(&self) -> u32 {
        SHEET_GAP + self.columns * (self.cell_width() + SHEET_GAP)
    }

    /// Height of the sheet.
    pub fn height(&self) -> u32 {
        SHEET_GAP + self.rows * (self.tile_size + self.label_height + SHEET_GAP)
    }

    /// Top-left corner of the cell of pose `pose` (row-major).
    pub fn cell_origin(&self, pose: usize) -> (u32, u32) {
        let (col, row) = (pose as u32 % self.columns, pose as u32 / self.columns);
        (
            SHEET_GAP + col * (self.cell_width() + SHEET_GAP),
            SHEET_GAP + row * (self.tile_size + self.label_height + SHEET_GAP),
        )
    }

    /// Top-left corner of the tile of pose `pose`, view `view`.
    pub fn tile_origin(&self, pose: usize, view: usize) -> (u32, u32) {
        let (x, y) = self.cell_origin(pose);
        (x + view as u32 * (self.tile_size + VIEW_GAP), y)
    }
}

/// A contact sheet with [`RenderSettings::default`]. See [`contact_sheet_with`].
pub fn contact_sheet<S: AsRef<str>>(
    tiles: &[(S, &Mesh)],
    views: &[View],
    tile_size: u32,
    columns: u32,
) -> Image {
    contact_sheet_with(tiles, views, tile_size, columns, &RenderSettings::default())
}

/// Renders each `(label, mesh)` of `tiles` in every view of `views` into square tiles of
/// `tile_size` pixels laid out by [`SheetLayout::new`]`(tiles.len(), views.len(), tile_size,
/// columns)`: one cell per mesh with its views side by side, the label under the cell (cut to the
/// cell width) and the view name in each tile's top-left corner.
///
/// All tiles of a view share one camera, fitted ([`Camera::fit`], [`TILE_MARGIN`]) to the
/// bounding box of all the meshes together, so sizes and positions compare across poses.
///
/// # Panics
/// If a mesh has a triangle index out of range.
pub fn contact_sheet_with<S: AsRef<str>>(
    tiles: &[(S, &Mesh)],
    views: &[View],
    tile_size: u32,
    columns: u32,
    settings: &RenderSettings,
) -> Image {
    let layout = SheetLayout::new(tiles.len(), views.len(), tile_size, columns);
    let mut sheet = Image::new(layout.width(), layout.height(), SHEET_BACKGROUND);
    let bounds = tiles
        .iter()
        .filter(|(_, mesh)| !mesh.positions.is_empty())
        .map(|(_, mesh)| mesh.bounding_box())
        .reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)))
        .unwrap_or((Vec3::ZERO, Vec3::ZERO));
    let cameras: Vec<Camera> = views
        .iter()
        .map(|&view| Camera::fit(view, bounds, tile_size, tile_size, TILE_MARGIN))
        .collect();

    let mut renderer = Renderer::new();
    let mut tile = Image::default();
    let view_pad = 3;
    let max_label_chars = (layout.cell_width() / (GLYPH_ADVANCE * layout.label_scale)) as usize;
    for (pose, (label, mesh)) in tiles.iter().enumerate() {
        for (v, (camera, view)) in cameras.iter().zip(views).enumerate() {
            renderer.render_into(
                &mesh.positions,
                &mesh.triangles,
                camera,
                settings,
                &mut tile,
            );
            tile.draw_text(view_pad, view_pad, view.name(), VIEW_LABEL_COLOR, 1);
            let (x, y) = layout.tile_origin(pose, v);
            sheet.blit(&tile, x, y);
        }
        let text: String = label.as_ref().chars().take(max_label_chars).collect();
        let (x, y) = layout.cell_origin(pose);
        let text_y = y + tile_size + 2 * layout.label_scale;
        sheet.draw_text(x, text_y, &text, LABEL_COLOR, layout.label_scale);
    }
    sheet
}
