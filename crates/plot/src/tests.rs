//! Rendering tests: files decode back, carry real content, and odd data does not panic.

use super::*;
use std::path::PathBuf;

/// A fresh, empty folder for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ballast-plot-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn demo_chart() -> Chart {
    let pts = |f: fn(f64) -> f64| {
        (0..200)
            .map(|i| i as f64 * 0.01)
            .map(|t| (t, f(t)))
            .collect()
    };
    Chart {
        title: "Compacity per control volume".into(),
        x_label: "time (s)".into(),
        y_label: "compacity (-)".into(),
        series: vec![
            Series::new(
                "CV 1 (crib)",
                pts(|t| 0.58 + 0.03 * (1.0 - (-t).exp())),
                Style::Line,
            ),
            Series::new(
                "CV 2 (under sleeper)",
                pts(|t| 0.6 + 0.01 * t.sin()),
                Style::LineMarkers,
            ),
            Series::new("CV 3", pts(|t| 0.59 + 0.005 * t), Style::Markers),
        ],
        log_y: false,
        x_range: None,
        y_range: None,
    }
}

#[test]
fn line_chart_png_decodes_with_content_and_legend_colours() {
    let dir = scratch("line");
    let path = dir.join("compacity.png");
    render_png(&demo_chart(), 960, 600, &path).unwrap();
    let img = decode_png(&path).unwrap();
    assert_eq!((img.width, img.height), (960, 600));
    assert_eq!(img.pixel(0, 0), Some([255, 255, 255]));
    // Background, grid, frame, text and the three series (no anti-aliasing).
    assert!(
        img.distinct_colors() >= 7,
        "{} colours",
        img.distinct_colors()
    );
    for c in &PALETTE[..3] {
        assert!(img.contains_color(*c), "palette colour {c:?} missing");
    }
    // Text and frame: plenty of dark pixels, but the image is mostly background.
    let dark = img
        .rgb
        .chunks_exact(3)
        .filter(|p| p.iter().all(|&v| v < 120))
        .count();
    assert!(dark > 2000, "{dark} dark pixels");
    let white = img
        .rgb
        .chunks_exact(3)
        .filter(|p| *p == [255, 255, 255])
        .count();
    assert!(white > (960 * 600) / 2);
    // No temporary file left behind.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn in_memory_render_matches_file() {
    let dir = scratch("mem");
    let path = dir.join("c.png");
    let chart = demo_chart();
    render_png(&chart, 400, 300, &path).unwrap();
    assert_eq!(
        decode_png(&path).unwrap(),
        render_image(&chart, 400, 300).unwrap()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let dir = scratch("degenerate");
    let nan = f64::NAN;
    let inf = f64::INFINITY;
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
            vec![Series::new(
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
            )],
            false,
        ),
        (
            "all_nan",
            vec![Series::new("n", vec![(nan, nan); 5], Style::Markers)],
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
            "unnamed",
            vec![Series::new("", vec![(0.0, 1.0), (1.0, 2.0)], Style::Dashed)],
            false,
        ),
    ];
    let ranges = [
        None,
        Some((0.5, 0.6)),
        Some((3.0, 3.0)),
        Some((f64::NAN, 1.0)),
        Some((1e300, -1e300)),
    ];
    for (name, series, log_y) in cases {
        for x_range in ranges {
            let chart = Chart {
                title: format!(
                    "case {name} with a deliberately long title that will not fit the image width"
                ),
                x_label: "x (unit)".into(),
                y_label: "y (unit)".into(),
                series: series.clone(),
                log_y,
                x_range,
                y_range: x_range,
            };
            let path = dir.join(format!("{name}.png"));
            render_png(&chart, MIN_SIDE, MIN_SIDE, &path).unwrap();
            render_png(&chart, 640, 400, &path).unwrap();
            let img = decode_png(&path).unwrap();
            assert_eq!((img.width, img.height), (640, 400), "{name}");
            assert!(img.distinct_colors() >= 2, "{name}");
        }
    }
    // Many series: colours repeat, dashes tell them apart; the legend shrinks.
    let many = Chart {
        series: (0..20)
            .map(|i| {
                Series::new(
                    format!("control volume {i}"),
                    vec![(0.0, i as f64), (1.0, i as f64 + 1.0)],
                    Style::Line,
                )
            })
            .collect(),
        ..Chart::default()
    };
    render_png(&many, 800, 500, &dir.join("many.png")).unwrap();
    assert!(render_png(&many, 10, 10, &dir.join("bad.png")).is_err());
    assert!(render_png(&many, 800, 500, &dir.join("missing/dir/x.png")).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn panels_stack_vertically() {
    let dir = scratch("stack");
    let path = dir.join("solver.png");
    let a = demo_chart();
    let b = Chart {
        title: "NLGS iterations".into(),
        series: vec![Series::new(
            "iterations",
            vec![(0.0, 10.0), (1.0, 40.0)],
            Style::Line,
        )],
        ..Chart::default()
    };
    render_png_stack(&[a, b], 800, 400, &path).unwrap();
    let img = decode_png(&path).unwrap();
    assert_eq!((img.width, img.height), (800, 800));
    render_png_stack(&[], 800, 400, &path).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn stacked_bars_decode_with_segment_colours() {
    let dir = scratch("bars");
    let path = dir.join("timings.png");
    let chart = BarChart {
        title: "Time per phase".into(),
        x_label: "configuration".into(),
        y_label: "time (s)".into(),
        categories: vec![
            "NLGS\n1 thread".into(),
            "NLGS\n2 threads".into(),
            "DDM 2x2x1\n2 threads".into(),
        ],
        segments: vec![
            "detection".into(),
            "NLGS subdomains".into(),
            "NLGS interface".into(),
            "other".into(),
        ],
        values: vec![
            vec![1.0, 6.0, 0.0, 0.5],
            vec![0.6, 3.4, 0.0, 0.3],
            vec![0.6, 2.0, 0.8, 0.3],
        ],
    };
    render_stacked_bars(&chart, 960, 600, &path).unwrap();
    let img = decode_png(&path).unwrap();
    assert_eq!((img.width, img.height), (960, 600));
    for c in &PALETTE[..4] {
        assert!(img.contains_color(*c), "segment colour {c:?} missing");
    }
    assert_eq!(img, render_stacked_bars_image(&chart, 960, 600).unwrap());
    // Degenerate bar charts.
    for bad in [
        BarChart::default(),
        BarChart {
            categories: vec!["a".into(), "b".into()],
            segments: vec!["s".into()],
            values: vec![vec![f64::NAN], vec![-1.0, 2.0, 3.0]],
            ..BarChart::default()
        },
        BarChart {
            categories: (0..40)
                .map(|i| format!("a very long category name {i}"))
                .collect(),
            segments: vec!["x".into(); 12],
            values: vec![vec![1e300; 12]; 40],
            ..BarChart::default()
        },
    ] {
        render_stacked_bars(&bad, 320, 200, &path).unwrap();
        assert!(decode_png(&path).is_ok());
    }
    let _ = std::fs::remove_dir_all(&dir);
}
