//! Every scenario shipped in `examples/` parses and validates (track scenarios, with a
//! `[track]` table, as overlays on the default preset; the others as engine scenarios), so a
//! user's first `ballast run examples/…` never stops on its input.

use ballast_engine::laws::NormalLaw;
use ballast_engine::scenario::Scenario;
use ballast_railway::TrackScenario;
use std::path::{Path, PathBuf};

fn tomls(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            tomls(&p, out);
        } else if p.extension().is_some_and(|x| x == "toml") {
            out.push(p);
        }
    }
}

#[test]
fn every_example_scenario_validates() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let mut files = Vec::new();
    tomls(&root, &mut files);
    files.sort();
    assert!(files.len() >= 6, "{files:?}");
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let track = text.lines().any(|l| l.trim() == "[track]");
        let result = if track {
            TrackScenario::from_toml(&text)
                .and_then(|s| s.validate().map(|_| ()))
                .map_err(|e| e.to_string())
        } else {
            Scenario::from_toml(&text)
                .and_then(|s| s.validate())
                .map_err(|e| e.to_string())
        };
        assert!(result.is_ok(), "{}: {result:?}", f.display());
    }
}

/// `examples/soft_tamping.toml` is the default job with the settings its comment measures:
/// compliant contacts under the overlap law with the hyperbolic closure, at dt = 1e-4 s.
#[test]
fn the_soft_tamping_example_uses_the_overlap_law() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/soft_tamping.toml");
    let s = TrackScenario::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    let sim = &s.simulation;
    assert_eq!(sim.normal_law, NormalLaw::Overlap);
    assert_eq!(sim.contact_stiffness, Some(1e6));
    assert_eq!(sim.max_closure, Some(7.5e-4));
    assert_eq!(s.steps(), 17640);
    assert_eq!(s, TrackScenario::default_preset());
}
