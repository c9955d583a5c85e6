//! Track geometry: a ballast bed in a box with a row of sleeper blocks, and the control volumes
//! where the track indicators are measured.
//!
//! Frame: `x` along the track, `y` across it (along the block's long side, the rail above the
//! block centre at `y = 0`), `z` up with the bed's floor at `z = 0`. The bed spans
//! `x ∈ [0, length]`, `y ∈ [−width/2, width/2]`. Block `k` (1-based, numbered along `x`) is
//! centred at `x_k = length/2 + (k − (n+1)/2) · spacing`, its soffit (underside) at
//! `z = depth`, its top at `depth + height`: the cribs between blocks are filled to that top.

use crate::error::{refuse, FieldError};
use ballast_engine::math::DVec3;
use serde::{Deserialize, Serialize};

/// The ballast bed and its sleeper blocks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackSpec {
    /// Number of sleeper blocks along the track.
    pub blocks: usize,
    /// Block size `[along x, across y, height z]` (m): a bi-block sleeper block, 0.29 × 0.84 ×
    /// 0.22 m by default.
    pub block_size: [f64; 3],
    /// Distance between block centres along the track (m).
    pub spacing: f64,
    /// Ballast depth under the soffit (m).
    pub depth: f64,
    /// Bed width across the track (m).
    pub width: f64,
    /// Bed length along the track (m); `None` = `blocks × spacing` (half a crib beyond each end
    /// block).
    pub length: Option<f64>,
    /// Density of the blocks (kg/m³), used once they are released onto the ballast.
    pub block_density: f64,
}

impl Default for TrackSpec {
    /// One concrete bi-block sleeper block, 0.6 m spacing, 0.30 m of ballast under it, a 1.0 m
    /// wide bed (8 cm beyond each end of the block).
    fn default() -> Self {
        TrackSpec {
            blocks: 1,
            block_size: [0.29, 0.84, 0.22],
            spacing: 0.6,
            depth: 0.30,
            width: 1.0,
            length: None,
            block_density: 2400.0,
        }
    }
}

/// An axis-aligned box `[min, max]` (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    /// Volume (m³).
    pub fn volume(&self) -> f64 {
        let s = self.max - self.min;
        s.x * s.y * s.z
    }

    /// Centre.
    pub fn centre(&self) -> DVec3 {
        0.5 * (self.min + self.max)
    }

    /// Half extents.
    pub fn half_extents(&self) -> DVec3 {
        0.5 * (self.max - self.min)
    }
}

impl TrackSpec {
    /// Checks every field and that the blocks fit in the bed.
    ///
    /// # Errors
    ///
    /// The first invalid field, its value and what is allowed.
    pub fn validate(&self) -> Result<(), FieldError> {
        if !(1..=1000).contains(&self.blocks) {
            return Err(refuse("track.blocks", self.blocks, "1 to 1000 blocks"));
        }
        if !self
            .block_size
            .iter()
            .all(|&s| s.is_finite() && (0.01..=10.0).contains(&s))
        {
            return Err(refuse(
                "track.block_size",
                self.block_size,
                "[x, y, z] each between 0.01 and 10 m",
            ));
        }
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v <= 100.0 {
                Ok(())
            } else {
                Err(refuse(field, v, "finite, > 0 and ≤ 100 m"))
            }
        };
        positive("track.spacing", self.spacing)?;
        positive("track.depth", self.depth)?;
        positive("track.width", self.width)?;
        if let Some(l) = self.length {
            positive("track.length", l)?;
        }
        if self.spacing <= self.block_size[0] {
            return Err(refuse(
                "track.spacing",
                self.spacing,
                &format!(
                    "greater than the block size along the track, {} m",
                    self.block_size[0]
                ),
            ));
        }
        if self.width <= self.block_size[1] {
            return Err(refuse(
                "track.width",
                self.width,
                &format!(
                    "greater than the block size across the track, {} m",
                    self.block_size[1]
                ),
            ));
        }
        let needed = (self.blocks - 1) as f64 * self.spacing + self.block_size[0];
        if self.length() <= needed {
            return Err(refuse(
                "track.length",
                self.length(),
                &format!("greater than the row of blocks, {needed} m"),
            ));
        }
        if !(self.block_density.is_finite() && self.block_density > 0.0) {
            return Err(refuse(
                "track.block_density",
                self.block_density,
                "finite and > 0 kg/m³",
            ));
        }
        Ok(())
    }

    /// Bed length along the track (m).
    pub fn length(&self) -> f64 {
        self.length.unwrap_or(self.blocks as f64 * self.spacing)
    }

    /// Height of the soffits above the floor (m).
    pub fn soffit(&self) -> f64 {
        self.depth
    }

    /// Height of the block tops, the level the cribs are filled to (m).
    pub fn top(&self) -> f64 {
        self.depth + self.block_size[2]
    }

    /// x of the centre of block `k` (1-based).
    pub fn block_x(&self, k: usize) -> f64 {
        let n = self.blocks as f64;
        0.5 * self.length() + (k as f64 - 0.5 * (n + 1.0)) * self.spacing
    }

    /// The box occupied by block `k` (1-based) in its design position.
    pub fn block_box(&self, k: usize) -> Aabb {
        let [bx, by, bz] = self.block_size;
        let x = self.block_x(k);
        Aabb {
            min: DVec3::new(x - 0.5 * bx, -0.5 * by, self.depth),
            max: DVec3::new(x + 0.5 * bx, 0.5 * by, self.depth + bz),
        }
    }

    /// The bed box up to the block tops.
    pub fn bed_box(&self) -> Aabb {
        Aabb {
            min: DVec3::new(0.0, -0.5 * self.width, 0.0),
            max: DVec3::new(self.length(), 0.5 * self.width, self.top()),
        }
    }

    /// Volume of the bed box not taken by blocks (m³).
    pub fn void_volume(&self) -> f64 {
        let blocks: f64 = (1..=self.blocks).map(|k| self.block_box(k).volume()).sum();
        self.bed_box().volume() - blocks
    }

    /// Control volume under block `k`: its footprint, from `cv_depth` below the soffit to the
    /// soffit (fixed in space: the design soffit, not the lifted one).
    pub fn under_block(&self, k: usize, cv_depth: f64) -> Aabb {
        let b = self.block_box(k);
        Aabb {
            min: DVec3::new(b.min.x, b.min.y, self.depth - cv_depth),
            max: DVec3::new(b.max.x, b.max.y, self.depth),
        }
    }

    /// Control volume of crib `k` (`0..=blocks`): between block `k` and block `k + 1` (crib 0
    /// and crib `blocks` run from the end blocks to the bed ends), over the blocks' width
    /// across the track, from the soffit level to the top. `None` when the crib is empty (an
    /// end block against the bed end).
    pub fn crib(&self, k: usize) -> Option<Aabb> {
        let by = self.block_size[1];
        let x0 = if k == 0 { 0.0 } else { self.block_box(k).max.x };
        let x1 = if k == self.blocks {
            self.length()
        } else {
            self.block_box(k + 1).min.x
        };
        (x1 > x0).then(|| Aabb {
            min: DVec3::new(x0, -0.5 * by, self.depth),
            max: DVec3::new(x1, 0.5 * by, self.top()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_track_is_one_centred_block() {
        let t = TrackSpec::default();
        t.validate().unwrap();
        assert_eq!(t.length(), 0.6);
        assert!((t.block_x(1) - 0.3).abs() < 1e-15);
        let b = t.block_box(1);
        assert!((b.volume() - 0.29 * 0.84 * 0.22).abs() < 1e-15);
        let bed = 0.6 * 1.0 * 0.52;
        assert!((t.void_volume() - (bed - b.volume())).abs() < 1e-12);
        let (c0, c1) = (t.crib(0).unwrap(), t.crib(1).unwrap());
        assert!((c0.max.x - b.min.x).abs() < 1e-15 && (c1.min.x - b.max.x).abs() < 1e-15);
        assert!((c0.volume() - c1.volume()).abs() < 1e-15);
    }

    #[test]
    fn blocks_are_evenly_spaced_and_centred() {
        let t = TrackSpec {
            blocks: 7,
            ..TrackSpec::default()
        };
        t.validate().unwrap();
        for k in 1..7 {
            assert!((t.block_x(k + 1) - t.block_x(k) - 0.6).abs() < 1e-12);
        }
        assert!((t.block_x(4) - 0.5 * t.length()).abs() < 1e-12);
        // Inner cribs are spacing − block width long.
        let c = t.crib(3).unwrap();
        assert!((c.max.x - c.min.x - 0.31).abs() < 1e-12);
    }

    #[test]
    fn bad_geometry_names_the_field() {
        let t = TrackSpec {
            spacing: 0.2,
            ..TrackSpec::default()
        };
        assert_eq!(t.validate().unwrap_err().field, "track.spacing");
        let t = TrackSpec {
            width: 0.5,
            ..TrackSpec::default()
        };
        assert_eq!(t.validate().unwrap_err().field, "track.width");
        let t = TrackSpec {
            blocks: 3,
            length: Some(1.0),
            ..TrackSpec::default()
        };
        assert_eq!(t.validate().unwrap_err().field, "track.length");
        let t = TrackSpec {
            depth: f64::NAN,
            ..TrackSpec::default()
        };
        assert_eq!(t.validate().unwrap_err().field, "track.depth");
    }
}
