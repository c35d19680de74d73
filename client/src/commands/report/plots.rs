//! The report's plots, drawn with `plotters` into SVG files: bar charts (per-bone rotation
//! error, per-pose error, stage timings), line plots (per-frame error by method, the bone fit's
//! convergence) and the model-selection grid as a heat map (kernel x kappa, one panel per
//! beta).

use std::path::Path;

use anyhow::{Context, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::renders::heat_color;

/// Plot text. (The SVG backend writes a size of `s` as `s / 1.24` pixels.)
const FONT: &str = "sans-serif";
/// Bar colour.
const BAR: RGBColor = RGBColor(70, 110, 170);
/// Series colours of line plots, cycling.
const SERIES: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
];

/// Draws into an SVG of `size` pixels with `draw`, then writes it to `path`.
fn svg(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
        draw(&root).with_context(|| format!("drawing {}", path.display()))?;
        root.present().map_err(|e| anyhow!("{e}"))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// `value` for an axis label: 3 significant digits, exponent form outside 1e-3..1e4.
pub(super) fn short(value: f64) -> String {
    let a = value.abs();
    if value == 0.0 {
        "0".to_owned()
    } else if !(1e-3..1e4).contains(&a) {
        format!("{value:.2e}")
    } else {
        let digits = (2 - a.log10().floor() as i32).max(0) as usize;
        let text = format!("{value:.digits$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_owned()
        } else {
            text
        }
    }
}

/// A vertical bar per value (short `labels[i]` under bar `i`, every few when there are many), with an
/// optional dot per bar (e.g. the maximum over frames above a mean).
pub(super) fn bars(
    path: &Path,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    labels: &[String],
    values: &[f64],
    dots: Option<&[f64]>,
) -> anyhow::Result<()> {
    let n = values.len().max(1);
    let top = values
        .iter()
        .chain(dots.unwrap_or(&[]))
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let top = if top > 0.0 { top * 1.08 } else { 1.0 };
    let width = (420 + 9 * n as u32).clamp(560, 1100);
    svg(path, (width, 360), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5f64..n as f64 - 0.5, 0f64..top)
            .map_err(|e| anyhow!("{e}"))?;
        let every = n.div_ceil(30).max(1);
        let label = |x: &f64| -> String {
            let i = x.round();
            if (x - i).abs() > 1e-6 || i < 0.0 || i as usize >= labels.len() {
                return String::new();
            }
            labels[i as usize].clone()
        };
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(x_desc)
            .y_desc(y_desc)
            .disable_x_mesh()
            .x_labels(n.div_ceil(every) + 1)
            .x_label_formatter(&label)
            .y_label_formatter(&|y| short(*y))
            .label_style((FONT, 15));
        mesh.draw().map_err(|e| anyhow!("{e}"))?;
        chart
            .draw_series(values.iter().enumerate().map(|(i, &v)| {
                let x = i as f64;
                Rectangle::new([(x - 0.4, 0.0), (x + 0.4, v.max(0.0))], BAR.filled())
            }))
            .map_err(|e| anyhow!("{e}"))?;
        if let Some(dots) = dots {
            chart
                .draw_series(
                    dots.iter()
                        .enumerate()
                        .map(|(i, &v)| Circle::new((i as f64, v), 3, SERIES[1].filled())),
                )
                .map_err(|e| anyhow!("{e}"))?
                .label("max")
                .legend(|(x, y)| Circle::new((x + 10, y), 3, SERIES[1].filled()));
            chart
                .configure_series_labels()
                .border_style(BLACK)
                .background_style(WHITE.mix(0.9))
                .label_font((FONT, 15))
                .draw()
                .map_err(|e| anyhow!("{e}"))?;
        }
        Ok(())
    })
}

/// Horizontal bars, one per `(label, value)`, the value written at each bar's end by `text`,
/// the first item at the top.
pub(super) fn hbars(
    path: &Path,
    title: &str,
    x_desc: &str,
    items: &[(String, f64)],
    text: &dyn Fn(f64) -> String,
) -> anyhow::Result<()> {
    let n = items.len().max(1);
    let top = items.iter().map(|i| i.1).fold(0.0f64, f64::max);
    let top = if top > 0.0 { top * 1.25 } else { 1.0 };
    svg(path, (760, 70 + 26 * n as u32), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, 22))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(200)
            .build_cartesian_2d(0f64..top, -0.5f64..n as f64 - 0.5)
            .map_err(|e| anyhow!("{e}"))?;
        let label = |y: &f64| -> String {
            let i = y.round();
            if (y - i).abs() > 1e-6 || i < 0.0 || i as usize >= n {
                return String::new();
            }
            items
                .get(n - 1 - i as usize)
                .map_or(String::new(), |i| i.0.clone())
        };
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .disable_y_mesh()
            .y_labels(n + 1)
            .y_label_formatter(&label)
            .x_label_formatter(&|x| short(*x))
            .label_style((FONT, 15))
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
        // First item at the top.
        chart
            .draw_series(items.iter().enumerate().map(|(i, (_, s))| {
                let y = (n - 1 - i) as f64;
                Rectangle::new([(0.0, y - 0.32), (s.max(0.0), y + 0.32)], BAR.filled())
            }))
            .map_err(|e| anyhow!("{e}"))?;
        chart
            .draw_series(items.iter().enumerate().map(|(i, (_, s))| {
                let y = (n - 1 - i) as f64;
                Text::new(format!(" {}", text(*s)), (s.max(0.0), y + 0.2), (FONT, 15))
            }))
            .map_err(|e| anyhow!("{e}"))?;
        Ok(())
    })
}

/// One line per `(name, points)`, a log-scale y axis when `log_y`, a dot on every point.
pub(super) fn lines(
    path: &Path,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
    log_y: bool,
) -> anyhow::Result<()> {
    let points = || series.iter().flat_map(|s| s.1.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in points().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        if log_y && y <= 0.0 {
            continue;
        }
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.1, 1.0);
    }
    if x1 - x0 < 1e-12 {
        x1 = x0 + 1.0;
    }
    // Room on the right for the legend, clear of the lines.
    let whole = series
        .iter()
        .all(|s| s.1.iter().all(|p| p.0.fract() == 0.0));
    let x1 = if series.len() > 1 {
        x1 + (x1 - x0) * 0.3
    } else {
        x1
    };
    let x0 = if whole { x0 - 0.3 } else { x0 };
    let (lo, hi) = if log_y {
        (y0 / 1.3, y1 * 1.3)
    } else {
        (0.0, if y1 > 0.0 { y1 * 1.08 } else { 1.0 })
    };
    svg(path, (860, 380), |root| {
        let mut builder = ChartBuilder::on(root);
        builder
            .caption(title, (FONT, 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(76);
        let style = |i: usize| SERIES[i % SERIES.len()];
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .x_desc(x_desc)
                    .y_desc(y_desc)
                    .y_label_formatter(&|y| short(*y))
                    .y_labels(12)
                    .x_label_formatter(&|x| {
                        if !whole {
                            short(*x)
                        } else if x.fract() != 0.0 {
                            String::new()
                        } else {
                            format!("{}", *x as i64)
                        }
                    })
                    .label_style((FONT, 15))
                    .draw()
                    .map_err(|e| anyhow!("{e}"))?;
                for (i, (name, pts)) in series.iter().enumerate() {
                    let color = style(i);
                    let pts: Vec<(f64, f64)> = pts
                        .iter()
                        .copied()
                        .filter(|p| p.1.is_finite() && (!log_y || p.1 > 0.0))
                        .collect();
                    chart
                        .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                        .map_err(|e| anyhow!("{e}"))?
                        .label(name.as_str())
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                        });
                    chart
                        .draw_series(pts.into_iter().map(|p| Circle::new(p, 3, color.filled())))
                        .map_err(|e| anyhow!("{e}"))?;
                }
                if series.len() > 1 {
                    chart
                        .configure_series_labels()
                        .position(SeriesLabelPosition::UpperRight)
                        .border_style(BLACK)
                        .background_style(WHITE.mix(0.9))
                        .label_font((FONT, 15))
                        .draw()
                        .map_err(|e| anyhow!("{e}"))?;
                }
            }};
        }
        if log_y {
            draw!(
                builder
                    .build_cartesian_2d(x0..x1, (lo..hi).log_scale())
                    .map_err(|e| anyhow!("{e}"))?
            );
        } else {
            draw!(
                builder
                    .build_cartesian_2d(x0..x1, lo..hi)
                    .map_err(|e| anyhow!("{e}"))?
            );
        }
        Ok(())
    })
}

/// The selection grid: `values[kernel][kappa][beta]` (mean leave-one-out error), one panel per
/// beta with kernels down and kappas across, cells coloured on a log scale shared by all
/// panels and labelled with their value, the lowest cell outlined.
pub(super) fn selection_grid(
    path: &Path,
    title: &str,
    kernels: &[String],
    kappas: &[f64],
    betas: &[f32],
    values: &[Vec<Vec<f64>>],
) -> anyhow::Result<()> {
    let finite = || {
        values
            .iter()
            .flatten()
            .flatten()
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
    };
    let lo = finite().fold(f64::MAX, f64::min);
    let hi = finite().fold(f64::MIN, f64::max);
    let norm = |v: f64| -> f32 {
        if !(v.is_finite() && v > 0.0) {
            return 1.0;
        }
        if hi <= lo {
            return 0.0;
        }
        ((v.ln() - lo.ln()) / (hi.ln() - lo.ln())) as f32
    };
    let (rows, cols, panels) = (
        kernels.len().max(1),
        kappas.len().max(1),
        betas.len().max(1),
    );
    // One chart: the panels side by side, one empty column between them.
    let stride = cols + 1;
    let columns = panels * stride - 1;
    let width = 200 + 64 * columns as u32;
    let height = 150 + 28 * rows as u32;
    svg(path, (width, height), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, 22))
            .margin(12)
            .margin_top(30)
            .x_label_area_size(44)
            .y_label_area_size(150)
            .build_cartesian_2d(
                (0..columns as i32 - 1).into_segmented(),
                (0..rows as i32).into_segmented(),
            )
            .map_err(|e| anyhow!("{e}"))?;
        let kappa_of = |v: &SegmentValue<i32>| -> String {
            match v {
                SegmentValue::CenterOf(c) if (*c as usize) % stride < cols => {
                    format!("{:e}", kappas[*c as usize % stride])
                }
                _ => String::new(),
            }
        };
        let kernel_of = |v: &SegmentValue<i32>| -> String {
            match v {
                // First kernel at the top.
                SegmentValue::CenterOf(r) if (*r as usize) < rows => {
                    kernels[rows - 1 - *r as usize].clone()
                }
                _ => String::new(),
            }
        };
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(columns)
            .y_labels(rows)
            .x_label_formatter(&kappa_of)
            .y_label_formatter(&kernel_of)
            .x_desc("kappa (one panel per beta)")
            .label_style((FONT, 15))
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
        let best = finite().fold(f64::MAX, f64::min);
        let cell = |c: usize, r: usize| {
            (
                SegmentValue::Exact(c as i32),
                SegmentValue::Exact((rows - 1 - r) as i32 + 1),
            )
        };
        let corner = |c: usize, r: usize| {
            (
                SegmentValue::Exact(c as i32 + 1),
                SegmentValue::Exact((rows - 1 - r) as i32),
            )
        };
        let center = |c: usize, r: usize| {
            (
                SegmentValue::CenterOf(c as i32),
                SegmentValue::CenterOf((rows - 1 - r) as i32),
            )
        };
        let centered = Pos::new(HPos::Center, VPos::Center);
        for (b, beta) in betas.iter().enumerate() {
            let first = b * stride;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("beta {beta}"),
                    (
                        SegmentValue::Exact(first as i32),
                        SegmentValue::Exact(rows as i32),
                    ),
                    (FONT, 17)
                        .into_font()
                        .color(&BLACK)
                        .pos(Pos::new(HPos::Left, VPos::Bottom)),
                )))
                .map_err(|e| anyhow!("{e}"))?;
            for (r, row) in values.iter().enumerate() {
                for (k, kappa_cells) in row.iter().enumerate() {
                    let v = kappa_cells.get(b).copied().unwrap_or(f64::NAN);
                    let c = first + k;
                    let [red, green, blue] = heat_color(norm(v));
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [cell(c, r), corner(c, r)],
                            RGBColor(red, green, blue).filled(),
                        )))
                        .map_err(|e| anyhow!("{e}"))?;
                    if v == best {
                        chart
                            .draw_series(std::iter::once(Rectangle::new(
                                [cell(c, r), corner(c, r)],
                                BLACK.stroke_width(3),
                            )))
                            .map_err(|e| anyhow!("{e}"))?;
                    }
                    let ink = if norm(v) > 0.6 { WHITE } else { BLACK };
                    let text = if v.is_finite() {
                        format!("{v:.2e}")
                    } else {
                        "failed".to_owned()
                    };
                    chart
                        .draw_series(std::iter::once(Text::new(
                            text,
                            center(c, r),
                            (FONT, 12).into_font().color(&ink).pos(centered),
                        )))
                        .map_err(|e| anyhow!("{e}"))?;
                }
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_labels() {
        assert_eq!(short(0.0), "0");
        assert_eq!(short(1.234), "1.23");
        assert_eq!(short(123.4), "123");
        assert_eq!(short(0.01234), "0.0123");
        assert_eq!(short(1.5e-5), "1.50e-5");
        assert_eq!(short(0.001), "0.001");
        assert_eq!(short(2.0), "2");
    }
}
