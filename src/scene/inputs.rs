//! Input scripts (`soda run --inputs FILE`): what happens to a scene's bodies at given
//! steps — spawn a body, remove one, push one, set its velocity — validated like scene files
//! (every error names the entry, the field, the value and what is allowed), and turned into
//! kernel inputs that every executor applies with the same bits (SPEC.md §8, §7).

use super::file::{from_json, from_toml};
use super::show::{number, vector};
use super::validate::{length, over_speed_cap, over_spin_cap, validate_added_body};
use super::{BodySpec, Scene, SceneError, SceneFormat};
use crate::kernel::{Edit, Input};
use crate::math::Vec3;
use crate::model::{BodyId, Step};
use crate::physics::Body;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// How far over a cap a push's speed change may be and still count as the cap: a relative
/// ulp or so (an impulse built in f32 for exactly the cap, as the viewer's pushes are).
const PUSH_CAP_SLACK: f64 = 1.0 + 1e-5;

/// What an input does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InputAction {
    /// Adds `body` (a body as in scene files, with an id not in use).
    Spawn,
    /// Removes the body `id`.
    Remove,
    /// Adds `impulse` (N·s) to the body `id`'s momentum at its centre of mass, and
    /// `angular_impulse` (N·m·s, world frame) to its angular momentum; wakes it.
    Push,
    /// Sets the body `id`'s `velocity` (m/s) and, if given, `angular_velocity` (rad/s);
    /// wakes it.
    SetVelocity,
}

impl InputAction {
    fn name(self) -> &'static str {
        match self {
            InputAction::Spawn => "spawn",
            InputAction::Remove => "remove",
            InputAction::Push => "push",
            InputAction::SetVelocity => "set-velocity",
        }
    }
}

/// One scripted input: at `step`, `action`, with the fields that action takes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedInput {
    /// The step the input applies to (the state of that step, before it is used).
    pub step: Step,
    /// What it does.
    pub action: InputAction,
    /// The body concerned (`remove`, `push`, `set-velocity`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<BodyId>,
    /// The body added (`spawn`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body: Option<BodySpec>,
    /// Linear impulse, N·s (`push`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impulse: Option<[f32; 3]>,
    /// Angular impulse about the centre of mass, N·m·s (`push`, optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_impulse: Option<[f32; 3]>,
    /// New linear velocity, m/s (`set-velocity`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<[f32; 3]>,
    /// New angular velocity, rad/s (`set-velocity`, optional: unchanged if absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_velocity: Option<[f32; 3]>,
}

/// An input script: `[[inputs]]` entries, in any order (applied by step, then in file order).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputScript {
    /// The entries.
    #[serde(default)]
    pub inputs: Vec<ScriptedInput>,
}

/// Parses an input script (TOML or JSON); `origin` names it in messages. Validate it against
/// its scene with [`InputScript::to_inputs`].
pub fn parse_inputs(
    text: &str,
    format: SceneFormat,
    origin: &str,
) -> Result<InputScript, SceneError> {
    match format {
        SceneFormat::Toml => from_toml(text).map_err(|message| SceneError::Parse {
            origin: origin.to_string(),
            message,
        }),
        SceneFormat::Json => from_json(text).map_err(|message| SceneError::Parse {
            origin: origin.to_string(),
            message,
        }),
    }
}

/// The presence of ids along the script, in application order.
struct Presence {
    /// Id → where it came from (`None`: the scene), and the entry that removed it.
    ids: BTreeMap<BodyId, (Option<usize>, Option<usize>)>,
}

impl InputScript {
    /// Validates every entry against `scene` and turns the script into kernel inputs, in the
    /// order they apply (by step, then file order). `first_step` is the earliest step an
    /// input may name (1, or the step after a checkpoint's).
    pub fn to_inputs(
        &self,
        scene: &Scene,
        origin: &str,
        first_step: Step,
    ) -> Result<Vec<(Step, Input<Body>)>, SceneError> {
        let fail = |i: usize, field: &str, value: String, allowed: String| SceneError::Invalid {
            origin: origin.to_string(),
            field: format!("inputs[{i}].{field}"),
            value,
            allowed,
        };
        let mut order: Vec<usize> = (0..self.inputs.len()).collect();
        order.sort_by_key(|&i| self.inputs[i].step);
        let mut presence = Presence {
            ids: scene.bodies.iter().map(|b| (b.id, (None, None))).collect(),
        };
        // The bodies a push or a new spin may name (the scene's and those spawned so far),
        // for the mass and the spin cap.
        let mut specs: BTreeMap<BodyId, &BodySpec> = if self.inputs.iter().any(|e| {
            e.action == InputAction::Push
                || (e.action == InputAction::SetVelocity && e.angular_velocity.is_some())
        }) {
            scene.bodies.iter().map(|b| (b.id, b)).collect()
        } else {
            BTreeMap::new()
        };
        let mut out = Vec::with_capacity(order.len());
        let largest = scene.max_radius();
        // Built at the first spawn, for all of them.
        let mut environment: Option<crate::physics::Environment> = None;
        for i in order {
            let e = &self.inputs[i];
            if e.step < first_step.max(1) {
                return Err(fail(
                    i,
                    "step",
                    e.step.to_string(),
                    if first_step <= 1 {
                        "must be 1 or more: step 0 is the initial state (put the change in the scene)".into()
                    } else {
                        format!("must be {first_step} or more: the steps before are committed")
                    },
                ));
            }
            let allowed_fields: &[&str] = match e.action {
                InputAction::Spawn => &["body"],
                InputAction::Remove => &["id"],
                InputAction::Push => &["id", "impulse", "angular_impulse"],
                InputAction::SetVelocity => &["id", "velocity", "angular_velocity"],
            };
            let given = [
                ("id", e.id.is_some()),
                ("body", e.body.is_some()),
                ("impulse", e.impulse.is_some()),
                ("angular_impulse", e.angular_impulse.is_some()),
                ("velocity", e.velocity.is_some()),
                ("angular_velocity", e.angular_velocity.is_some()),
            ];
            if let Some((field, _)) = given
                .iter()
                .find(|(f, g)| *g && !allowed_fields.contains(f))
            {
                return Err(fail(
                    i,
                    field,
                    "given".into(),
                    format!(
                        "a `{}` input takes {}",
                        e.action.name(),
                        allowed_fields.join(", ")
                    ),
                ));
            }
            let required = |field: &str, present: bool| {
                if present {
                    Ok(())
                } else {
                    Err(fail(
                        i,
                        field,
                        "missing".into(),
                        format!("a `{}` input needs `{field}`", e.action.name()),
                    ))
                }
            };
            let finite = |field: &str, v: [f32; 3]| {
                if v.iter().all(|x| x.is_finite()) {
                    Ok(())
                } else {
                    Err(fail(
                        i,
                        field,
                        vector(v),
                        "every component must be a finite number".into(),
                    ))
                }
            };
            let input = match e.action {
                InputAction::Spawn => {
                    required("body", e.body.is_some())?;
                    let body = e.body.as_ref().expect("checked");
                    validate_added_body(
                        scene,
                        body,
                        origin,
                        &format!("inputs[{i}].body"),
                        largest,
                        environment.get_or_insert_with(|| scene.model().environment),
                    )?;
                    match presence.ids.get(&body.id) {
                        Some((_, Some(j))) if self.inputs[*j].step == e.step => {
                            return Err(fail(
                                i,
                                "step",
                                e.step.to_string(),
                                format!(
                                    "inputs[{j}] removes body {} at the same step, and a removed body is gone only from the next step on (SPEC.md §5.4): spawn it at step {} or later",
                                    body.id,
                                    e.step + 1
                                ),
                            ))
                        }
                        Some((from, None)) => {
                            return Err(fail(
                                i,
                                "body.id",
                                body.id.to_string(),
                                format!(
                                    "must not be in use: {} has that id",
                                    from.map_or("a body of the scene".to_string(), |j| format!(
                                        "the body inputs[{j}] spawns"
                                    ))
                                ),
                            ))
                        }
                        _ => {}
                    }
                    presence.ids.insert(body.id, (Some(i), None));
                    specs.insert(body.id, body);
                    Input::Spawn(body.to_body())
                }
                InputAction::Remove | InputAction::Push | InputAction::SetVelocity => {
                    required("id", e.id.is_some())?;
                    let id = e.id.expect("checked");
                    match presence.ids.get(&id) {
                        None => {
                            return Err(fail(
                                i,
                                "id",
                                id.to_string(),
                                "must be the id of a body of the scene or of one an earlier input spawns".into(),
                            ))
                        }
                        Some((_, Some(j))) => {
                            return Err(fail(
                                i,
                                "id",
                                id.to_string(),
                                format!("the body is gone by then: inputs[{j}] removes it"),
                            ))
                        }
                        Some((Some(j), None)) if self.inputs[*j].step == e.step => {
                            return Err(fail(
                                i,
                                "step",
                                e.step.to_string(),
                                format!(
                                    "inputs[{j}] spawns the body at the same step, and changes apply before additions: name a later step"
                                ),
                            ))
                        }
                        Some(_) => {}
                    }
                    match e.action {
                        InputAction::Remove => {
                            if let Some(p) = presence.ids.get_mut(&id) {
                                p.1 = Some(i);
                            }
                            Input::Edit(id, removal())
                        }
                        InputAction::Push => {
                            required("impulse", e.impulse.is_some())?;
                            let impulse = e.impulse.expect("checked");
                            finite("impulse", impulse)?;
                            let angular = e.angular_impulse.unwrap_or([0.0; 3]);
                            finite("angular_impulse", angular)?;
                            // A push beyond the speed caps is no push the step can take
                            // (and a huge one overflows the rotation to NaN): refused here,
                            // against the body's mass and its least rotational inertia.
                            if let Some(spec) = specs.get(&id) {
                                let b = spec.to_body();
                                let dv = length(impulse) * f64::from(b.inv_mass());
                                if dv > f64::from(scene.solver.max_speed) * PUSH_CAP_SLACK {
                                    return Err(fail(
                                        i,
                                        "impulse",
                                        vector(impulse),
                                        format!(
                                            "would change body {id}'s speed by {dv:.4e} m/s (impulse / mass of {} kg), more than solver.max_speed = {} m/s: give a smaller impulse",
                                            number(1.0 / b.inv_mass()),
                                            number(scene.solver.max_speed)
                                        ),
                                    ));
                                }
                                let most = b.inv_inertia().max();
                                let dw = length(angular) * f64::from(most);
                                let spin_cap = scene.solver.spin_cap(b.bounding_radius());
                                if dw > f64::from(spin_cap) * PUSH_CAP_SLACK {
                                    return Err(fail(
                                        i,
                                        "angular_impulse",
                                        vector(angular),
                                        format!(
                                            "could change body {id}'s spin by up to {dw:.4e} rad/s (about its axis of least inertia, {} kg·m²), more than its spin cap of {} rad/s (the larger of solver.max_angular_speed = {} and solver.max_speed / bounding radius): give a smaller angular impulse",
                                            number(1.0 / most),
                                            number(spin_cap),
                                            number(scene.solver.max_angular_speed)
                                        ),
                                    ));
                                }
                            }
                            Input::Edit(id, push(impulse.into(), angular.into()))
                        }
                        _ => {
                            required("velocity", e.velocity.is_some())?;
                            let velocity = e.velocity.expect("checked");
                            finite("velocity", velocity)?;
                            if let Some(why) = over_speed_cap(velocity, &scene.solver) {
                                return Err(fail(i, "velocity", vector(velocity), why));
                            }
                            if let Some(w) = e.angular_velocity {
                                finite("angular_velocity", w)?;
                                let shape = specs.get(&id).map(|spec| spec.shape);
                                let over =
                                    shape.and_then(|shape| over_spin_cap(w, &shape, &scene.solver));
                                if let Some(why) = over {
                                    return Err(fail(i, "angular_velocity", vector(w), why));
                                }
                            }
                            Input::Edit(
                                id,
                                set_velocity(velocity.into(), e.angular_velocity.map(Vec3::from)),
                            )
                        }
                    }
                }
            };
            out.push((e.step, input));
        }
        Ok(out)
    }
}

/// An edit adding `impulse` at the centre of mass and `angular` about it (world frame); the
/// body wakes (SPEC.md §5.4).
pub fn push(impulse: Vec3, angular: Vec3) -> Edit<Body> {
    Edit::new(move |b: &Body| {
        let mut b = b.clone();
        b.linvel += impulse * b.inv_mass();
        // I⁻¹ L in the world frame: the body-frame inverse inertia, rotated.
        let local = b.rotation.inverse_transform_vector(&angular);
        b.angvel += b
            .rotation
            .transform_vector(&local.component_mul(&b.inv_inertia()));
        b.rest_steps = 0;
        b
    })
}

/// The edit of a `remove` input: the body is marked as leaving ([`Body::mark_leaving`]), so
/// it is in the state of the input's step, touches nothing in the step after it, is gone
/// from the next state, and wakes every body it could touch (SPEC.md §5.4). The kernel's
/// `Input::Remove` takes a body out at once and wakes nothing: a body asleep on it would
/// stay in mid-air.
pub fn removal() -> Edit<Body> {
    Edit::new(|b: &Body| {
        let mut b = b.clone();
        b.mark_leaving();
        b
    })
}

/// An edit setting the velocity (and the angular velocity, if given); the body wakes.
pub fn set_velocity(velocity: Vec3, angular: Option<Vec3>) -> Edit<Body> {
    Edit::new(move |b: &Body| {
        let mut b = b.clone();
        b.linvel = velocity;
        if let Some(w) = angular {
            b.angvel = w;
        }
        b.rest_steps = 0;
        b
    })
}
