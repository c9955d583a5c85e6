//! Helpers shared by the command-line tests (`cli.rs`, `mpi.rs`): what a run folder holds,
//! read the way a user's script would.
#![allow(dead_code)]

/// `DIR/summary.json`.
pub fn summary(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// `summary.json` without its wall-clock timings.
pub fn summary_without_timings(dir: &std::path::Path) -> serde_json::Value {
    let mut s = summary(dir);
    s.as_object_mut().unwrap().remove("timings_s");
    s
}

/// The steps of the checkpoints in `DIR/checkpoints`, sorted.
pub fn checkpoint_steps(dir: &std::path::Path) -> Vec<u64> {
    let mut steps: Vec<u64> = std::fs::read_dir(dir.join("checkpoints"))
        .map(|d| {
            d.filter_map(|e| {
                let name = e.ok()?.file_name().into_string().ok()?;
                name.strip_prefix("checkpoint_")?
                    .strip_suffix(".bin")?
                    .parse()
                    .ok()
            })
            .collect()
        })
        .unwrap_or_default();
    steps.sort_unstable();
    steps
}

/// The rows of `DIR/series.csv`, header included, without the columns of wall-clock times
/// (`t_*`): what two runs of one scenario must share.
pub fn rows_without_timings(dir: &std::path::Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("series.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<bool> = header.iter().map(|h| !h.starts_with("t_")).collect();
    std::iter::once(header.join(","))
        .chain(lines.map(|l| {
            l.split(',')
                .zip(&keep)
                .filter(|(_, &k)| k)
                .map(|(x, _)| x)
                .collect::<Vec<_>>()
                .join(",")
        }))
        .collect()
}

/// The step of the last whole row of `series.csv` (0 when there is none), from its tail.
pub fn last_row(path: &std::path::Path) -> u64 {
    use std::io::{Read, Seek, SeekFrom};
    let Ok(mut f) = std::fs::File::open(path) else {
        return 0;
    };
    let len = f.metadata().map_or(0, |m| m.len());
    let mut tail = Vec::new();
    if f.seek(SeekFrom::Start(len.saturating_sub(1024))).is_err()
        || f.read_to_end(&mut tail).is_err()
    {
        return 0;
    }
    let text = String::from_utf8_lossy(&tail);
    let whole = &text[..text.rfind('\n').unwrap_or(0)];
    whole
        .rsplit('\n')
        .next()
        .and_then(|l| l.split(',').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or(0)
}

/// The names in `dir` ending in `.tmp`: what a write cut short leaves.
pub fn tmp_files(dir: &std::path::Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| n.ends_with(".tmp"))
                .collect()
        })
        .unwrap_or_default()
}

/// Seeded pseudo-random numbers (xorshift64): the kill moments are the same every time.
pub struct Moments(pub u64);

impl Moments {
    pub fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 % n.max(1)
    }
}
