//! The rigid-body cell model: bodies, static environment, contact generation and the
//! per-body position-based solver that satisfies the locality contract (SPEC.md §Physics).

mod body;
mod contact;
mod environment;
mod event;
mod frame;
mod free_rotation;
mod friction;
mod initial_depth;
mod lcp;
mod load;
pub mod metrics;
mod model;
mod pair;
mod params;
mod props;
mod rotation;
mod solver;

pub use body::{Body, Material, Shape, LEAVING, SPEEDING_UP_TOLERANCE};
pub use contact::{ContactPoint, ContactSet, SetRole};
pub use environment::{DomainBox, Environment, Plane, StaticCuboid};
pub use event::EventKind;
pub use model::RigidBodyModel;
pub use params::{SolverParams, MAX_ANGULAR_SPEED_CAP, MAX_SLEEP_STEPS};
pub use props::{BodyProps, PropsId};
