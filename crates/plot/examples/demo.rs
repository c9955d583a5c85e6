//! Renders sample charts to look at: `cargo run -p ballast-plot --example demo -- DIR`.

use ballast_plot::{
    render_png, render_png_stack, render_stacked_bars, BarChart, Chart, Series, Style,
};
use std::path::PathBuf;

fn main() -> std::io::Result<()> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "plot-demo".into()),
    );
    std::fs::create_dir_all(&dir)?;
    let t: Vec<f64> = (0..=300).map(|i| i as f64 * 1e-3).collect();
    let curve = |f: &dyn Fn(f64) -> f64| t.iter().map(|&x| (x, f(x))).collect::<Vec<_>>();

    let compacity = Chart {
        title: "Compacity per control volume".into(),
        x_label: "time (s)".into(),
        y_label: "compacity (-)".into(),
        series: (0..4)
            .map(|k| {
                let k = k as f64;
                Series::new(
                    format!("CV {}", k + 1.0),
                    curve(&|x| 0.58 + 0.01 * k + 0.02 * (1.0 - (-x * (20.0 + 5.0 * k)).exp())),
                    Style::Line,
                )
            })
            .collect(),
        log_y: false,
        x_range: None,
        y_range: None,
    };
    render_png(&compacity, 960, 600, &dir.join("compacity.png"))?;

    let energy = Chart {
        title: "Kinetic energy".into(),
        x_label: "time (s)".into(),
        y_label: "kinetic energy (J)".into(),
        series: vec![Series::new(
            "grains",
            curve(&|x| 50.0 * (-x * 40.0).exp() + 1e-4),
            Style::Line,
        )],
        log_y: true,
        x_range: None,
        y_range: None,
    };
    render_png(&energy, 960, 600, &dir.join("energy.png"))?;

    let contacts = Chart {
        title: "Contact points".into(),
        x_label: "time (s)".into(),
        y_label: "contacts (-)".into(),
        series: vec![Series::new(
            "contacts",
            curve(&|x| 4000.0 * (1.0 - (-x * 30.0).exp())),
            Style::Line,
        )],
        log_y: false,
        x_range: None,
        y_range: None,
    };
    let iterations = Chart {
        title: "NLGS iterations per step".into(),
        x_label: "time (s)".into(),
        y_label: "iterations (-)".into(),
        series: vec![Series::new(
            "iterations",
            curve(&|x| 20.0 + 180.0 * (x * 50.0).sin().abs()),
            Style::Markers,
        )],
        log_y: false,
        x_range: None,
        y_range: None,
    };
    render_png_stack(&[contacts, iterations], 960, 420, &dir.join("solver.png"))?;

    let threads = [1.0, 2.0, 4.0, 8.0, 16.0];
    let speedup = Chart {
        title: "Speedup versus threads".into(),
        x_label: "threads".into(),
        y_label: "speedup (-)".into(),
        series: vec![
            Series::new(
                "NLGS",
                threads.iter().map(|&p| (p, p / (1.0 + 0.1 * p))).collect(),
                Style::LineMarkers,
            ),
            Series::new(
                "DDM 4x4x1",
                threads.iter().map(|&p| (p, p / (1.0 + 0.03 * p))).collect(),
                Style::LineMarkers,
            ),
            Series::new("ideal", vec![(1.0, 1.0), (16.0, 16.0)], Style::Dashed)
                .with_color([120, 120, 120]),
        ],
        log_y: false,
        x_range: None,
        y_range: None,
    };
    render_png(&speedup, 960, 600, &dir.join("speedup.png"))?;

    let bars = BarChart {
        title: "Time per phase (Table 1)".into(),
        x_label: String::new(),
        y_label: "time (s)".into(),
        categories: vec![
            "NLGS\n1 thread".into(),
            "NLGS\n16 threads".into(),
            "DDM 4x4x1\n1 thread".into(),
            "DDM 4x4x1\n16 threads".into(),
        ],
        segments: vec![
            "detection".into(),
            "NLGS subdomains".into(),
            "NLGS interface".into(),
            "other".into(),
        ],
        values: vec![
            vec![2.1, 30.0, 0.0, 1.2],
            vec![0.4, 5.0, 0.0, 0.3],
            vec![2.1, 24.0, 6.0, 1.2],
            vec![0.4, 2.2, 0.9, 0.3],
        ],
    };
    render_stacked_bars(&bars, 960, 600, &dir.join("timings.png"))?;
    println!("charts in {}", dir.display());
    Ok(())
}
