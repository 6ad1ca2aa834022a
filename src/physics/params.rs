//! Solver parameters and the limits that make the locality contract hold.

use super::body::SPEEDING_UP_TOLERANCE;
use serde::{Deserialize, Serialize};

/// Parameters of the rigid-body step. Defaults are the values SPEC.md documents.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverParams {
    /// Substeps per step (each of `dt / substeps` seconds).
    pub substeps: u32,
    /// Gauss–Seidel sweeps over one partner's contact points per substep.
    pub sweeps: u32,
    /// Sequential-impulse iterations of the plastic impact pass per substep (0 turns it
    /// off): over all of the body's points, each stopping the approach its gap allows.
    pub impact_iterations: u32,
    /// Most sequential-impulse sweeps of the velocity pass per substep (normal and Coulomb
    /// friction at every point that pushed); it stops earlier once no point's velocity
    /// changes by more than 0.1 mm/s.
    pub velocity_iterations: u32,
    /// Fastest approach, m/s, of the other points of a partner's manifold once one of its
    /// points touches within a substep (a tilted face lands as a face, not corner first).
    /// The static environment holds no body back: a box's face against it is solved as one
    /// block instead (SPEC.md §5.3).
    pub landing_speed: f32,
    /// Relaxation factor applied to the averaged position correction.
    pub relaxation: f32,
    /// Contact margin in metres: extra distance at which contact points are generated.
    pub margin: f32,
    /// Speed cap in m/s; sets the displacement allowance per step (`max_speed * dt`).
    pub max_speed: f32,
    /// Angular speed cap in rad/s of a body whose bounding radius is at least
    /// `max_speed / max_angular_speed`; a smaller body may spin as fast as moves its bounding
    /// sphere's surface at `max_speed` ([`SolverParams::spin_cap`]).
    pub max_angular_speed: f32,
    /// Largest separating speed at a contact point that a position correction may leave,
    /// m/s (above restitution's own target). 0 (the default) makes depenetration
    /// energy-free; a positive value may add up to that speed per correction.
    pub max_separation_speed: f32,
    /// Radius of the contact patch assumed for torsional friction, m: at each contact point
    /// with a normal impulse `N`, a spin about the normal is resisted by up to `μ·N·radius`
    /// (SPEC.md §5.3). A point contact alone cannot stop a ball spinning about the vertical
    /// on the ground. 0 turns it off.
    pub patch_radius: f32,
    /// Speed below which a body counts as quiet for sleeping, m/s (linear speed, and angular
    /// speed times the bounding radius).
    pub sleep_speed: f32,
    /// Steps a body and its touching partners must stay quiet before it falls asleep; 0
    /// disables sleeping. At most [`MAX_SLEEP_STEPS`] (a body counts its quiet steps in 16
    /// bits; a larger value counts as that many).
    pub sleep_steps: u32,
}

/// The largest `SolverParams::sleep_steps` that counts (`Body::rest_steps` is 16 bits): 65,535
/// steps, 18 minutes at 60 steps per second.
pub const MAX_SLEEP_STEPS: u32 = u16::MAX as u32;

/// The largest angular speed any body may reach, rad/s, and the largest
/// `solver.max_angular_speed` a scene may set: far above any rigid body's, and far below
/// where one step's rotation update overflows f32 (~1e20 rad/s).
pub const MAX_ANGULAR_SPEED_CAP: f32 = 1e6;

impl SolverParams {
    /// The angular speed cap, rad/s, of a body whose bounding sphere has radius
    /// `bounding_radius`: `max_angular_speed`, or the spin that moves the sphere's surface at
    /// `max_speed` if that is faster (at most [`MAX_ANGULAR_SPEED_CAP`]). A ball may roll as
    /// fast as it may slide: capped at 60 rad/s alone, a 5 cm ball could not roll faster
    /// than 3 m/s, and friction braked one sliding at 5 m/s to 3 m/s instead of 25/7.
    pub fn spin_cap(&self, bounding_radius: f32) -> f32 {
        let rolling = self.max_speed / bounding_radius;
        self.max_angular_speed
            .max(rolling.min(MAX_ANGULAR_SPEED_CAP))
    }

    /// The quiet steps after which a body is asleep, as its 16-bit counter reaches them:
    /// `sleep_steps` capped at [`MAX_SLEEP_STEPS`] (0: sleeping is off).
    pub fn sleep_limit(&self) -> u16 {
        self.sleep_steps.min(MAX_SLEEP_STEPS) as u16
    }

    /// The speed, m/s, below which a body's speeding up does not keep it awake (SPEC.md
    /// §5.4): [`SPEEDING_UP_TOLERANCE`] times half the sleep window, `⌊(sleep_steps − 1)/2⌋`
    /// steps (7 mm/s at the defaults). A body gathering more than the tolerance every step
    /// passes it within half the window, and from then on every step resets its counter, so
    /// from a counter of at most `sleep_steps − ⌊(sleep_steps − 1)/2⌋` it still never falls
    /// asleep (SPEC.md §5.4 states the limit); below it, a speed's rise and fall from step to step is
    /// the solver's noise in a resting pile (three balls of a settled gas traded velocities
    /// of 0.1–1.4 mm/s and stayed awake for good).
    pub fn speeding_up_floor(&self) -> f32 {
        SPEEDING_UP_TOLERANCE * f32::from(self.sleep_limit().saturating_sub(1) / 2)
    }
}

impl Default for SolverParams {
    fn default() -> Self {
        SolverParams {
            substeps: 2,
            sweeps: 2,
            impact_iterations: 8,
            velocity_iterations: 16,
            landing_speed: 0.3,
            relaxation: 1.0,
            margin: 0.02,
            max_speed: 30.0,
            max_angular_speed: 60.0,
            max_separation_speed: 0.0,
            patch_radius: 0.005,
            sleep_speed: 0.05,
            sleep_steps: 30,
        }
    }
}
