//! The rigid-body cell model: bodies, static environment, contact generation and the
//! per-body position-based solver that satisfies the locality contract (SPEC.md §Physics).

mod body;
mod contact;
mod environment;
mod event;
mod frame;
mod friction;
pub mod metrics;
mod model;
mod pair;
mod params;
mod props;
mod solver;

pub use body::{Body, Material, Shape, LEAVING};
pub use contact::{ContactPoint, ContactSet, SetRole};
pub use environment::{DomainBox, Environment, Plane, StaticCuboid};
pub use event::EventKind;
pub use model::RigidBodyModel;
pub use params::{SolverParams, MAX_SLEEP_STEPS};
pub use props::{BodyProps, PropsId};
