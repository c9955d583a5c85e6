//! # ballast-plot
//!
//! Small, dependency-light PNG charts that a simulation run draws itself (no Python, no system
//! libraries): line/scatter charts ([`Chart`], [`render_png`], [`render_png_stack`]) and
//! stacked bar charts ([`BarChart`], [`render_stacked_bars`]).
//!
//! Every chart has a white background, a framed plot area with light grid lines at "nice"
//! ticks (1-2-5 steps, see [`nice_ticks`]), labelled axes, a title and a legend with colour
//! swatches. Colours come from a colour-blind-friendly palette ([`PALETTE`], Okabe–Ito) and
//! markers also change shape from series to series. Text uses an embedded 8×8 bitmap font
//! drawn at twice its size. Non-finite values are skipped (a line breaks at them), empty or
//! constant data still give a readable chart, and nothing here panics on data.
//!
//! ```no_run
//! use ballast_plot::{render_png, Chart, Series, Style};
//! let chart = Chart {
//!     title: "Kinetic energy".into(),
//!     x_label: "time (s)".into(),
//!     y_label: "energy (J)".into(),
//!     series: vec![Series::new("grains", vec![(0.0, 1.0), (0.1, 0.5)], Style::Line)],
//!     log_y: false,
//!     x_range: None,
//!     y_range: None,
//! };
//! render_png(&chart, 960, 600, std::path::Path::new("energy.png")).unwrap();
//! ```

mod bars;
mod canvas;
mod chart;
mod ticks;

pub use canvas::Rgb;
pub use ticks::{
    format_log_tick, format_tick, format_value, log_ticks, nice_step, nice_ticks, sanitize_range,
};

use canvas::{Canvas, Rect, WHITE};
use std::io;
use std::path::Path;

/// Colour-blind-friendly palette (Okabe & Ito, yellow replaced by a wine red, which reads on
/// white): series `i` gets `PALETTE[i % 8]`.
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

/// Smallest and largest image side accepted, in pixels.
pub const MIN_SIDE: u32 = 160;
/// See [`MIN_SIDE`].
pub const MAX_SIDE: u32 = 8192;

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Style {
    /// Solid line through the points (a lone point is still shown as a marker).
    #[default]
    Line,
    /// Markers only (scatter).
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
pub struct Chart {
    pub title: String,
    /// Quantity and unit, e.g. `time (s)`.
    pub x_label: String,
    /// Quantity and unit, e.g. `max interpenetration (mm)`.
    pub y_label: String,
    pub series: Vec<Series>,
    /// Logarithmic y axis (values ≤ 0 are then skipped).
    pub log_y: bool,
    /// x-axis range; `None` fits the data. Panels over the same time span share it.
    pub x_range: Option<(f64, f64)>,
    /// y-axis range (positive values on a log axis); `None` fits the data.
    pub y_range: Option<(f64, f64)>,
}

/// A stacked bar chart: one bar per category, one stacked segment per entry of `segments`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BarChart {
    pub title: String,
    /// Caption under the categories (may be empty).
    pub x_label: String,
    /// Quantity and unit of the bar heights, e.g. `time (s)`.
    pub y_label: String,
    /// Bar captions; `\n` splits a caption over two lines.
    pub categories: Vec<String>,
    /// Segment names (the legend), bottom to top.
    pub segments: Vec<String>,
    /// `values[category][segment]`; missing, negative or non-finite values count as 0.
    pub values: Vec<Vec<f64>>,
}

/// A decoded RGB image (see [`decode_png`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// Row-major RGB bytes.
    pub rgb: Vec<u8>,
}

impl Image {
    /// Colour of pixel `(x, y)`, `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<Rgb> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        Some([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]])
    }

    /// Number of distinct colours.
    pub fn distinct_colors(&self) -> usize {
        let mut c: Vec<Rgb> = self
            .rgb
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        c.sort_unstable();
        c.dedup();
        c.len()
    }

    /// Whether some pixel has colour `c` exactly.
    pub fn contains_color(&self, c: Rgb) -> bool {
        self.rgb.chunks_exact(3).any(|p| p == c)
    }
}

fn check_size(width: u32, height: u32) -> io::Result<()> {
    if !(MIN_SIDE..=MAX_SIDE).contains(&width) || !(MIN_SIDE..=MAX_SIDE).contains(&height) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("image size {width}×{height}: each side must be {MIN_SIDE}..={MAX_SIDE} px"),
        ));
    }
    Ok(())
}

fn full(width: u32, height: u32) -> Rect {
    Rect {
        x0: 0,
        y0: 0,
        x1: width as i32,
        y1: height as i32,
    }
}

/// Renders `chart` into an in-memory image.
pub fn render_image(chart: &Chart, width: u32, height: u32) -> io::Result<Image> {
    check_size(width, height)?;
    let mut c = Canvas::new(width, height, WHITE);
    chart::draw(&mut c, chart, full(width, height));
    Ok(Image {
        width,
        height,
        rgb: c.px,
    })
}

/// Renders `chart` as a `width`×`height` PNG at `path`, written atomically (temporary file in
/// the same folder, then rename). Errors: a side outside [`MIN_SIDE`]..=[`MAX_SIDE`], or I/O.
pub fn render_png(chart: &Chart, width: u32, height: u32, path: &Path) -> io::Result<()> {
    check_size(width, height)?;
    let mut c = Canvas::new(width, height, WHITE);
    chart::draw(&mut c, chart, full(width, height));
    c.write_png(path)
}

/// Renders `charts` one above the other (each `width`×`panel_height`, sharing nothing but the
/// image) as one PNG at `path`, written atomically: for quantities of different units over
/// the same time axis. An empty slice gives one empty panel.
pub fn render_png_stack(
    charts: &[Chart],
    width: u32,
    panel_height: u32,
    path: &Path,
) -> io::Result<()> {
    check_size(width, panel_height)?;
    let n = charts.len().max(1) as u32;
    let height = panel_height.saturating_mul(n);
    if height > MAX_SIDE {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{n} panels of {panel_height} px exceed {MAX_SIDE} px"),
        ));
    }
    let mut c = Canvas::new(width, height, WHITE);
    let empty = [Chart::default()];
    let charts = if charts.is_empty() {
        &empty[..]
    } else {
        charts
    };
    for (i, ch) in charts.iter().enumerate() {
        let y0 = (i as u32 * panel_height) as i32;
        let area = Rect {
            x0: 0,
            y0,
            x1: width as i32,
            y1: y0 + panel_height as i32,
        };
        chart::draw(&mut c, ch, area);
    }
    c.write_png(path)
}

/// Renders `chart` as a `width`×`height` PNG of stacked bars at `path`, written atomically.
pub fn render_stacked_bars(
    chart: &BarChart,
    width: u32,
    height: u32,
    path: &Path,
) -> io::Result<()> {
    check_size(width, height)?;
    let mut c = Canvas::new(width, height, WHITE);
    bars::draw(&mut c, chart, full(width, height));
    c.write_png(path)
}

/// Renders `chart` (stacked bars) into an in-memory image.
pub fn render_stacked_bars_image(chart: &BarChart, width: u32, height: u32) -> io::Result<Image> {
    check_size(width, height)?;
    let mut c = Canvas::new(width, height, WHITE);
    bars::draw(&mut c, chart, full(width, height));
    Ok(Image {
        width,
        height,
        rgb: c.px,
    })
}

/// Reads a PNG back as 8-bit RGB (grey, alpha and palette images are converted): for tests
/// and checks of the rendered files.
pub fn decode_png(path: &Path) -> io::Result<Image> {
    let f = std::fs::File::open(path)?;
    let mut dec = png::Decoder::new(io::BufReader::new(f));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec.read_info().map_err(io::Error::other)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| io::Error::other("PNG too large"))?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(io::Error::other)?;
    buf.truncate(info.buffer_size());
    let n = (info.width as usize) * (info.height as usize);
    let rgb = match info.color_type {
        png::ColorType::Rgb => buf,
        png::ColorType::Rgba => buf
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
        png::ColorType::Grayscale => buf.iter().flat_map(|&g| [g, g, g]).collect(),
        png::ColorType::GrayscaleAlpha => buf
            .chunks_exact(2)
            .flat_map(|p| [p[0], p[0], p[0]])
            .collect(),
        png::ColorType::Indexed => {
            return Err(io::Error::other("indexed PNG left unexpanded"));
        }
    };
    if rgb.len() != n * 3 {
        return Err(io::Error::other("unexpected PNG layout"));
    }
    Ok(Image {
        width: info.width,
        height: info.height,
        rgb,
    })
}

#[cfg(test)]
mod tests;
