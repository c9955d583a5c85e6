//! Quality figures of a preset's or a track scenario file's prepared bed (read from the cache, or prepared): grains, bulk
//! compacity, compacity under each block and in each crib, largest overlap, speeds.
//!
//! ```bash
//! cargo run --release -p ballast-railway --example bed_quality -- paper CACHE_DIR
//! cargo run --release -p ballast-railway --example bed_quality -- my_track.toml CACHE_DIR
//! ```

use ballast_engine::math::DVec3;
use ballast_railway::compacity;
use ballast_railway::preparation::load_or_prepare;
use ballast_railway::scene::{build_bodies, Blocks};
use ballast_railway::TrackScenario;
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (preset, cache) = match args.as_slice() {
        [_, p, c] => (p.as_str(), PathBuf::from(c)),
        _ => {
            eprintln!("usage: bed_quality PRESET|FILE CACHE_DIR");
            std::process::exit(2);
        }
    };
    let scenario = match std::fs::read_to_string(preset) {
        Ok(text) => TrackScenario::from_toml(&text).map_err(|e| e.to_string()),
        Err(_) => TrackScenario::preset(preset).map_err(|e| e.to_string()),
    };
    let s = match scenario {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let (bed, _) = match load_or_prepare(
        &s.track,
        &s.ballast,
        &s.preparation,
        &s.friction,
        Some(&cache),
        &mut |_| {},
    ) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let r = &bed.report;
    println!("from cache: {}", bed.from_cache);
    println!("{r:#?}");
    let (bodies, layout) = build_bodies(
        &s.track,
        &Blocks::Fixed,
        None,
        &bed.grains,
        s.ballast.grains.density,
    );
    let grains = |i: usize| layout.grains.contains(&i);
    let t = &s.track;
    let w = t.width;
    // One grain size (40 mm) from the walls and the floor, up to 20 mm under the soffits.
    let bulk = compacity(
        &bodies,
        grains,
        DVec3::new(0.04, -0.5 * w + 0.04, 0.04),
        DVec3::new(t.length() - 0.04, 0.5 * w - 0.04, t.depth - 0.02),
    )
    .expect("a valid box");
    println!("bulk compacity under the soffits: {bulk:.4}");
    for k in 1..=t.blocks {
        let b = t.under_block(k, s.indicators.depth);
        let c = compacity(&bodies, grains, b.min, b.max).expect("a valid box");
        println!("under block {k}: {c:.4}");
    }
    for k in 0..=t.blocks {
        if let Some(b) = t.crib(k) {
            let c = compacity(&bodies, grains, b.min, b.max).expect("a valid box");
            println!("crib {k}: {c:.4}");
        }
    }
}
