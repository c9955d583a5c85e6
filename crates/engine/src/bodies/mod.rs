//! Rigid bodies, stored as a structure of arrays indexed by body number.
//!
//! Rotational state: for dynamic bodies the state variable is the world-frame angular momentum
//! `L` about the centre of mass; the angular velocity is derived, `ω = I_w(q)⁻¹ L` with
//! `I_w = R I_body Rᵀ`. Without torque `L` is then constant to round-off, which a torque-free
//! tumbling body requires, whatever the orientation error of the exponential-map update.

pub mod driver;
mod ranks;

pub use ranks::BodyValues;

pub use driver::{Driver, Limits, Profile, Term, Velocities};

use crate::math::{DMat3, DQuat, DVec3};
use crate::shapes::{ConvexPolyhedron, PolyhedronBuild, Shape};
use std::sync::Arc;

/// How a body moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BodyKind {
    /// Moves under gravity and contact impulses.
    Dynamic,
    /// Velocity imposed by a [`Driver`]; unaffected by contacts.
    Kinematic,
    /// Never moves.
    Fixed,
}

/// All bodies of a simulation.
#[derive(Clone, Debug, Default)]
pub struct BodySet {
    pub kind: Vec<BodyKind>,
    pub shape: Vec<Shape>,
    /// Group number, used by the friction table and outputs.
    pub group: Vec<u32>,
    /// World position of the centre of mass (of the body origin for planes).
    pub position: Vec<DVec3>,
    /// Rotation body → world.
    pub orientation: Vec<DQuat>,
    pub velocity: Vec<DVec3>,
    /// World-frame angular velocity.
    pub angular_velocity: Vec<DVec3>,
    /// World-frame angular momentum about the centre of mass (dynamic bodies).
    pub angular_momentum: Vec<DVec3>,
    /// 1/m; zero for fixed bodies. Kinematic bodies carry the mass they have once released
    /// (see [`Driver::release_at`]); the solver treats them as infinitely heavy while driven.
    pub inv_mass: Vec<f64>,
    /// Principal moments of inertia (kg m²) about the body axes.
    pub inertia: Vec<DVec3>,
    /// Imposed velocity of kinematic bodies. Boxed: a few bodies have one, and a driver
    /// inline would cost every grain its size (about 0.4 kB).
    pub driver: Vec<Option<Box<Driver>>>,
}

impl BodySet {
    /// Number of bodies.
    pub fn len(&self) -> usize {
        self.kind.len()
    }

    /// True when there is no body.
    pub fn is_empty(&self) -> bool {
        self.kind.is_empty()
    }

    /// Adds a polyhedron of the given density (kg/m³), returns its index.
    pub fn add_polyhedron(
        &mut self,
        build: PolyhedronBuild,
        density: f64,
        kind: BodyKind,
        group: u32,
    ) -> usize {
        self.add_shared_polyhedron(
            Arc::new(build.shape),
            build.position,
            build.orientation,
            density,
            kind,
            group,
        )
    }

    /// Adds a polyhedron whose shape may be shared with other bodies (or with a cache), placed
    /// with its centre of mass at `position`, rotated by `orientation`; returns its index.
    pub fn add_shared_polyhedron(
        &mut self,
        shape: Arc<ConvexPolyhedron>,
        position: DVec3,
        orientation: DQuat,
        density: f64,
        kind: BodyKind,
        group: u32,
    ) -> usize {
        let mass = density * shape.volume;
        let inertia = shape.unit_inertia * density;
        // Kinematic bodies carry their mass too: they may be released (see `Driver::release_at`).
        let inv_mass = if kind == BodyKind::Fixed {
            0.0
        } else {
            1.0 / mass
        };
        self.push(
            kind,
            Shape::Polyhedron(shape),
            group,
            position,
            orientation,
            inv_mass,
            inertia,
        )
    }

    /// Adds a fixed half-space whose boundary passes through `point` with outward normal
    /// `normal` (the solid is on the side opposite to `normal`).
    pub fn add_plane(&mut self, point: DVec3, normal: DVec3, group: u32) -> usize {
        let n = normal.normalize();
        // Body frame: origin at `point`, the plane normal is the body z axis.
        let rot = DQuat::from_rotation_arc(DVec3::Z, n);
        self.push(
            BodyKind::Fixed,
            Shape::Plane { normal: DVec3::Z },
            group,
            point,
            rot,
            0.0,
            DVec3::ZERO,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        kind: BodyKind,
        shape: Shape,
        group: u32,
        position: DVec3,
        orientation: DQuat,
        inv_mass: f64,
        inertia: DVec3,
    ) -> usize {
        self.kind.push(kind);
        self.shape.push(shape);
        self.group.push(group);
        self.position.push(position);
        self.orientation.push(orientation.normalize());
        self.velocity.push(DVec3::ZERO);
        self.angular_velocity.push(DVec3::ZERO);
        self.angular_momentum.push(DVec3::ZERO);
        self.inv_mass.push(inv_mass);
        self.inertia.push(inertia);
        self.driver.push(None);
        self.len() - 1
    }

    /// Sets the angular velocity of body `i` (and its angular momentum if dynamic).
    pub fn set_angular_velocity(&mut self, i: usize, omega: DVec3) {
        self.angular_velocity[i] = omega;
        if self.kind[i] == BodyKind::Dynamic {
            self.angular_momentum[i] = self.inertia_world(i) * omega;
        }
    }

    /// Frees the spare capacity the per-body arrays grew while the scene was added body by
    /// body (up to half of each array).
    pub(crate) fn shrink_to_fit(&mut self) {
        self.kind.shrink_to_fit();
        self.shape.shrink_to_fit();
        self.group.shrink_to_fit();
        self.position.shrink_to_fit();
        self.orientation.shrink_to_fit();
        self.velocity.shrink_to_fit();
        self.angular_velocity.shrink_to_fit();
        self.angular_momentum.shrink_to_fit();
        self.inv_mass.shrink_to_fit();
        self.inertia.shrink_to_fit();
        self.driver.shrink_to_fit();
    }

    /// Re-allocates the polyhedra in body order (a shape shared by several bodies stays
    /// shared). Contact detection reads the topology of bodies with nearby numbers together;
    /// shapes allocated in another order (generated, then renumbered along the track) scatter
    /// those reads over the heap, and they miss the caches. Changes no value.
    pub(crate) fn compact_shapes(&mut self) {
        let mut done: std::collections::HashMap<*const ConvexPolyhedron, Arc<ConvexPolyhedron>> =
            std::collections::HashMap::new();
        for s in &mut self.shape {
            if let Shape::Polyhedron(p) = s {
                let fresh = done
                    .entry(Arc::as_ptr(p))
                    .or_insert_with(|| Arc::new(ConvexPolyhedron::clone(p)));
                *p = Arc::clone(fresh);
            }
        }
    }

    /// Turns the kinematic bodies whose driver's `release_at` is ≤ `t` into dynamic ones. Their
    /// angular momentum is already `I_w ω` (the update keeps it so for driven bodies), so this
    /// only changes the kind and is idempotent: a resumed run calls it again bit-identically.
    pub(crate) fn apply_releases(&mut self, t: f64) {
        for i in 0..self.len() {
            if self.kind[i] == BodyKind::Kinematic
                && self.driver[i].as_ref().is_some_and(|d| d.released(t))
            {
                self.kind[i] = BodyKind::Dynamic;
            }
        }
    }

    /// The kind body `i` was created with: a released body reports `Kinematic`.
    pub(crate) fn scene_kind(&self, i: usize) -> BodyKind {
        match (&self.driver[i], self.kind[i]) {
            (Some(d), BodyKind::Dynamic) if d.release_at.is_some() => BodyKind::Kinematic,
            (_, k) => k,
        }
    }

    /// Mass of body `i` (infinite for fixed bodies and planes).
    pub fn mass(&self, i: usize) -> f64 {
        1.0 / self.inv_mass[i]
    }

    /// World inertia tensor `R I Rᵀ` of body `i`.
    pub fn inertia_world(&self, i: usize) -> DMat3 {
        let r = DMat3::from_quat(self.orientation[i]);
        r * DMat3::from_diagonal(self.inertia[i]) * r.transpose()
    }

    /// World inverse inertia tensor `R I⁻¹ Rᵀ`, zero for non-dynamic bodies.
    pub(crate) fn inv_inertia_world(&self, i: usize) -> DMat3 {
        if self.kind[i] != BodyKind::Dynamic {
            return DMat3::ZERO;
        }
        let r = DMat3::from_quat(self.orientation[i]);
        r * DMat3::from_diagonal(self.inertia[i].recip()) * r.transpose()
    }

    /// Kinetic energy of the dynamic bodies: their [`BodySet::kinetic_energy_of`] summed in
    /// body order.
    pub fn kinetic_energy(&self) -> f64 {
        (0..self.len())
            .filter(|&i| self.kind[i] == BodyKind::Dynamic)
            .map(|i| self.kinetic_energy_of(i))
            .sum()
    }

    /// Kinetic energy of body `i`, translation and rotation: `½ m |v|² + ½ ω · L`.
    pub fn kinetic_energy_of(&self, i: usize) -> f64 {
        0.5 * self.mass(i) * self.velocity[i].length_squared()
            + 0.5 * self.angular_velocity[i].dot(self.angular_momentum[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Compacting re-allocates each distinct shape once, keeps shared shapes shared, and
    /// changes no value.
    #[test]
    fn compact_shapes_keeps_values_and_sharing() {
        let cube = Arc::new(ConvexPolyhedron::cuboid(DVec3::splat(0.01)).unwrap().shape);
        let slab = Arc::new(
            ConvexPolyhedron::cuboid(DVec3::new(0.02, 0.01, 0.005))
                .unwrap()
                .shape,
        );
        let mut b = BodySet::default();
        for (k, s) in [&cube, &slab, &cube].into_iter().enumerate() {
            let x = DVec3::new(k as f64, 0.0, 0.0);
            b.add_shared_polyhedron(
                Arc::clone(s),
                x,
                DQuat::IDENTITY,
                2700.0,
                BodyKind::Dynamic,
                0,
            );
        }
        b.add_plane(DVec3::ZERO, DVec3::Z, 1);
        b.compact_shapes();
        let poly = |i: usize| match &b.shape[i] {
            Shape::Polyhedron(p) => Arc::clone(p),
            Shape::Plane { .. } => panic!("body {i} is a plane"),
        };
        assert!(!Arc::ptr_eq(&poly(0), &cube), "re-allocated");
        assert!(Arc::ptr_eq(&poly(0), &poly(2)), "still shared");
        // Debug prints every f64 in a form that round-trips: equal text, equal values.
        assert_eq!(format!("{:?}", poly(0)), format!("{cube:?}"));
        assert_eq!(format!("{:?}", poly(1)), format!("{slab:?}"));
        assert!(matches!(b.shape[3], Shape::Plane { .. }));
    }
}
