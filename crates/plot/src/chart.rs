//! Line/scatter chart layout and drawing.

use crate::canvas::{fit_text, text_width, Canvas, Rect, Shape, FRAME, GLYPH, GRID, TEXT, WHITE};
use crate::ticks::{
    format_log_tick, format_tick, log_decades, log_ticks, nice_ticks, sanitize_range,
};
use crate::{Chart, Rgb, Style, PALETTE};

/// Text scale: the 8-pixel font drawn at 16 pixels.
pub const S: i32 = 2;
/// Height of one text line at scale [`S`].
pub const LINE_H: i32 = GLYPH * S;
/// Data line width in pixels.
const LINE_W: i32 = 2;
/// Marker radius in pixels.
const MARKER_R: i32 = 4;
/// Tick mark length in pixels.
const TICK: i32 = 6;

/// An axis: data range in axis coordinates (log10 of the value on a log axis), tick positions
/// in axis coordinates and their labels.
pub struct Axis {
    pub lo: f64,
    pub hi: f64,
    pub ticks: Vec<(f64, String)>,
}

impl Axis {
    /// Linear axis over `[lo, hi]` with at most `n` ticks.
    pub fn linear(lo: f64, hi: f64, n: usize) -> Axis {
        let t = nice_ticks(lo, hi, n);
        let step = if t.len() >= 2 { t[1] - t[0] } else { 1.0 };
        let (a, b) = (t[0], t[t.len() - 1]);
        Axis {
            lo: a,
            hi: b,
            ticks: t.iter().map(|&v| (v, format_tick(v, step))).collect(),
        }
    }

    /// Logarithmic axis over the positive `[lo, hi]`.
    pub fn log(lo: f64, hi: f64) -> Axis {
        let (e0, e1) = log_decades(lo, hi);
        Axis {
            lo: e0 as f64,
            hi: e1 as f64,
            ticks: log_ticks(lo, hi)
                .into_iter()
                .map(|v| (v.log10(), format_log_tick(v)))
                .collect(),
        }
    }

    pub fn label_width(&self) -> i32 {
        self.ticks
            .iter()
            .map(|(_, l)| text_width(l, S))
            .max()
            .unwrap_or(0)
    }

    /// Pixel position of axis coordinate `v` on a pixel span `[p0, p1]` (p1 may be < p0).
    pub fn map(&self, v: f64, p0: f64, p1: f64) -> f64 {
        let span = self.hi - self.lo;
        let f = if span > 0.0 {
            (v - self.lo) / span
        } else {
            0.5
        };
        p0 + f * (p1 - p0)
    }
}

/// Colour of series `i`.
pub fn series_color(explicit: Option<Rgb>, i: usize) -> Rgb {
    explicit.unwrap_or(PALETTE[i % PALETTE.len()])
}

/// Draws the chart title centred at the top of `area`; returns the y below it.
pub fn draw_title(c: &mut Canvas, title: &str, area: Rect) -> i32 {
    if title.is_empty() {
        return area.y0 + 12;
    }
    let t = fit_text(title, S, area.w() - 20);
    let x = area.x0 + (area.w() - text_width(&t, S)) / 2;
    c.text(x, area.y0 + 10, &t, S, TEXT);
    area.y0 + 10 + LINE_H + 14
}

/// Draws the y-axis label rotated along the left edge of `area`, centred on `plot`.
pub fn draw_y_label(c: &mut Canvas, label: &str, area: Rect, plot: Rect) {
    if label.is_empty() {
        return;
    }
    let t = fit_text(label, S, plot.h() + 40);
    let y = plot.y0 + (plot.h() + text_width(&t, S)) / 2;
    c.text_up(area.x0 + 10, y, &t, S, TEXT);
}

/// Draws the x-axis label centred under `plot`, at `y`.
pub fn draw_x_label(c: &mut Canvas, label: &str, area: Rect, plot: Rect, y: i32) {
    if label.is_empty() {
        return;
    }
    let t = fit_text(label, S, area.w() - 20);
    let x = (plot.x0 + (plot.w() - text_width(&t, S)) / 2)
        .clamp(area.x0 + 4, (area.x1 - 4 - text_width(&t, S)).max(area.x0));
    c.text(x, y, &t, S, TEXT);
}

/// Draws horizontal grid lines, y tick marks and labels of `axis` for `plot`.
pub fn draw_y_axis(c: &mut Canvas, axis: &Axis, plot: Rect) {
    let (p0, p1) = ((plot.y1 - 1) as f64, plot.y0 as f64);
    for (v, label) in &axis.ticks {
        let y = axis.map(*v, p0, p1).round() as i32;
        c.fill(
            Rect {
                x0: plot.x0,
                y0: y,
                x1: plot.x1,
                y1: y + 1,
            },
            GRID,
        );
        c.fill(
            Rect {
                x0: plot.x0 - TICK,
                y0: y,
                x1: plot.x0,
                y1: y + 1,
            },
            FRAME,
        );
        let w = text_width(label, S);
        c.text(plot.x0 - TICK - 4 - w, y - LINE_H / 2, label, S, TEXT);
    }
}

/// The x axis over `[lo, hi]` with as many ticks as fit in `width` pixels without the labels
/// touching.
fn fit_x_axis(lo: f64, hi: f64, width: i32) -> Axis {
    let mut n = (width / 100).clamp(2, 11) as usize;
    loop {
        let a = Axis::linear(lo, hi, n);
        let k = a.ticks.len().max(2) as i32 - 1;
        if n <= 2 || width / k >= a.label_width() + 2 * GLYPH {
            return a;
        }
        n -= 1;
    }
}

/// Draws vertical grid lines, x tick marks and labels of `axis` for `plot`, labels at `y`.
fn draw_x_axis(c: &mut Canvas, axis: &Axis, plot: Rect, area: Rect) {
    let (p0, p1) = (plot.x0 as f64, (plot.x1 - 1) as f64);
    for (v, label) in &axis.ticks {
        let x = axis.map(*v, p0, p1).round() as i32;
        c.fill(
            Rect {
                x0: x,
                y0: plot.y0,
                x1: x + 1,
                y1: plot.y1,
            },
            GRID,
        );
        c.fill(
            Rect {
                x0: x,
                y0: plot.y1,
                x1: x + 1,
                y1: plot.y1 + TICK,
            },
            FRAME,
        );
        let w = text_width(label, S);
        let lx = (x - w / 2).clamp(area.x0 + 2, (area.x1 - 2 - w).max(area.x0));
        c.text(lx, plot.y1 + TICK + 4, label, S, TEXT);
    }
}

/// A legend entry: name, colour, whether it shows a line, a marker, and whether it is dashed.
pub struct Entry {
    pub name: String,
    pub color: Rgb,
    pub line: bool,
    pub marker: Option<Shape>,
    pub dashed: bool,
}

/// Room a legend may take: its height decides the text scale, names are cut to `text_w`.
#[derive(Clone, Copy)]
pub struct LegendRoom {
    pub max_h: i32,
    pub text_w: i32,
}

impl LegendRoom {
    /// Inside a line chart's plot: names up to half its width.
    pub fn inside(plot: Rect) -> LegendRoom {
        LegendRoom {
            max_h: plot.h(),
            text_w: plot.w() / 2 - 60,
        }
    }
}

/// Size `(w, h)` and text scale of a legend of `entries` fitted into `room`.
pub fn legend_size(entries: &[Entry], room: LegendRoom) -> (i32, i32, i32) {
    let n = entries.len() as i32;
    // Many entries: the half-size font keeps the box inside the plot.
    let scale = if n * (LINE_H + 6) + 12 > room.max_h * 3 / 5 {
        1
    } else {
        S
    };
    let row = GLYPH * scale + if scale == 1 { 4 } else { 6 };
    let max_text = room.text_w.max(GLYPH * scale * 4);
    let tw = entries
        .iter()
        .map(|e| text_width(&fit_text(&e.name, scale, max_text), scale))
        .max()
        .unwrap_or(0);
    (12 + 30 + 8 + tw + 12, 8 + n * row + 4, scale)
}

/// Draws the legend box with its top-left corner at `(x, y)`.
pub fn draw_legend_at(c: &mut Canvas, entries: &[Entry], room: LegendRoom, x: i32, y: i32) {
    let (w, h, scale) = legend_size(entries, room);
    let row = GLYPH * scale + if scale == 1 { 4 } else { 6 };
    let max_text = room.text_w.max(GLYPH * scale * 4);
    let bx = Rect {
        x0: x,
        y0: y,
        x1: x + w,
        y1: y + h,
    };
    c.fill(bx, WHITE);
    c.outline(bx, 1, FRAME);
    let everywhere = Rect {
        x0: i32::MIN / 2,
        y0: i32::MIN / 2,
        x1: i32::MAX / 2,
        y1: i32::MAX / 2,
    };
    for (k, e) in entries.iter().enumerate() {
        let ty = y + 8 + k as i32 * row;
        let cy = (ty + GLYPH * scale / 2) as f64;
        let (sx0, sx1) = ((x + 12) as f64, (x + 42) as f64);
        if e.line {
            let mut phase = 0.0;
            let dash = e.dashed.then_some((8.0, 5.0, &mut phase));
            c.line((sx0, cy), (sx1, cy), 3, e.color, everywhere, dash);
        }
        if let Some(shape) = e.marker {
            c.marker((sx0 + sx1) / 2.0, cy, shape, MARKER_R, e.color, everywhere);
        }
        if !e.line && e.marker.is_none() {
            // A colour swatch (bars).
            c.fill(
                Rect {
                    x0: x + 14,
                    y0: ty,
                    x1: x + 40,
                    y1: ty + GLYPH * scale,
                },
                e.color,
            );
        }
        c.text(x + 50, ty, &fit_text(&e.name, scale, max_text), scale, TEXT);
    }
}

/// Draws a legend in the corner of `plot` that hides the fewest of the `pixels` (data point
/// positions); top right wins ties.
fn draw_legend(c: &mut Canvas, entries: &[Entry], plot: Rect, pixels: &[(i32, i32)]) {
    if entries.is_empty() {
        return;
    }
    let room = LegendRoom::inside(plot);
    let (w, h, _) = legend_size(entries, room);
    let m = 8;
    let corners = [
        (plot.x1 - m - w, plot.y0 + m),
        (plot.x0 + m, plot.y0 + m),
        (plot.x1 - m - w, plot.y1 - m - h),
        (plot.x0 + m, plot.y1 - m - h),
    ];
    let (mut best, mut best_hits) = (corners[0], usize::MAX);
    for &(x, y) in &corners {
        let r = Rect {
            x0: x - 4,
            y0: y - 4,
            x1: x + w + 4,
            y1: y + h + 4,
        };
        let hits = pixels
            .iter()
            .filter(|&&(px, py)| px >= r.x0 && px < r.x1 && py >= r.y0 && py < r.y1)
            .count();
        if hits < best_hits {
            best = (x, y);
            best_hits = hits;
        }
    }
    draw_legend_at(c, entries, room, best.0, best.1);
}

/// Draws `chart` inside `area` of `c`.
pub fn draw(c: &mut Canvas, chart: &Chart, area: Rect) {
    // Data in axis coordinates; invalid points become NaN so lines break there.
    let data: Vec<Vec<(f64, f64)>> = chart
        .series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .map(|&(x, y)| {
                    let y = if chart.log_y {
                        if y > 0.0 {
                            y.log10()
                        } else {
                            f64::NAN
                        }
                    } else {
                        y
                    };
                    if x.is_finite() && y.is_finite() {
                        (x, y)
                    } else {
                        (f64::NAN, f64::NAN)
                    }
                })
                .collect()
        })
        .collect();
    let valid = || data.iter().flatten().filter(|p| p.0.is_finite());
    let has_data = valid().next().is_some();
    let (mut xmin, mut xmax, mut ymin, mut ymax) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in valid() {
        xmin = xmin.min(x);
        xmax = xmax.max(x);
        ymin = ymin.min(y);
        ymax = ymax.max(y);
    }

    // Vertical layout: title, plot, tick labels, x label.
    let top = draw_title(c, &chart.title, area);
    let bottom = area.y1
        - 8
        - (TICK + 4 + LINE_H + 8)
        - if chart.x_label.is_empty() {
            0
        } else {
            LINE_H + 4
        };
    let plot_h = (bottom - top).max(20);
    let yaxis = if chart.log_y {
        match chart.y_range {
            Some((a, b)) => Axis::log(a, b),
            None if has_data => Axis::log(10f64.powf(ymin), 10f64.powf(ymax)),
            None => Axis::log(1.0, 10.0),
        }
    } else if let Some((a, b)) = chart.y_range {
        Axis::linear(a, b, (plot_h / 45).clamp(2, 10) as usize)
    } else if has_data {
        Axis::linear(ymin, ymax, (plot_h / 45).clamp(2, 10) as usize)
    } else {
        Axis::linear(0.0, 1.0, 3)
    };
    // Horizontal layout: y label, tick labels, plot, margin.
    let left = area.x0
        + 10
        + if chart.y_label.is_empty() {
            0
        } else {
            LINE_H + 12
        }
        + yaxis.label_width()
        + TICK
        + 6;
    let right = area.x1 - 24;
    let plot = Rect {
        x0: left,
        y0: top,
        x1: left + (right - left).max(20),
        y1: top + plot_h,
    };
    let (xlo, xhi) = match chart.x_range {
        Some((a, b)) => sanitize_range(a, b),
        None if has_data => sanitize_range(xmin, xmax),
        None => (0.0, 1.0),
    };
    let xaxis = fit_x_axis(xlo, xhi, plot.w());

    draw_y_axis(c, &yaxis, plot);
    draw_x_axis(c, &xaxis, plot, area);
    draw_y_label(c, &chart.y_label, area, plot);
    draw_x_label(
        c,
        &chart.x_label,
        area,
        plot,
        plot.y1 + TICK + 4 + LINE_H + 8,
    );

    let to_px = |(x, y): (f64, f64)| {
        (
            xaxis.map(x, plot.x0 as f64, (plot.x1 - 1) as f64),
            yaxis.map(y, (plot.y1 - 1) as f64, plot.y0 as f64),
        )
    };
    let mut entries = Vec::new();
    let mut occupied = Vec::new();
    for (i, (s, pts)) in chart.series.iter().zip(&data).enumerate() {
        let color = series_color(s.color, i);
        let n_valid = pts.iter().filter(|p| p.0.is_finite()).count();
        // Beyond the palette, repeated colours are told apart by dashes.
        let dashed = s.style == Style::Dashed || (i >= PALETTE.len() && s.color.is_none());
        let line = s.style != Style::Markers;
        let markers = matches!(s.style, Style::Markers | Style::LineMarkers) || n_valid == 1;
        let shape = Shape::nth(i);
        if line {
            let mut phase = 0.0;
            let mut prev: Option<(f64, f64)> = None;
            for &p in pts {
                if !p.0.is_finite() {
                    prev = None;
                    continue;
                }
                let q = to_px(p);
                if let Some(a) = prev {
                    let dash = dashed.then_some((10.0, 6.0, &mut phase));
                    c.line(a, q, LINE_W, color, plot, dash);
                }
                prev = Some(q);
            }
        }
        if markers {
            for &p in pts.iter().filter(|p| p.0.is_finite()) {
                let (x, y) = to_px(p);
                c.marker(x, y, shape, MARKER_R, color, plot);
            }
        }
        // A sample of positions for the legend placement.
        let every = (pts.len() / 2000).max(1);
        occupied.extend(
            pts.iter()
                .step_by(every)
                .filter(|p| p.0.is_finite())
                .map(|&p| {
                    let (x, y) = to_px(p);
                    (x.round() as i32, y.round() as i32)
                }),
        );
        if !s.name.is_empty() {
            entries.push(Entry {
                name: s.name.clone(),
                color,
                line,
                marker: markers.then_some(shape),
                dashed,
            });
        }
    }
    if !has_data {
        let msg = "no data";
        c.text(
            plot.x0 + (plot.w() - text_width(msg, S)) / 2,
            plot.y0 + (plot.h() - LINE_H) / 2,
            msg,
            S,
            FRAME,
        );
    }
    // The frame lies just outside the plot so data on the axis limits stays visible.
    c.outline(frame_of(plot), 2, FRAME);
    draw_legend(c, &entries, plot, &occupied);
}

/// The 2-pixel frame rectangle drawn just outside `plot`.
pub fn frame_of(plot: Rect) -> Rect {
    Rect {
        x0: plot.x0 - 2,
        y0: plot.y0 - 2,
        x1: plot.x1 + 2,
        y1: plot.y1 + 2,
    }
}
