//! The report's figures, drawn with `plotters`: line/scatter charts (one or several panels over
//! a shared x axis, linear or logarithmic y), stacked bars, and a scatter coloured by a value
//! with its colour bar. Every figure is written twice, `NAME.svg` (vector, text as text) and
//! `NAME.png` (raster, antialiased), from the same layout.
//!
//! * Text is set in DejaVu Sans, shipped in `assets/fonts` and rasterised in pure Rust
//!   (`ab_glyph`, in the `text` module): no system font or library is needed, and the PNG is the same
//!   on every machine. The SVG names the family `sans-serif`, so a viewer uses its own sans
//!   font.
//! * The PNG is drawn at [`SUPERSAMPLE`] times its size and averaged down: plotters' raster
//!   lines wider than a pixel, markers and bars have hard edges otherwise.
//! * Colours come from [`PALETTE`] (Okabe–Ito, colour-blind safe); markers also change shape
//!   from series to series.
//! * Non-finite values are skipped (a line breaks there), values ≤ 0 on a log axis too;
//!   empty and constant data still give a readable figure. Drawing never panics on data.
//! * Same figure, same bytes: nothing depends on time, threads or hashing order.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::io;
use std::path::Path;
use std::sync::Once;
use text::Typeset;

mod text;

/// An RGB colour.
pub type Rgb = [u8; 3];

/// Colour-blind-safe palette (Okabe & Ito; yellow, which does not read on white, replaced by
/// a wine red): series `i` gets `PALETTE[i % 8]`.
pub const PALETTE: [Rgb; 8] = [
    [0x00, 0x72, 0xb2], // blue
    [0xd5, 0x5e, 0x00], // vermillion
    [0x00, 0x9e, 0x73], // bluish green
    [0xe6, 0x9f, 0x00], // orange
    [0xcc, 0x79, 0xa7], // reddish purple
    [0x56, 0xb4, 0xe9], // sky blue
    [0x00, 0x00, 0x00], // black
    [0x88, 0x22, 0x55], // wine
];

/// Grey of reference curves (ideal speedup, tolerance).
pub const REFERENCE: Rgb = [120, 120, 120];

/// Width of every figure, in pixels of the PNG and user units of the SVG.
pub const WIDTH: u32 = 1600;
/// Height of a one-panel figure.
pub const HEIGHT: u32 = 1000;
/// Height of one panel of a multi-panel figure.
pub const PANEL_HEIGHT: u32 = 560;
/// The PNG is drawn this many times larger, then each block of pixels averaged.
pub const SUPERSAMPLE: u32 = 2;
/// Widest figure (stacked bars with many categories).
const MAX_WIDTH: u32 = 4096;

/// The family the font is registered under, and the family the SVG names.
const FAMILY: &str = "sans-serif";
/// DejaVu Sans (Bitstream Vera licence, `assets/fonts/LICENSE-DejaVu.txt`).
const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

// Text sizes and widths in figure pixels (multiplied by the drawing scale).
const TITLE: f64 = 40.0;
const AXIS_LABEL: f64 = 34.0;
const TICK_LABEL: f64 = 28.0;
const LEGEND: f64 = 28.0;
const LINE_W: f64 = 3.0;
const MARKER_R: f64 = 7.0;
const MARGIN: f64 = 24.0;

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Style {
    /// Solid line through the points (a lone point is shown as a marker).
    #[default]
    Line,
    /// Markers only (scatter).
    // No report figure is a bare scatter yet; the tests draw it.
    #[allow(dead_code)]
    Markers,
    /// Line with a marker at every point.
    LineMarkers,
    /// Dashed line: reference curves such as the ideal speedup.
    Dashed,
}

/// One named data series.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Series {
    /// Legend entry (empty: not in the legend).
    pub name: String,
    /// `(x, y)` points in drawing order; non-finite points are skipped and break the line.
    pub points: Vec<(f64, f64)>,
    /// Line, markers or both.
    pub style: Style,
    /// Colour; `None` takes the palette colour of the series' position.
    pub color: Option<Rgb>,
}

impl Series {
    /// A series with the palette colour of its position in the chart.
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Series {
        Series {
            name: name.into(),
            points,
            style,
            color: None,
        }
    }

    /// The same series drawn in colour `c`.
    pub fn with_color(mut self, c: Rgb) -> Series {
        self.color = Some(c);
        self
    }
}

/// A line/scatter chart.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LineChart {
    /// What is shown.
    pub title: String,
    /// Quantity and unit, e.g. `time (s)`.
    pub x_label: String,
    /// Quantity and unit, e.g. `max interpenetration (mm)`.
    pub y_label: String,
    /// The curves; a legend names them when there are two or more.
    pub series: Vec<Series>,
    /// Logarithmic y axis (values ≤ 0 are then skipped).
    pub log_y: bool,
    /// x-axis range; `None` fits the data. Panels over the same time span share it.
    pub x_range: Option<(f64, f64)>,
    /// y-axis range (positive values on a log axis); `None` fits the data.
    pub y_range: Option<(f64, f64)>,
}

/// A stacked bar chart: one bar per category, one stacked segment per entry of `segments`,
/// the bar's total written above it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BarChart {
    /// What is shown.
    pub title: String,
    /// Quantity and unit of the bar heights, e.g. `time (s)`.
    pub y_label: String,
    /// Bar captions; `\n` splits a caption over two lines.
    pub categories: Vec<String>,
    /// Segment names (the legend), bottom to top.
    pub segments: Vec<String>,
    /// `values[category][segment]`; missing, negative or non-finite values count as 0.
    pub values: Vec<Vec<f64>>,
}

/// Points coloured by a value, with a colour bar: a section through a bed, a map of a field.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScatterMap {
    /// What is shown.
    pub title: String,
    /// Quantity and unit, e.g. `x (m)`.
    pub x_label: String,
    /// Quantity and unit, e.g. `z (m)`.
    pub y_label: String,
    /// Quantity and unit of the colour, e.g. `compacity (-)`.
    pub value_label: String,
    /// `(x, y, value)`; a point with a non-finite coordinate or value is skipped.
    pub points: Vec<(f64, f64, f64)>,
    /// Marker radius in figure pixels.
    pub radius: f64,
    /// Range of the colour scale; `None` fits the values.
    pub value_range: Option<(f64, f64)>,
}

/// A figure: what one `NAME.svg` / `NAME.png` pair shows.
#[derive(Clone, Debug, PartialEq)]
pub enum Figure {
    /// Charts one above the other (quantities of different units over one x axis); an empty
    /// list gives one empty chart.
    Panels(Vec<LineChart>),
    /// Stacked bars, wider with many categories.
    Bars(BarChart),
    /// A scatter coloured by value: the section pictures of a track run.
    Map(ScatterMap),
}

impl Figure {
    /// One line/scatter chart.
    pub fn chart(c: LineChart) -> Figure {
        Figure::Panels(vec![c])
    }

    /// Size in pixels of the PNG (and user units of the SVG).
    pub fn size(&self) -> (u32, u32) {
        match self {
            Figure::Panels(p) if p.len() > 1 => (WIDTH, PANEL_HEIGHT * p.len() as u32),
            Figure::Panels(_) | Figure::Map(_) => (WIDTH, HEIGHT),
            Figure::Bars(b) => (
                WIDTH.max(150 * b.categories.len() as u32).min(MAX_WIDTH),
                HEIGHT,
            ),
        }
    }
}

/// Writes `fig` as `dir/NAME.svg` and `dir/NAME.png`, each atomically (temporary file, then
/// rename).
pub fn write_figure(dir: &Path, name: &str, fig: &Figure) -> io::Result<()> {
    let svg = render_svg(fig)?;
    let png = render_png(fig)?;
    write_atomic(&dir.join(format!("{name}.svg")), svg.as_bytes())?;
    write_atomic(&dir.join(format!("{name}.png")), &png)
}

/// `fig` as an SVG document.
pub fn render_svg(fig: &Figure) -> io::Result<String> {
    register_font();
    let mut svg = String::new();
    {
        let root = Typeset {
            inner: SVGBackend::with_string(&mut svg, fig.size()),
            raster: false,
        }
        .into_drawing_area();
        draw(&root, fig, 1.0)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// `fig` as a PNG file's bytes (8-bit RGB).
pub fn render_png(fig: &Figure) -> io::Result<Vec<u8>> {
    register_font();
    let (w, h) = fig.size();
    let k = SUPERSAMPLE;
    let mut big = vec![0u8; (w * k * h * k * 3) as usize];
    {
        let root = Typeset {
            inner: BitMapBackend::with_buffer(&mut big, (w * k, h * k)),
            raster: true,
        }
        .into_drawing_area();
        draw(&root, fig, f64::from(k))?;
        root.present().map_err(err)?;
    }
    encode_png(&downsample(&big, w, h, k), w, h)
}

/// Registers the shipped font under [`FAMILY`], once per process.
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // plotters' own text styles look the family up (the text itself is set by
        // `Typeset`). The font is part of the binary: failing to parse it is a build defect.
        if plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_err() {
            panic!("the embedded font assets/fonts/DejaVuSans.ttf does not parse");
        }
    });
}

fn err(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(e.to_string())
}

/// Averages each `k`×`k` block of the RGB image `big` (`w·k` × `h·k`) into one pixel.
fn downsample(big: &[u8], w: u32, h: u32, k: u32) -> Vec<u8> {
    let (w, h, k) = (w as usize, h as usize, k as usize);
    let row = w * k * 3;
    let mut out = vec![0u8; w * h * 3];
    let n = (k * k) as u32;
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0u32; 3];
            for dy in 0..k {
                let base = (y * k + dy) * row + x * k * 3;
                for p in big[base..base + k * 3].chunks_exact(3) {
                    for c in 0..3 {
                        sum[c] += u32::from(p[c]);
                    }
                }
            }
            let o = (y * w + x) * 3;
            for c in 0..3 {
                // Rounded mean.
                out[o + c] = ((sum[c] + n / 2) / n) as u8;
            }
        }
    }
    out
}

fn encode_png(rgb: &[u8], w: u32, h: u32) -> io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().map_err(err)?;
        writer.write_image_data(rgb).map_err(err)?;
        writer.finish().map_err(err)?;
    }
    Ok(bytes)
}

/// Writes `bytes` to `path` through a temporary sibling file and a rename.
fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write as _;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = std::path::PathBuf::from(tmp);
    let res = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    res
}

type Area<DB> = DrawingArea<DB, Shift>;

/// Draws `fig` on `root`, every length multiplied by `s` (1 for the SVG, [`SUPERSAMPLE`] for
/// the PNG).
fn draw<DB: DrawingBackend>(root: &Area<DB>, fig: &Figure, s: f64) -> io::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    match fig {
        Figure::Panels(charts) => {
            let empty = [LineChart::default()];
            let charts = if charts.is_empty() {
                &empty[..]
            } else {
                charts
            };
            // One y label area and legend column for all panels: their x axes line up.
            let y_area = y_label_area(
                root,
                charts.iter().flat_map(|ch| Axes::of(ch).y_label_guess()),
                s,
            );
            let lw = charts
                .iter()
                .map(|ch| legend_width(root, &line_entries(ch), s))
                .max()
                .unwrap_or(0);
            for (area, ch) in root.split_evenly((charts.len(), 1)).iter().zip(charts) {
                draw_lines(area, ch, (y_area, lw), s)?;
            }
        }
        Figure::Bars(b) => draw_bars(root, b, s)?,
        Figure::Map(m) => draw_map(root, m, s)?,
    }
    Ok(())
}

fn rgb(c: Rgb) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

fn font(size: f64, s: f64) -> TextStyle<'static> {
    (FAMILY, size * s).into_font().color(&BLACK)
}

/// Pixels for `v` figure pixels at scale `s`.
fn px(v: f64, s: f64) -> u32 {
    (v * s).round().max(1.0) as u32
}

/// Makes `[lo, hi]` a usable, non-empty, finite range: non-finite bounds give `[0, 1]`,
/// swapped bounds are ordered, a degenerate range (constant data) is widened around its value.
fn sanitize_range(lo: f64, hi: f64) -> (f64, f64) {
    const MAX_ABS: f64 = 1e300;
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let (lo, hi) = (lo.min(hi).max(-MAX_ABS), hi.max(lo).min(MAX_ABS));
    let scale = lo.abs().max(hi.abs());
    if hi - lo <= scale * 1e-12 {
        // Constant data: ±5 % of the value (±1 around zero).
        let d = if scale == 0.0 { 1.0 } else { scale * 0.05 };
        return (lo - d, hi + d);
    }
    (lo, hi)
}

/// Smallest and largest of the finite `values`, if any.
fn span(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    (lo <= hi).then_some((lo, hi))
}

/// Label of tick `v` on an axis from `lo` to `hi`: as few decimals as the value needs,
/// scientific notation for very large or small magnitudes.
fn tick_label(v: f64, lo: f64, hi: f64) -> String {
    let span = (hi - lo).abs();
    let tol = span * 1e-6;
    if v.abs() <= span * 1e-9 {
        return "0".into();
    }
    let mag = lo.abs().max(hi.abs());
    if !(1e-3..1e5).contains(&mag) {
        for p in 0..8 {
            let t = format!("{v:.p$e}");
            if t.parse::<f64>().is_ok_and(|b| (b - v).abs() <= tol) {
                return t;
            }
        }
        return format!("{v:.3e}");
    }
    for d in 0..10 {
        let t = format!("{v:.d$}");
        if t.parse::<f64>().is_ok_and(|b| (b - v).abs() <= tol) {
            return t;
        }
    }
    format!("{v}")
}

/// `v` to 4 significant digits (a bar's total, a colour bar's tick).
fn sig4(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        "0".into()
    } else if (1e-3..1e5).contains(&v.abs()) {
        let d = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.d$}")
    } else {
        format!("{v:.3e}")
    }
}

/// `10` with exponent `e` in superscript digits: `10⁻⁴`.
fn pow10_label(e: i32) -> String {
    const SUP: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut t = String::from("10");
    if e < 0 {
        t.push('⁻');
    }
    for d in e.unsigned_abs().to_string().bytes() {
        t.push(SUP[usize::from(d - b'0')]);
    }
    t
}

/// One legend entry: name, colour, how its sample is drawn (`None`: a filled square).
struct Entry {
    name: String,
    color: RGBColor,
    style: Option<Style>,
    marker: usize,
}

/// Width of the legend column for `entries` (0 when there is none), at most a third of the
/// area.
fn legend_width<DB: DrawingBackend>(area: &Area<DB>, entries: &[Entry], s: f64) -> u32 {
    if entries.is_empty() {
        return 0;
    }
    let f = font(LEGEND, s);
    let text = entries
        .iter()
        .map(|e| area.estimate_text_size(&e.name, &f).map_or(0, |(w, _)| w))
        .max()
        .unwrap_or(0);
    let w = text + px(60.0 + 12.0 + 2.0 * MARGIN, s);
    w.min(area.dim_in_pixel().0 / 3)
}

/// Draws the legend in `area` (the column right of the plot), from height `top`.
fn draw_legend<DB: DrawingBackend>(
    area: &Area<DB>,
    entries: &[Entry],
    top: i32,
    s: f64,
) -> io::Result<()> {
    let f = font(LEGEND, s);
    let line_h = (LEGEND * 1.5 * s) as i32;
    let x0 = px(MARGIN * 0.5, s) as i32;
    let sample = px(60.0, s) as i32;
    for (i, e) in entries.iter().enumerate() {
        let y = top + line_h / 2 + i as i32 * line_h;
        let shape = ShapeStyle::from(&e.color).stroke_width(px(LINE_W, s));
        match e.style {
            None => {
                let h = line_h / 3;
                area.draw(&Rectangle::new(
                    [(x0 + sample / 4, y - h), (x0 + 3 * sample / 4, y + h)],
                    e.color.filled(),
                ))
            }
            Some(Style::Dashed) => area
                .draw(&PathElement::new(
                    vec![(x0, y), (x0 + sample * 2 / 5, y)],
                    shape,
                ))
                .and_then(|_| {
                    area.draw(&PathElement::new(
                        vec![(x0 + sample * 3 / 5, y), (x0 + sample, y)],
                        shape,
                    ))
                }),
            Some(Style::Markers) => {
                draw_marker(area, (x0 + sample / 2, y), e.marker, e.color, s).map_err(err)?;
                Ok(())
            }
            Some(style) => {
                let r = area.draw(&PathElement::new(vec![(x0, y), (x0 + sample, y)], shape));
                if style == Style::LineMarkers {
                    draw_marker(area, (x0 + sample / 2, y), e.marker, e.color, s).map_err(err)?;
                }
                r
            }
        }
        .map_err(err)?;
        area.draw(&Text::new(
            e.name.clone(),
            (x0 + sample + px(12.0, s) as i32, y),
            f.pos(Pos::new(HPos::Left, VPos::Center)),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// Marker shape `k` (circle, square, triangle, diamond, …) at pixel `c`.
fn draw_marker<DB: DrawingBackend>(
    area: &Area<DB>,
    c: (i32, i32),
    k: usize,
    color: RGBColor,
    s: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let r = MARKER_R * s;
    let ri = r.round() as i32;
    let fill = color.filled();
    let poly = |pts: &[(f64, f64)]| {
        Polygon::new(
            pts.iter()
                .map(|(dx, dy)| (c.0 + (dx * r).round() as i32, c.1 + (dy * r).round() as i32))
                .collect::<Vec<_>>(),
            fill,
        )
    };
    match k % 4 {
        0 => area.draw(&Circle::new(c, ri, fill)),
        1 => area.draw(&Rectangle::new(
            [
                (c.0 - ri * 9 / 10, c.1 - ri * 9 / 10),
                (c.0 + ri * 9 / 10, c.1 + ri * 9 / 10),
            ],
            fill,
        )),
        2 => area.draw(&poly(&[(0.0, -1.2), (1.1, 0.8), (-1.1, 0.8)])),
        _ => area.draw(&poly(&[(0.0, -1.25), (1.0, 0.0), (0.0, 1.25), (-1.0, 0.0)])),
    }
}

/// Whether `p` lies in the axes' ranges.
fn inside(p: &(f64, f64), (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> bool {
    (x0..=x1).contains(&p.0) && (y0..=y1).contains(&p.1)
}

/// Runs of consecutive drawable points of `pts` (a non-finite point ends a run).
fn runs(pts: &[(f64, f64)]) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut run = Vec::new();
    for &(x, y) in pts {
        if x.is_finite() && y.is_finite() {
            run.push((x, y));
        } else if !run.is_empty() {
            out.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        out.push(run);
    }
    out
}

/// Width of the y tick labels of the range `[lo, hi]` plus room for the axis label.
fn y_label_area<DB: DrawingBackend>(
    area: &Area<DB>,
    labels: impl Iterator<Item = String>,
    s: f64,
) -> u32 {
    let f = font(TICK_LABEL, s);
    let w = labels
        .map(|l| area.estimate_text_size(&l, &f).map_or(0, |(w, _)| w))
        .max()
        .unwrap_or(0);
    w + px(AXIS_LABEL * 1.3 + 24.0, s)
}

/// The legend of a line chart: its named series, when there are two or more (one curve
/// needs no legend: the title and axis label name it).
fn line_entries(ch: &LineChart) -> Vec<Entry> {
    let entries: Vec<Entry> = ch
        .series
        .iter()
        .enumerate()
        .filter(|(_, se)| !se.name.is_empty())
        .map(|(i, se)| Entry {
            name: se.name.clone(),
            color: rgb(se.color.unwrap_or(PALETTE[i % PALETTE.len()])),
            style: Some(se.style),
            marker: i,
        })
        .collect();
    if entries.len() >= 2 {
        entries
    } else {
        vec![]
    }
}

/// A line chart's data in axis coordinates and its axes' ranges.
struct Axes {
    /// Per series, its runs of drawable points (y as log10 of the value on a log axis).
    data: Vec<Vec<Vec<(f64, f64)>>>,
    x: (f64, f64),
    /// Whole decades (as exponents) on a log axis.
    y: (f64, f64),
    log: bool,
}

impl Axes {
    fn of(ch: &LineChart) -> Axes {
        let log = ch.log_y;
        // Axis coordinates: log10 of the value on a log axis (so ticks are whole decades).
        let ty = |y: f64| {
            if !log {
                y
            } else if y > 0.0 {
                y.log10()
            } else {
                f64::NAN
            }
        };
        let data: Vec<Vec<Vec<(f64, f64)>>> = ch
            .series
            .iter()
            .map(|se| {
                let pts: Vec<(f64, f64)> = se.points.iter().map(|&(x, y)| (x, ty(y))).collect();
                runs(&pts)
            })
            .collect();
        let all = || data.iter().flatten().flatten();
        let x = ch
            .x_range
            .or_else(|| span(all().map(|p| p.0)))
            .map_or((0.0, 1.0), |(a, b)| sanitize_range(a, b));
        let (y0, y1) = match ch.y_range {
            Some((a, b)) => sanitize_range(ty(a), ty(b)),
            None => {
                let (a, b) =
                    span(all().map(|p| p.1)).map_or((0.0, 1.0), |(a, b)| sanitize_range(a, b));
                if log {
                    (a, b)
                } else {
                    // A little room so no curve runs along the frame.
                    let pad = 0.04 * (b - a);
                    (a - pad, b + pad)
                }
            }
        };
        let y = if log {
            // Whole decades, at least one.
            let (a, b) = (y0.floor(), y1.ceil());
            (a, if b > a { b } else { a + 1.0 })
        } else {
            (y0, y1)
        };
        Axes { data, x, y, log }
    }

    /// Whether 2 and 5 of each decade are labelled too (log axis of two decades or less).
    fn minor(&self) -> bool {
        self.log && self.y.1 - self.y.0 <= 2.0
    }

    /// Label of y tick `v` (axis coordinate).
    fn y_label(&self, v: f64) -> String {
        if self.log {
            let e = v.round();
            if (v - e).abs() < 1e-6 {
                pow10_label(e as i32)
            } else {
                String::new()
            }
        } else {
            tick_label(v, self.y.0, self.y.1)
        }
    }

    /// Labels as wide as the widest y tick label is likely to be.
    fn y_label_guess(&self) -> Vec<String> {
        let (y0, y1) = self.y;
        let mut v: Vec<String> = [y0, y1, 0.5 * (y0 + y1), y0 + 0.25 * (y1 - y0)]
            .iter()
            .map(|&v| self.y_label(v))
            .collect();
        if self.minor() {
            v.push(format!("5×{}", pow10_label(y0 as i32)));
        }
        v
    }
}

/// Draws a line/scatter chart filling `area`, with a y label area `y_area` and a legend
/// column `lw` pixels wide (the same for every panel of a figure, so their axes line up).
fn draw_lines<DB: DrawingBackend>(
    area: &Area<DB>,
    ch: &LineChart,
    (y_area, lw): (u32, u32),
    s: f64,
) -> io::Result<()> {
    let ax = Axes::of(ch);
    let (log, data) = (ax.log, &ax.data);
    let has_data = data.iter().flatten().flatten().next().is_some();
    let ((x0, x1), (y0, y1)) = (ax.x, ax.y);
    let entries = line_entries(ch);
    let (aw, _) = area.dim_in_pixel();
    let (plot_area, legend_area) = area.split_horizontally(aw - lw);

    let decades = (y1 - y0).round() as usize;
    let y_ticks = if log { (decades + 1).min(9) } else { 7 };
    let y_fmt = |v: &f64| ax.y_label(*v);

    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&ch.title, font(TITLE, s))
        .margin(px(MARGIN, s))
        .x_label_area_size(px(TICK_LABEL + AXIS_LABEL + 40.0, s))
        .y_label_area_size(y_area)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(&ch.x_label)
        .y_desc(&ch.y_label)
        .axis_desc_style(font(AXIS_LABEL, s))
        .label_style(font(TICK_LABEL, s))
        .x_labels(8)
        .y_labels(y_ticks)
        .x_label_formatter(&|v| tick_label(*v, x0, x1))
        .y_label_formatter(&y_fmt)
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(px(1.0, s)))
        .light_line_style(TRANSPARENT)
        .axis_style(BLACK.stroke_width(px(1.5, s)))
        .set_all_tick_mark_size(px(8.0, s))
        .draw()
        .map_err(err)?;

    for (i, (se, segs)) in ch.series.iter().zip(data).enumerate() {
        let color = rgb(se.color.unwrap_or(PALETTE[i % PALETTE.len()]));
        let line = ShapeStyle::from(&color).stroke_width(px(LINE_W, s));
        for seg in segs {
            match se.style {
                Style::Line | Style::LineMarkers if seg.len() > 1 => {
                    chart
                        .draw_series(LineSeries::new(seg.iter().copied(), line))
                        .map_err(err)?;
                }
                Style::Dashed if seg.len() > 1 => {
                    chart
                        .draw_series(DashedLineSeries::new(
                            seg.iter().copied(),
                            px(14.0, s),
                            px(9.0, s),
                            line,
                        ))
                        .map_err(err)?;
                }
                _ => {}
            }
            let markers = matches!(se.style, Style::Markers | Style::LineMarkers) || seg.len() == 1;
            if markers {
                // On the whole panel: a marker on the frame is drawn whole, not cut.
                let (bx, by) = plot_area.get_base_pixel();
                for p in seg.iter().filter(|p| inside(p, (x0, x1), (y0, y1))) {
                    let c = chart.backend_coord(p);
                    draw_marker(&plot_area, (c.0 - bx, c.1 - by), i, color, s).map_err(err)?;
                }
            }
        }
    }
    if ax.minor() {
        // Two decades or less: 2 and 5 of each decade labelled too.
        let (bx, by) = plot_area.get_base_pixel();
        let grid = RGBColor(215, 215, 215).stroke_width(px(1.0, s));
        for e in (y0 as i32)..(y1 as i32) {
            for m in [2.0f64, 5.0] {
                let y = f64::from(e) + m.log10();
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x0, y), (x1, y)],
                        grid,
                    )))
                    .map_err(err)?;
                let c = chart.backend_coord(&(x0, y));
                plot_area
                    .draw(&Text::new(
                        format!("{m}×{}", pow10_label(e)),
                        (c.0 - bx - px(14.0, s) as i32, c.1 - by),
                        font(TICK_LABEL, s).pos(Pos::new(HPos::Right, VPos::Center)),
                    ))
                    .map_err(err)?;
            }
        }
    }
    if !has_data {
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        chart
            .draw_series(std::iter::once(Text::new(
                "no data",
                (cx, cy),
                font(AXIS_LABEL, s)
                    .color(&RGBColor(100, 100, 100))
                    .pos(Pos::new(HPos::Center, VPos::Center)),
            )))
            .map_err(err)?;
    }
    if !entries.is_empty() {
        let top = chart.backend_coord(&(x0, y1)).1 - legend_area.get_base_pixel().1;
        draw_legend(&legend_area, &entries, top, s)?;
    }
    Ok(())
}

/// Segment value counted in a bar: missing, negative and non-finite values count as 0.
fn bar_value(b: &BarChart, cat: usize, seg: usize) -> f64 {
    b.values
        .get(cat)
        .and_then(|v| v.get(seg))
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .unwrap_or(0.0)
}

/// Draws a stacked bar chart filling `area`; the legend sits in a column right of the plot.
fn draw_bars<DB: DrawingBackend>(area: &Area<DB>, b: &BarChart, s: f64) -> io::Result<()> {
    let n = b.categories.len();
    let totals: Vec<f64> = (0..n)
        .map(|k| (0..b.segments.len()).map(|g| bar_value(b, k, g)).sum())
        .collect();
    let max_total = totals.iter().copied().fold(0.0, f64::max);
    // Room above the tallest bar for its total.
    let y1 = if max_total > 0.0 {
        max_total * 1.12
    } else {
        1.0
    };
    let entries: Vec<Entry> = b
        .segments
        .iter()
        .enumerate()
        .map(|(i, name)| Entry {
            name: name.clone(),
            color: rgb(PALETTE[i % PALETTE.len()]),
            style: None,
            marker: i,
        })
        .collect();
    let (aw, _) = area.dim_in_pixel();
    let lw = legend_width(area, &entries, s);
    let (plot_area, legend_area) = area.split_horizontally(aw - lw);
    let lines = b
        .categories
        .iter()
        .map(|c| c.split('\n').count())
        .max()
        .unwrap_or(1)
        .clamp(1, 3);
    let y_fmt = |v: &f64| tick_label(*v, 0.0, y1);
    let guess = [y1, 0.5 * y1, 0.3 * y1];
    let y_area = y_label_area(&plot_area, guess.iter().map(y_fmt), s);
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&b.title, font(TITLE, s))
        .margin(px(MARGIN, s))
        .x_label_area_size(px(16.0 + lines as f64 * TICK_LABEL * 1.3, s))
        .y_label_area_size(y_area)
        .build_cartesian_2d(0.0..n.max(1) as f64, 0.0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_labels(7)
        .y_desc(&b.y_label)
        .axis_desc_style(font(AXIS_LABEL, s))
        .label_style(font(TICK_LABEL, s))
        .y_label_formatter(&y_fmt)
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(px(1.0, s)))
        .light_line_style(TRANSPARENT)
        .axis_style(BLACK.stroke_width(px(1.5, s)))
        .set_all_tick_mark_size(px(8.0, s))
        .draw()
        .map_err(err)?;
    // Captions small enough for their slot: the widest line fits the bar's slot.
    let slot = chart.backend_coord(&(1.0, 0.0)).0 - chart.backend_coord(&(0.0, 0.0)).0;
    let base = plot_area.get_base_pixel();
    let mut cap_size = TICK_LABEL;
    while cap_size > 14.0 {
        let f = font(cap_size, s);
        let widest = b
            .categories
            .iter()
            .flat_map(|c| c.split('\n'))
            .map(|l| plot_area.estimate_text_size(l, &f).map_or(0, |(w, _)| w))
            .max()
            .unwrap_or(0);
        if (widest as i32) < slot - px(8.0, s) as i32 {
            break;
        }
        cap_size -= 2.0;
    }
    // Bars 60 % of their slot, at most 240 px wide.
    let half = (0.3f64).min(120.0 * s / f64::from(slot.max(1)));
    for (k, cat) in b.categories.iter().enumerate() {
        let (l, r) = (k as f64 + 0.5 - half, k as f64 + 0.5 + half);
        let mut acc = 0.0;
        for g in 0..b.segments.len() {
            let v = bar_value(b, k, g);
            if v > 0.0 {
                let color = rgb(PALETTE[g % PALETTE.len()]);
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(l, acc), (r, acc + v)],
                        color.filled(),
                    )))
                    .map_err(err)?;
                acc += v;
            }
        }
        if acc > 0.0 {
            chart
                .draw_series([
                    Rectangle::new([(l, 0.0), (r, acc)], BLACK.stroke_width(px(1.0, s))).into_dyn(),
                    Text::new(
                        sig4(totals[k]),
                        (0.5 * (l + r), acc + 0.015 * y1),
                        font(TICK_LABEL, s).pos(Pos::new(HPos::Center, VPos::Bottom)),
                    )
                    .into_dyn(),
                ])
                .map_err(err)?;
        }
        // Caption lines centred under the bar, on the whole area (outside the plot).
        let (cx, cy) = chart.backend_coord(&(k as f64 + 0.5, 0.0));
        for (j, line) in cat.split('\n').take(3).enumerate() {
            let y = cy - base.1 + px(12.0, s) as i32 + (j as f64 * cap_size * 1.3 * s) as i32;
            plot_area
                .draw(&Text::new(
                    line.to_string(),
                    (cx - base.0, y),
                    font(cap_size, s).pos(Pos::new(HPos::Center, VPos::Top)),
                ))
                .map_err(err)?;
        }
    }
    if n == 0 {
        chart
            .draw_series(std::iter::once(Text::new(
                "no data",
                (0.5, 0.5 * y1),
                font(AXIS_LABEL, s)
                    .color(&RGBColor(100, 100, 100))
                    .pos(Pos::new(HPos::Center, VPos::Center)),
            )))
            .map_err(err)?;
    }
    if !entries.is_empty() {
        let top = chart.backend_coord(&(0.0, y1)).1 - legend_area.get_base_pixel().1;
        draw_legend(&legend_area, &entries, top, s)?;
    }
    Ok(())
}

/// Colour of `t` ∈ [0, 1] on a perceptually ordered, colour-blind-safe scale (viridis,
/// interpolated between 9 of its stops).
pub fn colormap(t: f64) -> Rgb {
    const STOPS: [Rgb; 9] = [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let f = t * (STOPS.len() - 1) as f64;
    let i = (f.floor() as usize).min(STOPS.len() - 2);
    let w = f - i as f64;
    let mix = |a: u8, b: u8| (f64::from(a) + w * (f64::from(b) - f64::from(a))).round() as u8;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [mix(a[0], b[0]), mix(a[1], b[1]), mix(a[2], b[2])]
}

/// Draws a scatter coloured by value, with its colour bar on the right.
fn draw_map<DB: DrawingBackend>(area: &Area<DB>, m: &ScatterMap, s: f64) -> io::Result<()> {
    let pts: Vec<(f64, f64, f64)> = m
        .points
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
        .collect();
    // A little room so that no point sits on the frame.
    let padded = |(a, b): (f64, f64)| {
        let (a, b) = sanitize_range(a, b);
        (a - 0.04 * (b - a), b + 0.04 * (b - a))
    };
    let (x0, x1) = span(pts.iter().map(|p| p.0)).map_or((0.0, 1.0), padded);
    let (y0, y1) = span(pts.iter().map(|p| p.1)).map_or((0.0, 1.0), padded);
    let (v0, v1) = m
        .value_range
        .or_else(|| span(pts.iter().map(|p| p.2)))
        .map_or((0.0, 1.0), |(a, b)| sanitize_range(a, b));
    let (aw, _) = area.dim_in_pixel();
    let bar_w = px(260.0, s);
    let (plot_area, bar_area) = area.split_horizontally(aw - bar_w);
    let x_label_area = px(TICK_LABEL + AXIS_LABEL + 40.0, s);
    let y_fmt = |v: &f64| tick_label(*v, y0, y1);
    let y_area = y_label_area(&plot_area, [y0, y1].iter().map(y_fmt), s);
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&m.title, font(TITLE, s))
        .margin(px(MARGIN, s))
        .x_label_area_size(x_label_area)
        .y_label_area_size(y_area)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(&m.x_label)
        .y_desc(&m.y_label)
        .axis_desc_style(font(AXIS_LABEL, s))
        .label_style(font(TICK_LABEL, s))
        .x_label_formatter(&|v| tick_label(*v, x0, x1))
        .y_label_formatter(&y_fmt)
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(px(1.0, s)))
        .light_line_style(TRANSPARENT)
        .axis_style(BLACK.stroke_width(px(1.5, s)))
        .draw()
        .map_err(err)?;
    let r = (m.radius.max(0.5) * s).round() as i32;
    chart
        .draw_series(pts.iter().map(|&(x, y, v)| {
            let c = rgb(colormap((v - v0) / (v1 - v0)));
            Circle::new((x, y), r, c.filled())
        }))
        .map_err(err)?;
    // The colour bar spans the plot's height.
    let top = chart.backend_coord(&(x0, y1)).1 - bar_area.get_base_pixel().1;
    let bottom = chart.backend_coord(&(x0, y0)).1 - bar_area.get_base_pixel().1;
    let (bx0, bx1) = (px(MARGIN, s) as i32, px(MARGIN + 40.0, s) as i32);
    let steps = (bottom - top).max(1);
    for i in 0..steps {
        let t = 1.0 - f64::from(i) / f64::from(steps);
        bar_area
            .draw(&Rectangle::new(
                [(bx0, top + i), (bx1, top + i + 1)],
                rgb(colormap(t)).filled(),
            ))
            .map_err(err)?;
    }
    bar_area
        .draw(&Rectangle::new(
            [(bx0, top), (bx1, bottom)],
            BLACK.stroke_width(px(1.0, s)),
        ))
        .map_err(err)?;
    for k in 0..=4 {
        let v = v0 + (v1 - v0) * f64::from(k) / 4.0;
        let y = bottom - ((bottom - top) as f64 * f64::from(k) / 4.0).round() as i32;
        bar_area
            .draw(&Text::new(
                sig4(v),
                (bx1 + px(10.0, s) as i32, y),
                font(TICK_LABEL, s).pos(Pos::new(HPos::Left, VPos::Center)),
            ))
            .map_err(err)?;
    }
    bar_area
        .draw(&Text::new(
            m.value_label.clone(),
            (bar_w as i32 - px(MARGIN, s) as i32, (top + bottom) / 2),
            font(AXIS_LABEL, s)
                .transform(FontTransform::Rotate270)
                .pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(err)?;
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests;
