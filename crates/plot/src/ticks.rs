//! "Nice" axis ticks (1-2-5 steps) and their labels.

/// Largest magnitude an axis accepts: keeps `hi - lo` finite.
const MAX_ABS: f64 = 1e300;

/// Makes `[lo, hi]` a usable, non-empty, finite range: non-finite bounds give `[0, 1]`,
/// swapped bounds are ordered, and a degenerate range (constant data) is widened around its
/// value so that it still gets ticks.
pub fn sanitize_range(lo: f64, hi: f64) -> (f64, f64) {
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let (mut lo, mut hi) = if lo <= hi { (lo, hi) } else { (hi, lo) };
    lo = lo.clamp(-MAX_ABS, MAX_ABS);
    hi = hi.clamp(-MAX_ABS, MAX_ABS);
    let scale = lo.abs().max(hi.abs());
    if hi - lo <= scale * 1e-12 {
        // Constant data: ±5 % of the value (±1 around zero).
        let d = if scale == 0.0 { 1.0 } else { scale * 0.05 };
        lo -= d;
        hi += d;
    }
    (lo, hi)
}

/// Tick step of the ticks [`nice_ticks`] returns for the same arguments.
pub fn nice_step(lo: f64, hi: f64, max_ticks: usize) -> f64 {
    let t = nice_ticks(lo, hi, max_ticks);
    if t.len() >= 2 {
        t[1] - t[0]
    } else {
        1.0
    }
}

/// Tick values `k × step` with `step` = 1, 2 or 5 × 10ⁿ, at most `max_ticks` of them (at least
/// 2), that cover `[lo, hi]`: the first is ≤ `lo` and the last ≥ `hi`. Degenerate or
/// non-finite ranges are handled by [`sanitize_range`], so this never panics and never returns
/// fewer than two ticks.
pub fn nice_ticks(lo: f64, hi: f64, max_ticks: usize) -> Vec<f64> {
    let (lo, hi) = sanitize_range(lo, hi);
    let max_ticks = max_ticks.clamp(2, 50);
    let raw = (hi - lo) / (max_ticks - 1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    // Start one size below `raw` and take the first step whose ticks fit.
    for m in [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0] {
        let step = m * mag;
        if !(step.is_finite() && step > 0.0) {
            break;
        }
        let (k0, k1) = ((lo / step).floor(), (hi / step).ceil());
        if k1 - k0 + 1.0 <= max_ticks as f64 {
            let n = (k1 - k0) as usize;
            return (0..=n).map(|i| clean((k0 + i as f64) * step)).collect();
        }
    }
    vec![lo, hi]
}

/// Turns `-0.0` into `0.0` (so no "-0" label).
fn clean(v: f64) -> f64 {
    if v == 0.0 {
        0.0
    } else {
        v
    }
}

/// Ticks of a logarithmic axis covering the positive range `[lo, hi]`: whole decades (every
/// few decades when the range is wide), with 2 and 5 in between when it spans two decades or
/// less. Returns the tick values (not their logarithms); the first is ≤ `lo`, the last ≥ `hi`.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let (e0, e1) = log_decades(lo, hi);
    let span = e1 - e0;
    if span <= 2 {
        let mut t = Vec::new();
        for e in e0..e1 {
            for m in [1.0, 2.0, 5.0] {
                t.push(m * 10f64.powi(e));
            }
        }
        t.push(10f64.powi(e1));
        t
    } else {
        let every = log_every(span);
        (e0..=e1)
            .step_by(every as usize)
            .map(|e| 10f64.powi(e))
            .collect()
    }
}

/// Decade step of a log axis spanning `span` decades: at most about 8 labelled decades.
fn log_every(span: i32) -> i32 {
    (span + 7) / 8
}

/// Decade exponents `(e0, e1)`, `e0 < e1`, of a log axis covering `[lo, hi]` (both > 0),
/// aligned on the decade step so that the end ticks are the axis ends.
pub fn log_decades(lo: f64, hi: f64) -> (i32, i32) {
    let ok = |v: f64| v.is_finite() && v > 0.0;
    let (lo, hi) = match (ok(lo), ok(hi)) {
        (true, true) => (lo.min(hi), lo.max(hi)),
        (true, false) => (lo, lo),
        (false, true) => (hi, hi),
        (false, false) => (1.0, 10.0),
    };
    let mut e0 = lo.log10().floor().clamp(-300.0, 300.0) as i32;
    let mut e1 = hi.log10().ceil().clamp(-300.0, 300.0) as i32;
    if e1 <= e0 {
        e1 = e0 + 1;
    }
    if e1 - e0 > 2 {
        let every = log_every(e1 - e0);
        e0 = e0.div_euclid(every) * every;
        e1 = -((-e1).div_euclid(every) * every);
    }
    (e0, e1)
}

/// Label of a linear-axis tick `v` on an axis of tick step `step`: fixed-point with just
/// enough decimals for the step, or scientific notation for very large or small values.
pub fn format_tick(v: f64, step: f64) -> String {
    let step = step.abs();
    if !v.is_finite() {
        return String::new();
    }
    if step > 0.0 && v.abs() < step * 1e-6 {
        return "0".into();
    }
    let a = v.abs();
    let step_exp = if step > 0.0 {
        (step.log10() + 1e-9).floor()
    } else {
        0.0
    };
    if (1e-4..1e6).contains(&step) && a < 1e6 {
        let d = (-step_exp).max(0.0) as usize;
        format!("{v:.d$}")
    } else {
        let p = ((a.log10() + 1e-9).floor() - step_exp).clamp(0.0, 4.0) as usize;
        format!("{v:.p$e}")
    }
}

/// Label of a logarithmic-axis tick: plain for 0.001 … 10000, else like `2e-5`.
pub fn format_log_tick(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return String::new();
    }
    let e = (v.log10() + 1e-9).floor() as i32;
    if (-3..=4).contains(&e) {
        let d = (-e).max(0) as usize;
        format!("{v:.d$}")
    } else {
        format!("{v:.0e}")
    }
}

/// Short label of a value for annotations (3 significant digits).
pub fn format_value(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    if v == 0.0 {
        return "0".into();
    }
    let e = (v.abs().log10() + 1e-9).floor() as i32;
    if (-3..6).contains(&e) {
        let d = (2 - e).max(0) as usize;
        format!("{v:.d$}")
    } else {
        format!("{v:.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn is_nice_step(step: f64) -> bool {
        let m = step / 10f64.powf(step.log10().floor());
        [1.0, 2.0, 5.0, 10.0]
            .iter()
            .any(|n| (m - n).abs() < 1e-6 * n)
    }

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        for &(lo, hi, n) in &[
            (0.0, 1.0, 6),
            (0.0, 0.37, 8),
            (-3.2, 17.9, 7),
            (0.5812, 0.6233, 6),
            (1e-7, 3.3e-6, 5),
            (12345.0, 98765.0, 10),
            (-1e9, 2.5e9, 4),
            (0.0, 1e-12, 3),
        ] {
            let t = nice_ticks(lo, hi, n);
            assert!(t.len() >= 2 && t.len() <= n, "{lo}..{hi}: {t:?}");
            assert!(t[0] <= lo && *t.last().unwrap() >= hi, "{lo}..{hi}: {t:?}");
            let step = t[1] - t[0];
            assert!(is_nice_step(step), "step {step} of {t:?}");
            for w in t.windows(2) {
                assert!(((w[1] - w[0]) - step).abs() < 1e-9 * step);
            }
            for v in &t {
                let k = v / step;
                assert!((k - k.round()).abs() < 1e-6, "{v} not a multiple of {step}");
            }
        }
    }

    #[test]
    fn degenerate_ranges_still_get_ticks() {
        for &(lo, hi) in &[
            (5.0, 5.0),
            (0.0, 0.0),
            (-2.0, -2.0),
            (f64::NAN, 1.0),
            (f64::NEG_INFINITY, f64::INFINITY),
            (3.0, 1.0),
            (-f64::MAX, f64::MAX),
            (1e-300, 1e-300),
        ] {
            let t = nice_ticks(lo, hi, 6);
            assert!(t.len() >= 2, "{lo}..{hi}: {t:?}");
            assert!(t.iter().all(|v| v.is_finite()));
            assert!(t[0] < t[t.len() - 1]);
        }
        assert_eq!(nice_ticks(3.0, 1.0, 3), vec![1.0, 2.0, 3.0]);
    }

    #[test]
    fn log_ticks_cover_decades() {
        assert_eq!(log_ticks(1.0, 1000.0), vec![1.0, 10.0, 100.0, 1000.0]);
        let t = log_ticks(0.3, 7.0);
        assert_eq!(t.len(), 7);
        assert!(t[0] <= 0.3 && *t.last().unwrap() >= 7.0);
        let t = log_ticks(1e-12, 1e6);
        assert!(t.len() <= 10 && t[0] <= 1e-12 && *t.last().unwrap() >= 1e6);
        assert!(log_ticks(-1.0, f64::NAN).len() >= 2);
        assert!(log_ticks(5.0, 5.0).len() >= 2);
    }

    #[test]
    fn labels_are_short_and_exact() {
        assert_eq!(format_tick(0.30000000000000004, 0.1), "0.3");
        assert_eq!(format_tick(-0.0, 0.5), "0");
        assert_eq!(format_tick(1e-17, 0.2), "0");
        assert_eq!(format_tick(2500.0, 500.0), "2500");
        assert_eq!(format_tick(0.0025, 0.0005), "0.0025");
        assert_eq!(format_tick(2.5e-6, 5e-7), "2.5e-6");
        assert_eq!(format_tick(3e9, 1e9), "3e9");
        assert_eq!(format_log_tick(0.001), "0.001");
        assert_eq!(format_log_tick(200.0), "200");
        assert_eq!(format_log_tick(1e-5), "1e-5");
        assert_eq!(format_value(0.012345), "0.0123");
        assert_eq!(format_value(123.456), "123");
        assert_eq!(format_value(f64::NAN), "n/a");
    }
}
