//! Checks of the figures a run writes, shared by the command's tests: each as `NAME.svg` (parses
//! as XML, has its labels as text) and `NAME.png` (decodes, as large as the SVG, at least
//! 1600 px wide, not blank, antialiased text in the title band).

use std::path::Path;

/// The figures of a run whose data does not depend on wall-clock time: two runs of one
/// scenario give them byte for byte (`timings` and `phases` show measured times).
pub const DETERMINISTIC: [&str; 7] = [
    "solver",
    "energy",
    "penetration",
    "compacity",
    "tines",
    "blocks",
    "coordination",
];

/// A decoded PNG: width, height and RGB pixels.
pub fn decode_png(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.starts_with(&[0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n']),
        "{}: no PNG signature",
        path.display()
    );
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec
        .read_info()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader
        .next_frame(&mut buf)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let data = &buf[..info.buffer_size()];
    let px: Vec<[u8; 3]> = match info.color_type {
        png::ColorType::Rgb => data.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
        png::ColorType::Rgba => data.chunks_exact(4).map(|p| [p[0], p[1], p[2]]).collect(),
        png::ColorType::Grayscale => data.iter().map(|&g| [g, g, g]).collect(),
        png::ColorType::GrayscaleAlpha => {
            data.chunks_exact(2).map(|p| [p[0], p[0], p[0]]).collect()
        }
        t => panic!("{}: colour type {t:?}", path.display()),
    };
    assert_eq!(px.len(), (info.width * info.height) as usize);
    (info.width, info.height, px)
}

/// Checks `dir/NAME.svg` and `dir/NAME.png` (see the module's documentation); `texts` must be
/// among the SVG's text elements (axis labels, legend entries).
pub fn check(dir: &Path, name: &str, texts: &[&str]) {
    let svg_path = dir.join(format!("{name}.svg"));
    let svg = std::fs::read_to_string(&svg_path)
        .unwrap_or_else(|e| panic!("{}: {e}", svg_path.display()));
    let doc = roxmltree::Document::parse(&svg)
        .unwrap_or_else(|e| panic!("{}: not XML: {e}", svg_path.display()));
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "svg", "{}", svg_path.display());
    let found: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| n.text().unwrap_or("").trim())
        .collect();
    for t in texts {
        assert!(
            found.contains(t),
            "{}: no text {t:?} in {found:?}",
            svg_path.display()
        );
    }
    let size = |a: &str| -> u32 {
        root.attribute(a)
            .and_then(|v| v.trim_end_matches("px").parse().ok())
            .unwrap_or_else(|| panic!("{}: no {a}", svg_path.display()))
    };
    let png_path = dir.join(format!("{name}.png"));
    let (w, h, px) = decode_png(&png_path);
    let shown = png_path.display();
    assert_eq!((size("width"), size("height")), (w, h), "{shown}");
    assert!(w >= 1600 && h >= 500, "{shown}: {w} × {h}");
    // Not blank: drawn pixels (axes, text, curves) beyond the white background.
    let drawn = px.iter().filter(|p| **p != [255, 255, 255]).count();
    assert!(drawn * 100 >= px.len(), "{shown}: {drawn} pixels drawn");
    // Antialiased text: the title band (top 70 rows, middle columns) has many greys.
    let mut greys: Vec<u8> = (0..70.min(h))
        .flat_map(|y| (w / 8..w * 7 / 8).map(move |x| (y * w + x) as usize))
        .map(|i| px[i])
        .filter(|p| p[0] == p[1] && p[1] == p[2])
        .map(|p| p[0])
        .collect();
    greys.sort_unstable();
    greys.dedup();
    assert!(greys.len() > 16, "{shown}: {} grey levels", greys.len());
}

/// The figures `names` are the same bytes in `a` and `b`, in both formats.
pub fn same(a: &Path, b: &Path, names: &[&str]) {
    for name in names {
        for ext in ["svg", "png"] {
            let f = format!("{name}.{ext}");
            let (x, y) = (std::fs::read(a.join(&f)), std::fs::read(b.join(&f)));
            assert!(
                x.unwrap() == y.unwrap(),
                "{f} differs between {} and {}",
                a.display(),
                b.display()
            );
        }
    }
}
