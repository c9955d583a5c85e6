//! Vertical sections through the bed at chosen moments of the cycle: the grains whose centre
//! lies in a thin slab around a vertical plane, with their speed and the load they carry, so
//! that a reader sees where the ballast went (`sections/*.csv` in the run folder, and the
//! section figures of the run report).
//!
//! Planes: along the track through the first tine row (`y` = the first `tine_y`), which cuts
//! the blades, the block and the cribs either side; and across the track through the axis of
//! the first tamped block (`x` = its centre), which cuts the ballast under the block from
//! shoulder to shoulder. Moments: just after the start (the prepared bed, before the lift
//! has moved anything), the end of each tamped block's squeeze, and the last step of the run
//! (after the release when the run covers the whole cycle).
//!
//! The load a grain carries is the sum of the normal forces of its contacts over the step
//! (normal impulses / h, N): the force network of the section.

use crate::scene::Layout;
use crate::tamping::Cycle;
use crate::track::TrackSpec;
use ballast_engine::world::World;
use std::fmt::Write as _;
use std::ops::Range;

/// Half thickness of the slab around a section plane (m): about half a mean ballast grain,
/// so that each grain cut by the plane appears once and the picture stays one grain deep.
pub(crate) const SLAB_HALF_WIDTH: f64 = 0.02;

/// Which vertical plane a section is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cut {
    /// The plane `y = y0`: points `(x, z)`.
    AlongTrack { y: f64 },
    /// The plane `x = x0`: points `(y, z)`.
    AcrossTrack { x: f64 },
}

/// A section plane.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    /// File-name part, e.g. `tine-plane`.
    pub name: String,
    /// Words for a caption.
    pub label: String,
    pub cut: Cut,
}

impl Plane {
    /// Name of the horizontal coordinate along the plane.
    pub fn axis(&self) -> &'static str {
        match self.cut {
            Cut::AlongTrack { .. } => "x",
            Cut::AcrossTrack { .. } => "y",
        }
    }
}

/// A moment at which sections are written.
#[derive(Clone, Debug, PartialEq)]
pub struct Moment {
    /// File-name part, e.g. `end-of-squeeze-1`.
    pub name: String,
    /// Words for a caption.
    pub label: String,
    /// The step after which the sections are taken.
    pub step: u64,
}

/// One grain of a section.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SectionPoint {
    /// Body index of the grain.
    pub grain: usize,
    /// Horizontal coordinate along the plane (m): `x` or `y`.
    pub u: f64,
    /// Height of the grain's centre (m).
    pub z: f64,
    /// Speed of the grain's centre (m/s).
    pub speed: f64,
    /// Sum of the normal forces of its contacts over the last step (N).
    pub load: f64,
}

/// The sections of one track run: planes × moments.
#[derive(Clone, Debug, PartialEq)]
pub struct Sections {
    pub planes: Vec<Plane>,
    pub moments: Vec<Moment>,
    grains: Range<usize>,
}

/// CSV header of a section file.
pub const SECTION_HEADER: &str = "grain,u_m,z_m,speed_m_s,load_N";

impl Sections {
    /// The planes through the first tine row and the first tamped block, at the moments of
    /// `cycle` that fall within a run of `steps` steps of `dt`.
    pub fn new(
        track: &TrackSpec,
        tine_y: f64,
        layout: &Layout,
        cycle: &Cycle,
        tamped: &[usize],
        dt: f64,
        steps: u64,
    ) -> Sections {
        // Blocks are numbered from 1.
        let block = tamped.first().copied().unwrap_or(1);
        let planes = vec![
            Plane {
                name: "tine-plane".into(),
                label: format!("along the track through the tines at y = {tine_y} m"),
                cut: Cut::AlongTrack { y: tine_y },
            },
            Plane {
                name: "block-axis".into(),
                label: format!(
                    "across the track through the axis of block {} (x = {:.3} m)",
                    block,
                    track.block_x(block)
                ),
                cut: Cut::AcrossTrack {
                    x: track.block_x(block),
                },
            },
        ];
        let step_of = |t: f64| (t / dt).round().max(1.0) as u64;
        let mut moments = vec![Moment {
            name: "start".into(),
            label: "the prepared bed, before the lift".into(),
            step: 1,
        }];
        for (k, p) in cycle.phases.iter().enumerate() {
            let b = tamped.get(k).copied().unwrap_or(k + 1);
            moments.push(Moment {
                name: format!("end-of-squeeze-{}", k + 1),
                label: format!("the end of the squeeze of block {b}"),
                step: step_of(p.hold),
            });
        }
        let released = steps >= step_of(cycle.release);
        moments.push(Moment {
            name: if released { "after-release" } else { "end" }.into(),
            label: if released {
                "the end of the cycle, after the release".into()
            } else {
                format!("the last step of the run ({steps})")
            },
            step: steps.max(1),
        });
        moments.retain(|m| m.step <= steps.max(1));
        // Two moments on one step (a very short run) write the same files once.
        moments.dedup_by_key(|m| m.step);
        Sections {
            planes,
            moments,
            grains: layout.grains.clone(),
        }
    }

    /// The moments taken after step `step`.
    pub fn due(&self, step: u64) -> impl Iterator<Item = &Moment> {
        self.moments.iter().filter(move |m| m.step == step)
    }

    /// The grains of `world` in the slab of `plane`, in body order. On ranks that share the
    /// bodies, a collective (each grain read on the rank that answers for it).
    pub fn points(&self, world: &World, plane: &Plane) -> Vec<SectionPoint> {
        let b = &world.bodies;
        let h = world.settings.dt;
        let offset = |i: usize| {
            let p = b.position[i];
            match plane.cut {
                Cut::AlongTrack { y } => (p.y - y, p.x),
                Cut::AcrossTrack { x } => (p.x - x, p.y),
            }
        };
        let in_slab = |i: usize| self.grains.contains(&i) && offset(i).0.abs() <= SLAB_HALF_WIDTH;
        // The slab's grains, each from the rank that answers for it.
        let rows = world.gather_body_values(|i, out| {
            if in_slab(i) {
                out.extend([offset(i).1, b.position[i].z, b.velocity[i].length()]);
            }
        });
        let slab: Vec<usize> = rows.iter().map(|(i, _)| i).collect();
        let member = |i: u32| slab.binary_search(&(i as usize)).is_ok();
        let mut load = vec![0.0; self.grains.len()];
        // The loaded contacts of the slab's grains, from every rank, in pair order (each
        // grain's load sums them in a single process's order; the rest of the bed's contacts
        // stay where they are held).
        let c = &world.gather_contacts(|c, k| {
            (c.impulse[k].x > 0.0 || c.impulse[k].x.is_nan())
                && (member(c.body1[k]) || member(c.body2[k]))
        });
        for (k, r) in c.impulse.iter().enumerate() {
            if r.x <= 0.0 {
                continue;
            }
            for body in [c.body1[k], c.body2[k]] {
                let i = body as usize;
                if self.grains.contains(&i) {
                    load[i - self.grains.start] += r.x / h;
                }
            }
        }
        rows.iter()
            .map(|(i, v)| SectionPoint {
                grain: i,
                u: v[0],
                z: v[1],
                speed: v[2],
                load: load[i - self.grains.start],
            })
            .collect()
    }

    /// File name (under `sections/`) of a moment's section through a plane.
    pub fn file_name(moment: &Moment, plane: &Plane) -> String {
        format!("{}_{}.csv", moment.name, plane.name)
    }
}

/// The CSV text of a section ([`SECTION_HEADER`], one grain per line).
pub fn section_csv(points: &[SectionPoint]) -> String {
    let mut s = String::with_capacity(64 * (points.len() + 1));
    s.push_str(SECTION_HEADER);
    s.push('\n');
    for p in points {
        // Writing to a String cannot fail.
        let _ = writeln!(
            s,
            "{},{:.6e},{:.6e},{:.6e},{:.6e}",
            p.grain, p.u, p.z, p.speed, p.load
        );
    }
    s
}
