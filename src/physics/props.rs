//! A rigid body's constant properties, interned once per process so that a body's state —
//! what every step copies, logs and sends — holds a 4-byte handle instead of 40 bytes that
//! never change (SPEC.md §5.1).
//!
//! The table is process-wide and append-only: [`BodyProps::intern`] returns the handle of
//! an equal entry (equal bits) or appends one; [`PropsId::get`] reads without a lock. The
//! handle's value depends on the order in which a process first met each kind of body, so
//! it never enters a result: hashes, checkpoints and messages between processes carry the
//! properties themselves, and two bodies' handles are equal exactly when their properties'
//! bits are.

use super::body::{Material, Shape};
use crate::math::Vec3;
use std::collections::BTreeMap;
use std::sync::Mutex;

/// A body's shape, inverse mass and inertia, and surface coefficients: what does not change
/// while it moves; with two figures derived from them once, here, instead of at every use.
/// Two are equal exactly when their bits are (as interning compares them: `-0.0` is not
/// `+0.0`).
#[derive(Clone, Copy, Debug)]
pub struct BodyProps {
    shape: Shape,
    inv_mass: f32,
    inv_inertia: Vec3,
    friction: f32,
    restitution: f32,
    /// `shape.bounding_radius()`.
    bounding_radius: f32,
    /// Whether the three principal inverse inertias are equal (a ball, a cube): the world
    /// frame inverse inertia is then that number times the identity at every orientation.
    isotropic: bool,
}

/// The handle of an interned [`BodyProps`] (process-local; see the module's doc). It has no
/// order on purpose: its value depends on the order in which the process met each kind of
/// body, so sorting by it would make results depend on that.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PropsId(u32);

/// The interned properties, by handle.
static TABLE: boxcar::Vec<BodyProps> = boxcar::Vec::new();

/// The handle of each interned entry, by its bits.
static INDEX: Mutex<BTreeMap<PropsKey, PropsId>> = Mutex::new(BTreeMap::new());

/// The bits of a [`BodyProps`]: shape kind, three shape words, inverse mass, three inverse
/// inertias, friction, restitution.
type PropsKey = [u32; 10];

impl BodyProps {
    /// The properties of a body of `shape` and `material`: mass from the density, inertia of
    /// the solid shape.
    pub fn new(shape: Shape, material: Material) -> BodyProps {
        let mass = material.density * shape.volume();
        let inertia = shape.unit_inertia() * mass;
        BodyProps::from_parts(
            shape,
            1.0 / mass,
            inertia.map(|i| 1.0 / i),
            material.friction,
            material.restitution,
        )
    }

    /// Properties given part by part (as a checkpoint stores them), taken as they are.
    pub fn from_parts(
        shape: Shape,
        inv_mass: f32,
        inv_inertia: Vec3,
        friction: f32,
        restitution: f32,
    ) -> BodyProps {
        let d = inv_inertia;
        BodyProps {
            shape,
            inv_mass,
            inv_inertia,
            friction,
            restitution,
            bounding_radius: shape.bounding_radius(),
            isotropic: d.x == d.y && d.y == d.z,
        }
    }

    /// Collision shape.
    #[inline]
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// 1 / mass.
    #[inline]
    pub fn inv_mass(&self) -> f32 {
        self.inv_mass
    }

    /// Inverse principal moments of inertia, body frame.
    #[inline]
    pub fn inv_inertia(&self) -> Vec3 {
        self.inv_inertia
    }

    /// Coulomb friction coefficient.
    #[inline]
    pub fn friction(&self) -> f32 {
        self.friction
    }

    /// Restitution coefficient.
    #[inline]
    pub fn restitution(&self) -> f32 {
        self.restitution
    }

    /// Radius of the smallest sphere about the centre that holds the shape.
    #[inline]
    pub fn bounding_radius(&self) -> f32 {
        self.bounding_radius
    }

    /// Whether the three principal inverse inertias are equal.
    #[inline]
    pub fn isotropic(&self) -> bool {
        self.isotropic
    }

    /// The handle of these properties: an equal (same bits) entry's, else a new entry's.
    pub fn intern(self) -> PropsId {
        let key = self.key();
        // A panic elsewhere while the lock was held cannot leave the map inconsistent (an
        // entry is pushed before it is indexed), so a poisoned lock is used as it is.
        let mut index = INDEX.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(&id) = index.get(&key) {
            return id;
        }
        let slot = TABLE.push(self);
        let id = PropsId(u32::try_from(slot).expect("fewer than 2^32 kinds of body"));
        index.insert(key, id);
        id
    }

    fn key(&self) -> PropsKey {
        let (kind, s) = match self.shape {
            Shape::Ball { radius } => (0, [radius.to_bits(), 0, 0]),
            Shape::Cuboid { half_extents: h } => (1, h.map(f32::to_bits)),
        };
        let i = self.inv_inertia;
        [
            kind,
            s[0],
            s[1],
            s[2],
            self.inv_mass.to_bits(),
            i.x.to_bits(),
            i.y.to_bits(),
            i.z.to_bits(),
            self.friction.to_bits(),
            self.restitution.to_bits(),
        ]
    }
}

impl PartialEq for BodyProps {
    fn eq(&self, other: &Self) -> bool {
        self.key() == other.key()
    }
}

impl PropsId {
    /// The properties this handle stands for.
    #[inline]
    pub fn get(self) -> &'static BodyProps {
        // SAFETY: `get_unchecked` needs the entry at this index (and its bucket) to be
        // initialised. A `PropsId` is made only by `intern` (its field is private; no
        // `Default`, no deserialiser), from the index `TABLE.push` returned while `INDEX`'s
        // lock was held, and `push` allocates the bucket and writes the entry before
        // returning; the table never removes an entry and a bucket pointer, once set, never
        // changes. A thread holding the handle made it, found it under the same lock (whose
        // acquire orders the entry's write before this read), or received it inside a body
        // through something that synchronises — a channel, a lock, a thread spawn or join;
        // safe Rust has no other way to move a value between threads — so the bucket
        // pointer's and the entry's writes happen before these reads. Tested by
        // `interning_from_many_threads_gives_one_handle_per_kind` (handles read on threads
        // other than the one that pushed the entry).
        unsafe { TABLE.get_unchecked(self.0 as usize) }
    }

    /// How many kinds of body this process has interned (the table never shrinks).
    pub fn interned() -> usize {
        TABLE.count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_properties_share_one_handle_and_different_bits_do_not() {
        let m = Material::default();
        let a = BodyProps::new(Shape::Ball { radius: 0.25 }, m).intern();
        let b = BodyProps::new(Shape::Ball { radius: 0.25 }, m).intern();
        assert_eq!(a, b);
        let c = BodyProps::new(
            Shape::Ball { radius: 0.25 },
            Material {
                friction: 0.25,
                ..m
            },
        )
        .intern();
        assert_ne!(a, c);
        assert_eq!(c.get().friction(), 0.25);
        let p = a.get();
        let with = |r: f32| {
            BodyProps::from_parts(p.shape(), p.inv_mass(), p.inv_inertia(), p.friction(), r)
        };
        assert_ne!(
            with(-0.0).intern(),
            with(0.0).intern(),
            "-0.0 and +0.0 differ in bits"
        );
        assert_ne!(with(-0.0), with(0.0), "equality is by bits, as interning");
        assert_eq!(with(0.25), with(0.25));
        assert!(PropsId::interned() >= 3);
    }

    #[test]
    fn a_body_state_is_68_bytes_and_keeps_its_properties() {
        // What every step copies, logs and sends per body (SPEC.md §5.1): id, handle,
        // position, orientation, both velocities and two 16-bit counters.
        assert_eq!(std::mem::size_of::<crate::physics::Body>(), 68);
        let m = Material {
            density: 2.0,
            friction: 0.3,
            restitution: 0.2,
        };
        let shape = Shape::Cuboid {
            half_extents: [0.5, 0.25, 1.0],
        };
        let b = crate::physics::Body::new(7, shape, m, Vec3::zeros(), Default::default());
        assert_eq!(b.shape(), shape);
        assert_eq!(b.inv_mass(), 1.0 / (2.0 * shape.volume()));
        assert_eq!((b.friction(), b.restitution()), (0.3, 0.2));
        assert_eq!(b.bounding_radius(), shape.bounding_radius());
        assert!(!b.props().isotropic());
        assert_eq!(b.props_id(), BodyProps::new(shape, m).intern());
        let far =
            crate::physics::Body::new(u64::MAX - 3, shape, m, Vec3::zeros(), Default::default());
        assert_eq!(far.id(), u64::MAX - 3, "both halves of the id");
        let shown = format!("{b:?}");
        assert!(
            shown.contains("id: 7") && shown.contains("friction: 0.3"),
            "Debug shows the id and the properties, not the handle: {shown}"
        );
    }

    #[test]
    fn interning_from_many_threads_gives_one_handle_per_kind() {
        let handles: Vec<Vec<PropsId>> = std::thread::scope(|s| {
            let workers: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(|| {
                        (0..200)
                            .map(|k| {
                                let r = 1.0 + k as f32 / 1024.0;
                                BodyProps::new(Shape::Ball { radius: r }, Material::default())
                                    .intern()
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            workers.into_iter().map(|w| w.join().unwrap()).collect()
        });
        for h in &handles[1..] {
            assert_eq!(h, &handles[0]);
        }
        for (k, id) in handles[0].iter().enumerate() {
            assert_eq!(
                id.get().shape(),
                Shape::Ball {
                    radius: 1.0 + k as f32 / 1024.0
                }
            );
        }
    }
}
