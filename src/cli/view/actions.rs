//! What a page may ask for, and how its acts on bodies become kernel inputs: each is stamped
//! at a step not yet committed (the shown step plus a small lead, or the earliest open step
//! if that is later), validated like an input script entry, posted to the run, and appended
//! to the run's input log, which "save run" writes as an input script so that `soda run
//! --scene S --inputs LOG --steps N` replays the interactive run (SPEC.md §8).

use serde::{Deserialize, Serialize};
use soda::exec::control::RunControl;
use soda::exec::error::InputError;
use soda::model::{BodyId, Step};
use soda::physics::{Body, Material, Shape};
use soda::scene::{BodySpec, InputAction, InputScript, Scene, ScriptedInput};
use std::sync::Mutex;

/// A message a page sends (JSON text; anything else is rejected with a reason).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum PageMessage {
    /// Pause the display.
    Pause,
    /// Resume the display.
    Resume,
    /// Set the playback speed (1 = real time).
    Speed {
        /// The speed, 1/16…16.
        value: f64,
    },
    /// Push a body: change its velocity by `speed` m/s along `direction`.
    Push {
        /// The body.
        id: BodyId,
        /// The direction of the push (normalised by the server).
        direction: [f32; 3],
        /// The velocity change, m/s (0…`solver.max_speed`).
        speed: f32,
    },
    /// Drop a new cube with its centre at `position`.
    Spawn {
        /// Where its centre starts.
        position: [f32; 3],
    },
    /// Remove a body.
    Remove {
        /// The body.
        id: BodyId,
    },
    /// Write the scene and the input log (`PREFIX.scene.json`, `PREFIX.inputs.json`).
    Save,
}

/// An act on the bodies waiting for the run to stamp it.
#[derive(Clone, Debug, PartialEq)]
pub enum Act {
    /// See [`PageMessage::Push`].
    Push {
        /// The body.
        id: BodyId,
        /// The unit direction.
        direction: [f32; 3],
        /// The velocity change, m/s.
        speed: f32,
    },
    /// See [`PageMessage::Spawn`].
    Spawn {
        /// The centre.
        position: [f32; 3],
    },
    /// See [`PageMessage::Remove`].
    Remove {
        /// The body.
        id: BodyId,
    },
}

/// What became of an act: stamped at a step, or refused.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum Outcome {
    /// Posted to the run and logged.
    Stamped {
        /// `push`, `spawn` or `remove`.
        action: String,
        /// The body concerned (the new body's id for a spawn).
        id: BodyId,
        /// The step it applies at.
        step: Step,
        /// Entries in the input log now.
        logged: usize,
    },
    /// Refused (the reason says why and what to do).
    Rejected {
        /// Why.
        reason: String,
    },
}

/// The acts waiting to be stamped and the run's input log.
pub struct InputDesk {
    scene: Scene,
    waiting: Mutex<Vec<Act>>,
    log: Mutex<InputScript>,
    /// The next id a spawned body gets.
    next_id: Mutex<BodyId>,
    /// Steps between the shown step and the step an act is stamped at.
    lead: u64,
}

impl InputDesk {
    /// A desk for `scene`, whose log starts with `script` (the run's `--inputs`, if any).
    pub fn new(scene: Scene, script: InputScript, lead: u64) -> InputDesk {
        let next_id = scene
            .bodies
            .iter()
            .map(|b| b.id)
            .chain(script.inputs.iter().filter_map(|e| e.body.map(|b| b.id)))
            .max()
            .map_or(0, |m| m.saturating_add(1));
        InputDesk {
            scene,
            waiting: Mutex::new(Vec::new()),
            log: Mutex::new(script),
            next_id: Mutex::new(next_id),
            lead,
        }
    }

    /// Queues an act for the run to stamp at its next committed frame.
    pub fn queue(&self, act: Act) {
        self.waiting.lock().expect("input desk").push(act);
    }

    /// A copy of the input log.
    pub fn log(&self) -> InputScript {
        self.log.lock().expect("input log").clone()
    }

    /// Stamps and posts every waiting act; called by the run's frame sink with the committed
    /// bodies of the frame (sorted by id) and the step shown now.
    pub fn post_waiting(
        &self,
        bodies: &[&Body],
        shown: Step,
        control: &mut RunControl<'_, Body>,
    ) -> Vec<Outcome> {
        let acts = std::mem::take(&mut *self.waiting.lock().expect("input desk"));
        acts.into_iter()
            .map(|act| match self.post(act, bodies, shown, control) {
                Ok(o) => o,
                Err(reason) => Outcome::Rejected { reason },
            })
            .collect()
    }

    fn post(
        &self,
        act: Act,
        bodies: &[&Body],
        shown: Step,
        control: &mut RunControl<'_, Body>,
    ) -> Result<Outcome, String> {
        let find = |id: BodyId| {
            bodies
                .binary_search_by_key(&id, |b| b.id())
                .map(|k| bodies[k])
                .map_err(|_| {
                    format!("body {id} is not in the scene any more (removed or left the domain)")
                })
        };
        let mut entry = ScriptedInput {
            step: 0,
            action: InputAction::Push,
            id: None,
            body: None,
            impulse: None,
            angular_impulse: None,
            velocity: None,
            angular_velocity: None,
        };
        let id = match act {
            Act::Push {
                id,
                direction,
                speed,
            } => {
                let body = find(id)?;
                if body.inv_mass() == 0.0 {
                    return Err(format!("body {id} has infinite mass and cannot be pushed"));
                }
                let d = soda::math::Vec3::from(direction);
                let n = d.norm();
                if !n.is_finite() || n == 0.0 || !speed.is_finite() || speed < 0.0 {
                    return Err(format!(
                        "a push needs a non-zero finite direction and a speed of 0 or more, got {direction:?} at {speed} m/s"
                    ));
                }
                let speed = speed.min(self.scene.solver.max_speed);
                let impulse = d / n * (speed / body.inv_mass());
                entry.id = Some(id);
                entry.impulse = Some(impulse.into());
                id
            }
            Act::Remove { id } => {
                find(id)?;
                entry.action = InputAction::Remove;
                entry.id = Some(id);
                id
            }
            Act::Spawn { position } => {
                let id = *self.next_id.lock().expect("next id");
                let half = (0.5f32).min(self.scene.max_radius() / 3f32.sqrt());
                entry.action = InputAction::Spawn;
                entry.body = Some(BodySpec {
                    id,
                    shape: Shape::Cuboid {
                        half_extents: [half; 3],
                    },
                    material: Material::default(),
                    position,
                    rotation: [0.0; 3],
                    velocity: [0.0; 3],
                    angular_velocity: [0.0; 3],
                });
                id
            }
        };
        let mut step = (shown + self.lead).max(control.earliest_input_step());
        let mut log = self.log.lock().expect("input log");
        // The threaded executor's GVT may pass the step between the look and the post: try
        // the earliest open step it names then.
        for _ in 0..8 {
            entry.step = step;
            let mut candidate = log.clone();
            candidate.inputs.push(entry.clone());
            let inputs = candidate
                .to_inputs(&self.scene, "the page", 1)
                .map_err(|e| e.to_string())?;
            let (_, input) = inputs
                .into_iter()
                .rfind(|(s, _)| *s == step)
                .expect("the new entry applies last");
            match control.input(step, input) {
                Ok(()) => {
                    log.inputs.push(entry.clone());
                    if entry.action == InputAction::Spawn {
                        *self.next_id.lock().expect("next id") = id.saturating_add(1);
                    }
                    return Ok(Outcome::Stamped {
                        action: match entry.action {
                            InputAction::Spawn => "spawn",
                            InputAction::Remove => "remove",
                            _ => "push",
                        }
                        .into(),
                        id,
                        step,
                        logged: log.inputs.len(),
                    });
                }
                Err(InputError::TooLate { earliest, .. }) => step = earliest,
                Err(e) => return Err(e.to_string()),
            }
        }
        Err("the run committed past every step tried; try again".into())
    }
}
