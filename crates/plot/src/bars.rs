//! Stacked bar chart layout and drawing.

use crate::canvas::{fit_text, text_width, Canvas, Rect, FRAME, GLYPH, TEXT};
use crate::chart::{
    draw_legend_at, draw_title, draw_x_label, draw_y_axis, draw_y_label, frame_of, legend_size,
    Axis, Entry, LegendRoom, LINE_H, S,
};
use crate::ticks::format_value;
use crate::{BarChart, PALETTE};

/// Segment value counted in a bar: missing, negative and non-finite values count as 0.
fn value(chart: &BarChart, cat: usize, seg: usize) -> f64 {
    chart
        .values
        .get(cat)
        .and_then(|v| v.get(seg))
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .unwrap_or(0.0)
}

/// Draws `chart` inside `area` of `c`; the legend sits in a column right of the plot.
pub fn draw(c: &mut Canvas, chart: &BarChart, area: Rect) {
    let ncat = chart.categories.len();
    let nseg = chart.segments.len();
    let totals: Vec<f64> = (0..ncat)
        .map(|k| (0..nseg).map(|s| value(chart, k, s)).sum())
        .collect();
    let max_total = totals.iter().copied().fold(0.0, f64::max);

    // Category captions: up to two lines each.
    let captions: Vec<Vec<&str>> = chart
        .categories
        .iter()
        .map(|c| c.split('\n').take(2).collect())
        .collect();
    let cap_lines = captions.iter().map(Vec::len).max().unwrap_or(1).max(1) as i32;

    let top = draw_title(c, &chart.title, area);
    let bottom = area.y1
        - 8
        - (6 + 4 + cap_lines * (LINE_H + 4) + 4)
        - if chart.x_label.is_empty() {
            0
        } else {
            LINE_H + 4
        };
    let plot_h = (bottom - top).max(20);
    // Room above the tallest bar for its total.
    let ymax = if max_total > 0.0 {
        max_total * 1.08
    } else {
        1.0
    };
    let yaxis = Axis::linear(0.0, ymax, (plot_h / 45).clamp(2, 10) as usize);

    let entries: Vec<Entry> = chart
        .segments
        .iter()
        .enumerate()
        .map(|(i, name)| Entry {
            name: name.clone(),
            color: PALETTE[i % PALETTE.len()],
            line: false,
            marker: None,
            dashed: false,
        })
        .collect();
    // A column right of the plot, up to a third of the width.
    let room = LegendRoom {
        max_h: plot_h,
        text_w: area.w() / 3 - 70,
    };
    let legend_w = if entries.is_empty() {
        0
    } else {
        legend_size(&entries, room).0 + 16
    };
    let left = area.x0
        + 10
        + if chart.y_label.is_empty() {
            0
        } else {
            LINE_H + 12
        }
        + yaxis.label_width()
        + 12;
    let right = area.x1 - 16 - legend_w;
    let plot = Rect {
        x0: left,
        y0: top,
        x1: left + (right - left).max(20),
        y1: top + plot_h,
    };
    draw_y_axis(c, &yaxis, plot);
    draw_y_label(c, &chart.y_label, area, plot);

    let y_of = |v: f64| yaxis.map(v, (plot.y1 - 1) as f64, plot.y0 as f64);
    let slot = plot.w() as f64 / ncat.max(1) as f64;
    let bar_w = (slot * 0.6).clamp(4.0, 160.0);
    // One caption scale for all bars: half size when some caption is too wide for its slot.
    let widest = captions
        .iter()
        .flatten()
        .map(|l| text_width(l, S))
        .max()
        .unwrap_or(0);
    let cap_scale = if widest <= slot as i32 - 6 { S } else { 1 };
    for (k, caption) in captions.iter().enumerate() {
        let cx = plot.x0 as f64 + slot * (k as f64 + 0.5);
        let (x0, x1) = (
            (cx - bar_w / 2.0).round() as i32,
            (cx + bar_w / 2.0).round() as i32,
        );
        let mut acc = 0.0;
        for s in 0..nseg {
            let v = value(chart, k, s);
            if v <= 0.0 {
                continue;
            }
            let (ya, yb) = (y_of(acc).round() as i32, y_of(acc + v).round() as i32);
            acc += v;
            c.fill(
                Rect {
                    x0,
                    y0: yb.min(ya),
                    x1,
                    y1: ya.max(yb) + 1,
                },
                PALETTE[s % PALETTE.len()],
            );
        }
        if acc > 0.0 {
            c.outline(
                Rect {
                    x0,
                    y0: y_of(acc).round() as i32,
                    x1,
                    y1: plot.y1,
                },
                1,
                FRAME,
            );
            // The bar's total above it, half size when it would not fit the slot.
            let label = format_value(totals[k]);
            let scale = if text_width(&label, S) <= slot as i32 - 4 {
                S
            } else {
                1
            };
            let ly = y_of(acc).round() as i32 - GLYPH * scale - 4;
            c.text(
                cx.round() as i32 - text_width(&label, scale) / 2,
                ly.max(plot.y0 + 2),
                &label,
                scale,
                TEXT,
            );
        }
        // Caption lines, centred under the bar.
        let scale = cap_scale;
        for (j, line) in caption.iter().enumerate() {
            let t = fit_text(line, scale, slot as i32 - 4);
            let w = text_width(&t, scale);
            c.text(
                cx.round() as i32 - w / 2,
                plot.y1 + 10 + j as i32 * (LINE_H + 4),
                &t,
                scale,
                TEXT,
            );
        }
    }
    draw_x_label(
        c,
        &chart.x_label,
        area,
        plot,
        plot.y1 + 10 + cap_lines * (LINE_H + 4) + 4,
    );
    c.outline(frame_of(plot), 2, FRAME);
    if ncat == 0 {
        let msg = "no data";
        c.text(
            plot.x0 + (plot.w() - text_width(msg, S)) / 2,
            plot.y0 + (plot.h() - LINE_H) / 2,
            msg,
            S,
            FRAME,
        );
    }
    if !entries.is_empty() {
        // The legend uses its own scale choice; place it in the right-hand column.
        draw_legend_at(c, &entries, room, plot.x1 + 16, plot.y0);
    }
}
