use super::*;
use std::path::PathBuf;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ballast-charts-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Removes a test folder, unless `BALLAST_KEEP_REPORT` is set (to look at the figures).
fn cleanup(dir: &Path) {
    if std::env::var_os("BALLAST_KEEP_REPORT").is_none() {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// Checks of a written figure, shared with the report's tests.
pub(crate) mod check {
    use std::path::Path;

    /// Width, height and RGB pixels of a PNG file's bytes.
    pub fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<[u8; 3]>) {
        let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
        dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
        let mut reader = dec.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        let data = &buf[..info.buffer_size()];
        let px: Vec<[u8; 3]> = match info.color_type {
            png::ColorType::Rgb => data.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
            png::ColorType::Rgba => data.chunks_exact(4).map(|p| [p[0], p[1], p[2]]).collect(),
            t => panic!("colour type {t:?}"),
        };
        assert_eq!(px.len(), (info.width * info.height) as usize);
        (info.width, info.height, px)
    }

    /// The texts of the `<text>` elements of an SVG document (which must parse as XML).
    pub fn svg_texts(svg: &str) -> (roxmltree::Document<'_>, Vec<String>) {
        let doc = roxmltree::Document::parse(svg).unwrap_or_else(|e| panic!("SVG: {e}"));
        assert_eq!(doc.root_element().tag_name().name(), "svg");
        let texts = doc
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| n.text().unwrap_or("").trim().to_string())
            .collect();
        (doc, texts)
    }

    /// `dir/NAME.svg` parses, has `texts` among its text elements and the PNG's size;
    /// `dir/NAME.png` decodes, is at least 1600 px wide, is not blank, and its title band has
    /// antialiased text (more than 16 grey levels).
    pub fn figure(dir: &Path, name: &str, texts: &[&str]) {
        let svg_path = dir.join(format!("{name}.svg"));
        let svg = std::fs::read_to_string(&svg_path)
            .unwrap_or_else(|e| panic!("{}: {e}", svg_path.display()));
        let (doc, found) = svg_texts(&svg);
        for t in texts {
            assert!(
                found.iter().any(|f| f == t),
                "{name}.svg has no text {t:?}: {found:?}"
            );
        }
        let png = std::fs::read(dir.join(format!("{name}.png"))).unwrap();
        let (w, h, px) = decode_png(&png);
        let attr = |a: &str| -> u32 {
            doc.root_element()
                .attribute(a)
                .and_then(|v| v.trim_end_matches("px").parse().ok())
                .unwrap_or_else(|| panic!("{name}.svg: no {a}"))
        };
        assert_eq!((attr("width"), attr("height")), (w, h), "{name}");
        assert!(w >= 1600 && h >= 500, "{name}: {w} × {h}");
        let drawn = px.iter().filter(|p| **p != [255, 255, 255]).count();
        assert!(drawn * 100 >= px.len(), "{name}: {drawn} pixels drawn");
        // The title band: the top 70 px (title and its margin), over the middle columns.
        let mut greys: Vec<u8> = (0..70u32.min(h))
            .flat_map(|y| (w / 8..w * 7 / 8).map(move |x| (y * w + x) as usize))
            .map(|i| px[i])
            .filter(|p| p[0] == p[1] && p[1] == p[2])
            .map(|p| p[0])
            .collect();
        greys.sort_unstable();
        greys.dedup();
        assert!(greys.len() > 16, "{name}: {} grey levels", greys.len());
    }
}

fn chart(series: Vec<Series>, log_y: bool) -> LineChart {
    LineChart {
        title: "Test chart".into(),
        x_label: "time (s)".into(),
        y_label: "value (m)".into(),
        series,
        log_y,
        x_range: None,
        y_range: None,
    }
}

#[test]
fn line_chart_is_written_twice_with_its_labels() {
    let dir = scratch("line");
    let sine: Vec<(f64, f64)> = (0..200)
        .map(|i| (i as f64 * 0.01, (i as f64 * 0.05).sin()))
        .collect();
    let ch = LineChart {
        title: "Sine and cosine".into(),
        series: vec![
            Series::new("sine", sine.clone(), Style::Line),
            Series::new(
                "cosine",
                sine.iter().map(|p| (p.0, p.1.cos())).collect(),
                Style::LineMarkers,
            ),
            Series::new("samples", sine[..20].to_vec(), Style::Markers),
            Series::new("reference", vec![(0.0, 0.5), (2.0, 0.5)], Style::Dashed)
                .with_color(REFERENCE),
        ],
        ..chart(vec![], false)
    };
    write_figure(&dir, "line", &Figure::chart(ch.clone())).unwrap();
    check::figure(
        &dir,
        "line",
        &[
            "Sine and cosine",
            "time (s)",
            "value (m)",
            "sine",
            "reference",
        ],
    );
    // Same figure, same bytes.
    let again = scratch("line-again");
    write_figure(&again, "line", &Figure::chart(ch)).unwrap();
    for ext in ["svg", "png"] {
        let f = format!("line.{ext}");
        assert!(std::fs::read(dir.join(&f)).unwrap() == std::fs::read(again.join(&f)).unwrap());
    }
    // Nothing temporary left behind.
    for e in std::fs::read_dir(&dir).unwrap() {
        let n = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!n.contains(".tmp"), "left over {n}");
    }
    assert!(write_figure(&dir.join("missing/dir"), "x", &Figure::Panels(vec![])).is_err());
    cleanup(&dir);
    cleanup(&again);
}

#[test]
fn degenerate_data_gives_readable_figures() {
    let dir = scratch("degenerate");
    let (nan, inf) = (f64::NAN, f64::INFINITY);
    let cases: Vec<(&str, Vec<Series>, bool)> = vec![
        ("no_series", vec![], false),
        (
            "empty",
            vec![Series::new("empty", vec![], Style::Line)],
            false,
        ),
        (
            "single",
            vec![Series::new("one", vec![(1.0, 2.0)], Style::Line)],
            false,
        ),
        (
            "constant",
            vec![Series::new(
                "c",
                vec![(0.0, 3.0), (1.0, 3.0), (2.0, 3.0)],
                Style::LineMarkers,
            )],
            false,
        ),
        (
            "zero",
            vec![Series::new("z", vec![(5.0, 0.0), (5.0, 0.0)], Style::Line)],
            false,
        ),
        (
            "nonfinite",
            vec![
                Series::new(
                    "n",
                    vec![
                        (nan, 1.0),
                        (0.0, inf),
                        (1.0, 1.0),
                        (2.0, nan),
                        (3.0, 2.0),
                        (4.0, -inf),
                    ],
                    Style::Line,
                ),
                Series::new("m", vec![(nan, nan); 5], Style::Markers),
            ],
            false,
        ),
        (
            "huge",
            vec![Series::new(
                "h",
                vec![(-f64::MAX, f64::MAX), (f64::MAX, -f64::MAX)],
                Style::Line,
            )],
            false,
        ),
        (
            "tiny",
            vec![Series::new(
                "t",
                vec![(0.0, 1e-300), (1e-300, 2e-300)],
                Style::Line,
            )],
            false,
        ),
        (
            "log_nonpositive",
            vec![Series::new(
                "l",
                vec![(0.0, 0.0), (1.0, -1.0), (2.0, 1e-3), (3.0, 10.0)],
                Style::Line,
            )],
            true,
        ),
        (
            "log_empty",
            vec![Series::new("l", vec![(0.0, -1.0)], Style::Line)],
            true,
        ),
        (
            "log_constant",
            vec![Series::new(
                "l",
                vec![(0.0, 2e-4), (1.0, 2e-4)],
                Style::Line,
            )],
            true,
        ),
        (
            "many",
            (0..20)
                .map(|i| {
                    Series::new(
                        format!("control volume {i}"),
                        vec![(0.0, i as f64), (1.0, i as f64 + 1.0)],
                        Style::Line,
                    )
                })
                .collect(),
            false,
        ),
    ];
    let ranges = [
        None,
        Some((0.5, 0.6)),
        Some((3.0, 3.0)),
        Some((nan, 1.0)),
        Some((1e300, -1e300)),
    ];
    for (name, series, log_y) in cases {
        for (k, range) in ranges.iter().enumerate() {
            let ch = LineChart {
                x_range: *range,
                y_range: *range,
                ..chart(series.clone(), log_y)
            };
            let file = format!("{name}_{k}");
            let fig = if k % 2 == 0 {
                Figure::chart(ch)
            } else {
                Figure::Panels(vec![ch.clone(), ch])
            };
            write_figure(&dir, &file, &fig).unwrap_or_else(|e| panic!("{file}: {e}"));
            check::figure(&dir, &file, &["Test chart", "time (s)", "value (m)"]);
        }
    }
    write_figure(&dir, "none", &Figure::Panels(vec![])).unwrap();
    cleanup(&dir);
}

#[test]
fn stacked_bars_and_maps_are_written() {
    let dir = scratch("bars");
    let bars = BarChart {
        title: "Time per phase".into(),
        y_label: "time (s)".into(),
        categories: (0..12).map(|i| format!("DDM 2x2x1\n{i} thr.")).collect(),
        segments: vec!["detection".into(), "NLGS".into(), "other".into()],
        values: (0..12)
            .map(|i| vec![1.0, 10.0 / (1.0 + i as f64), 0.5])
            .collect(),
    };
    write_figure(&dir, "bars", &Figure::Bars(bars.clone())).unwrap();
    check::figure(
        &dir,
        "bars",
        &["Time per phase", "time (s)", "detection", "4 thr."],
    );
    assert!(Figure::Bars(bars).size().0 > WIDTH);
    for (name, categories, values) in [
        ("bars_empty", vec![], vec![]),
        (
            "bars_bad",
            vec!["a".into(), "b".into()],
            vec![vec![f64::NAN], vec![-1.0, 2.0, 3.0]],
        ),
        ("bars_zero", vec!["a".into()], vec![vec![0.0, 0.0]]),
    ] {
        let b = BarChart {
            title: "Degenerate bars".into(),
            y_label: "time (s)".into(),
            categories,
            segments: vec!["x".into(), "y".into()],
            values,
        };
        write_figure(&dir, name, &Figure::Bars(b)).unwrap();
        check::figure(&dir, name, &["Degenerate bars", "time (s)"]);
    }
    let map = ScatterMap {
        title: "Compacity in a section".into(),
        x_label: "x (m)".into(),
        y_label: "z (m)".into(),
        value_label: "compacity (-)".into(),
        points: (0..400)
            .map(|i| {
                let (x, z) = ((i % 20) as f64 * 0.01, (i / 20) as f64 * 0.01);
                (x, z, 0.5 + 0.1 * (x * 20.0).sin() * z)
            })
            .chain([(f64::NAN, 0.0, 1.0), (0.0, 0.0, f64::INFINITY)])
            .collect(),
        radius: 8.0,
        value_range: None,
    };
    write_figure(&dir, "map", &Figure::Map(map.clone())).unwrap();
    check::figure(
        &dir,
        "map",
        &["Compacity in a section", "x (m)", "compacity (-)"],
    );
    let empty = ScatterMap {
        points: vec![],
        ..map
    };
    write_figure(&dir, "map_empty", &Figure::Map(empty)).unwrap();
    check::figure(&dir, "map_empty", &["Compacity in a section"]);
    cleanup(&dir);
}

#[test]
fn tick_labels_and_helpers() {
    assert_eq!(tick_label(0.5, 0.0, 2.0), "0.5");
    assert_eq!(tick_label(1.0, 0.0, 2.0), "1");
    assert_eq!(tick_label(0.30000000000000004, 0.0, 1.0), "0.3");
    assert_eq!(tick_label(1e-17, -1.0, 1.0), "0");
    assert_eq!(tick_label(2.5e-4, 0.0, 5e-4), "2.5e-4");
    assert_eq!(tick_label(2e6, 0.0, 5e6), "2e6");
    assert_eq!(tick_label(1250.0, 0.0, 2500.0), "1250");
    assert_eq!(sig4(7.48846), "7.488");
    assert_eq!(sig4(1234.5), "1234");
    assert_eq!(sig4(2.5e-5), "2.500e-5");
    assert_eq!(pow10_label(-4), "10⁻⁴");
    assert_eq!(pow10_label(12), "10¹²");
    assert_eq!(pow10_label(0), "10⁰");
    assert_eq!(sanitize_range(3.0, 3.0), (2.85, 3.15));
    assert_eq!(sanitize_range(0.0, 0.0), (-1.0, 1.0));
    assert_eq!(sanitize_range(f64::NAN, 1.0), (0.0, 1.0));
    assert_eq!(sanitize_range(2.0, 1.0), (1.0, 2.0));
    assert_eq!(colormap(0.0), [68, 1, 84]);
    assert_eq!(colormap(1.0), [253, 231, 37]);
    assert_eq!(colormap(f64::NAN), colormap(0.0));
    let r = runs(&[(0.0, 1.0), (f64::NAN, 1.0), (1.0, 1.0), (2.0, 2.0)]);
    assert_eq!(r, vec![vec![(0.0, 1.0)], vec![(1.0, 1.0), (2.0, 2.0)]]);
    // A 2×2 block averages to one pixel, rounded.
    let big = [0, 0, 0, 255, 255, 255, 255, 255, 255, 0, 0, 1];
    assert_eq!(downsample(&big, 1, 1, 2), vec![128, 128, 128]);
}
