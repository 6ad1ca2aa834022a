//! Checkpoint files: the committed states of one step, exact to the bit, with whatever an
//! application needs to continue the run (SPEC.md §Checkpoints).
//!
//! A checkpoint is text in three parts:
//!
//! ```text
//! soda-checkpoint 2                 the format and its version
//! {"model": …, "step": …, …}        one JSON document (a [`Checkpoint`])
//! checksum 0123456789abcdef         FNV-1a 64 of every byte above this line
//! ```
//!
//! States are stored as the exact words of their bits ([`ExactState`]), never as decimal
//! floats, and the document also holds the canonical hash of those states, checked when they
//! are read back: a truncated file lacks its checksum line, an edited one fails the checksum,
//! a file of another model or format says so, and states that decode but are not the ones
//! written fail the hash. [`Runner::start_at`](crate::sim::Runner::start_at) continues a run
//! from the states; writing the text to disk atomically is the application's (the `soda`
//! binary writes a temporary file, syncs it and renames it into place).

use crate::hash::{hex, StateHash};
use crate::model::{CellModel, Step};
use crate::state::{canonical_hash, sorted_by_id};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// The first word of every checkpoint file.
pub const MAGIC: &str = "soda-checkpoint";

/// The format version this build writes and reads.
pub const VERSION: u32 = 2;

/// A model state that can be written as words holding its exact bits and read back
/// identical (the same canonical hash, the same future).
pub trait ExactState: Sized {
    /// Appends the state's words (f32 fields as their `to_bits`, integers as they are).
    fn to_words(&self, out: &mut Vec<u64>);
    /// Reads a state back from the words [`to_words`](Self::to_words) wrote; an error names
    /// what is wrong with them.
    fn from_words(words: &[u64]) -> Result<Self, StateDecodeError>;
}

/// The [`Wire`](crate::model::Wire) of a model whose states are [`ExactState`]: states as
/// their exact words, event kinds as `event_to_word` and `event_from_word` say
/// ([`CellModel::wire`]).
pub fn exact_wire<S: ExactState, E>(
    event_to_word: fn(&E) -> u64,
    event_from_word: fn(u64) -> Option<E>,
) -> crate::model::Wire<S, E> {
    crate::model::Wire {
        state_to_words: S::to_words,
        state_from_words: |w| S::from_words(w).map_err(|e| e.to_string()),
        event_to_word,
        event_from_word,
    }
}

/// Why words do not decode as a state ([`ExactState::from_words`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StateDecodeError {
    /// A state of this kind has another number of words.
    #[error("{what} has {expected} words, this one {found}")]
    WordCount {
        /// The kind of state, with its article (`a body`).
        what: &'static str,
        /// The words a state of this kind has.
        expected: usize,
        /// The words found.
        found: usize,
    },
    /// A word holding a 32-bit field has higher bits set.
    #[error("word {0} is not 32 bits")]
    Not32Bits(usize),
    /// A word holding a float holds a NaN or an infinity.
    #[error("word {0} is not a finite number")]
    NotFinite(usize),
    /// A field's value is none of those it can take (the message says which).
    #[error("{0}")]
    BadValue(String),
}

/// One checkpoint: the committed states of `step` and the application's description `R` of
/// the run to continue.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint<R> {
    /// The model whose states these are (the application's name for it).
    pub model: String,
    /// The committed step the states belong to.
    pub step: Step,
    /// The canonical hash of the states (16 hex digits), checked on reading.
    pub hash: String,
    /// How to continue: scene, options, target step — whatever the application needs.
    pub run: R,
    /// Every state's words, in ascending id order.
    pub states: Vec<Vec<u64>>,
}

/// Why a checkpoint could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CheckpointError {
    /// The first line is not `soda-checkpoint N`.
    #[error("this is not a SODA checkpoint (its first line is not `{MAGIC} <version>`)")]
    NotACheckpoint,
    /// Written by another version of the format.
    #[error(
        "the checkpoint is format version {found}; this soda reads version {VERSION}: resume it \
         with the soda that wrote it"
    )]
    UnsupportedVersion {
        /// The version in the file.
        found: String,
    },
    /// The file ends before its checksum line: cut off while being written or copied.
    #[error("the checkpoint is truncated: it ends before its checksum line")]
    Truncated,
    /// The bytes are not the ones written.
    #[error(
        "the checkpoint is damaged or was edited: its checksum is {stored}, its contents hash to \
         {computed}"
    )]
    ChecksumMismatch {
        /// The checksum in the file.
        stored: String,
        /// The checksum of the contents.
        computed: String,
    },
    /// The JSON document does not parse as a checkpoint of the expected kind.
    #[error("the checkpoint's document is malformed: {0}")]
    Malformed(String),
    /// The checkpoint holds another model's states.
    #[error("the checkpoint holds states of the model `{found}`, not `{expected}`")]
    WrongModel {
        /// The model named in the file.
        found: String,
        /// The model asked for.
        expected: String,
    },
    /// A state's words do not decode.
    #[error("state {index} of the checkpoint does not decode: {reason}")]
    BadState {
        /// Position of the state in the file.
        index: usize,
        /// What is wrong.
        reason: StateDecodeError,
    },
    /// The states are not in strictly ascending id order (a duplicate or reordered entity).
    #[error("the checkpoint's states are not in strictly ascending id order at id {id}")]
    Unordered {
        /// The first id out of order.
        id: u64,
    },
    /// The decoded states do not hash to the hash written with them.
    #[error(
        "the checkpoint's states hash to {computed}, not to the {stored} written with them: they \
         are not the committed states of step {step}"
    )]
    HashMismatch {
        /// The step of the states.
        step: Step,
        /// The hash in the file.
        stored: String,
        /// The hash of the decoded states.
        computed: String,
    },
}

/// The model a checkpoint's text holds, after checking its format, version, completeness and
/// checksum (to pick the model before reading its states).
pub fn model_of(text: &str) -> Result<String, CheckpointError> {
    parse::<serde_json::Value>(text).map(|c| c.model)
}

/// Checks the format line, the checksum line and the checksum, and parses the document.
fn parse<R: DeserializeOwned>(text: &str) -> Result<Checkpoint<R>, CheckpointError> {
    let first = text.lines().next().unwrap_or("");
    let version = match first.split_once(' ') {
        Some((MAGIC, v)) => v,
        _ => return Err(CheckpointError::NotACheckpoint),
    };
    if version != VERSION.to_string() {
        return Err(CheckpointError::UnsupportedVersion {
            found: version.to_string(),
        });
    }
    let body_end = text
        .trim_end_matches('\n')
        .rfind('\n')
        .map(|i| i + 1)
        .ok_or(CheckpointError::Truncated)?;
    let (body, last) = text.split_at(body_end);
    let stored = match last.strip_prefix("checksum ") {
        Some(sum) if last.ends_with('\n') => sum.trim_end().to_string(),
        _ => return Err(CheckpointError::Truncated),
    };
    let computed = checksum(body.as_bytes());
    if stored != computed {
        return Err(CheckpointError::ChecksumMismatch { stored, computed });
    }
    serde_json::from_str(&body[first.len()..])
        .map_err(|e| CheckpointError::Malformed(e.to_string()))
}

/// The FNV-1a 64 checksum of `bytes`, 16 hex digits.
fn checksum(bytes: &[u8]) -> String {
    let mut h = StateHash::new();
    h.bytes(bytes);
    hex(h.finish())
}

impl<R: Serialize + DeserializeOwned> Checkpoint<R> {
    /// The checkpoint of `states` (any order) committed at `step` of a run of `M`, named
    /// `model`, to be continued as `run` says.
    pub fn new<M: CellModel>(model: &str, step: Step, states: &[&M::State], run: R) -> Self
    where
        M::State: ExactState,
    {
        let sorted = sorted_by_id::<M>(states.iter().copied());
        let hash = hex(canonical_hash::<M>(sorted.iter().copied()));
        let states = sorted
            .iter()
            .map(|s| {
                let mut words = Vec::new();
                s.to_words(&mut words);
                words
            })
            .collect();
        Checkpoint {
            model: model.to_string(),
            step,
            hash,
            run,
            states,
        }
    }

    /// The file's text: the format line, the document and the checksum line. Fails only if
    /// the application's `R` fails to serialise (a map with non-string keys, say).
    pub fn to_text(&self) -> Result<String, serde_json::Error> {
        let mut text = format!("{MAGIC} {VERSION}\n");
        text += &serde_json::to_string(self)?;
        text.push('\n');
        let sum = checksum(text.as_bytes());
        Ok(text + "checksum " + &sum + "\n")
    }

    /// Reads a checkpoint of the model `model` from a file's text: format, version,
    /// completeness and checksum are checked (the states' hash is checked by
    /// [`states`](Self::states)).
    pub fn from_text(text: &str, model: &str) -> Result<Self, CheckpointError> {
        let checkpoint: Checkpoint<R> = parse(text)?;
        if checkpoint.model != model {
            return Err(CheckpointError::WrongModel {
                found: checkpoint.model,
                expected: model.to_string(),
            });
        }
        Ok(checkpoint)
    }

    /// The states, decoded and checked: strictly ascending ids and the canonical hash
    /// written with them.
    pub fn states<M: CellModel>(&self) -> Result<Vec<M::State>, CheckpointError>
    where
        M::State: ExactState,
    {
        let mut states = Vec::with_capacity(self.states.len());
        for (index, words) in self.states.iter().enumerate() {
            let s = M::State::from_words(words)
                .map_err(|reason| CheckpointError::BadState { index, reason })?;
            if let Some(prev) = states.last() {
                if M::id(&s) <= M::id(prev) {
                    return Err(CheckpointError::Unordered { id: M::id(&s) });
                }
            }
            states.push(s);
        }
        let computed = hex(canonical_hash::<M>(states.iter()));
        if computed != self.hash {
            return Err(CheckpointError::HashMismatch {
                step: self.step,
                stored: self.hash.clone(),
                computed,
            });
        }
        Ok(states)
    }
}

/// An epidemic agent: 11 words — id, position, velocity, health (0 susceptible, 1 infected,
/// 2 recovered), steps since the last change, the next and end of its id range.
impl ExactState for crate::models::epidemic::Agent {
    fn to_words(&self, out: &mut Vec<u64>) {
        use crate::models::epidemic::Health;
        out.push(self.id);
        out.extend(self.pos.iter().map(|v| u64::from(v.to_bits())));
        out.extend(self.vel.iter().map(|v| u64::from(v.to_bits())));
        out.push(match self.health {
            Health::Susceptible => 0,
            Health::Infected => 1,
            Health::Recovered => 2,
        });
        out.extend([u64::from(self.since), self.next_id, self.end_id]);
    }

    fn from_words(w: &[u64]) -> Result<Self, StateDecodeError> {
        use crate::models::epidemic::Health;
        if w.len() != 11 {
            return Err(StateDecodeError::WordCount {
                what: "an agent",
                expected: 11,
                found: w.len(),
            });
        }
        let f = |k: usize| finite_f32(w, k);
        Ok(crate::models::epidemic::Agent {
            id: w[0],
            pos: [f(1)?, f(2)?, f(3)?],
            vel: [f(4)?, f(5)?, f(6)?],
            health: match w[7] {
                0 => Health::Susceptible,
                1 => Health::Infected,
                2 => Health::Recovered,
                other => {
                    return Err(StateDecodeError::BadValue(format!(
                        "health {other} is not 0, 1 or 2"
                    )))
                }
            },
            since: u32::try_from(w[8]).map_err(|_| StateDecodeError::Not32Bits(8))?,
            next_id: w[9],
            end_id: w[10],
        })
    }
}

/// A PHOLD job: 5 words — id, position, value.
impl ExactState for crate::models::phold::Job {
    fn to_words(&self, out: &mut Vec<u64>) {
        out.push(self.id);
        out.extend(self.pos.iter().map(|v| u64::from(v.to_bits())));
        out.push(self.value);
    }

    fn from_words(w: &[u64]) -> Result<Self, StateDecodeError> {
        if w.len() != 5 {
            return Err(StateDecodeError::WordCount {
                what: "a job",
                expected: 5,
                found: w.len(),
            });
        }
        let f = |k: usize| finite_f32(w, k);
        Ok(crate::models::phold::Job {
            id: w[0],
            pos: [f(1)?, f(2)?, f(3)?],
            value: w[4],
        })
    }
}

/// Word `k` of `w` as the finite f32 whose bits it holds.
fn finite_f32(w: &[u64], k: usize) -> Result<f32, StateDecodeError> {
    let bits = u32::try_from(w[k]).map_err(|_| StateDecodeError::Not32Bits(k))?;
    let v = f32::from_bits(bits);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(StateDecodeError::NotFinite(k))
    }
}

/// The built-in rigid body: 26 words — id, shape (0 ball / 1 cuboid, then radius or half
/// extents), inverse mass and inertia, friction, restitution, position, rotation (w, i, j, k),
/// linear and angular velocity, rest steps, support depth.
impl ExactState for crate::physics::Body {
    fn to_words(&self, out: &mut Vec<u64>) {
        let f = |v: f32| u64::from(v.to_bits());
        out.push(self.id());
        match self.shape() {
            crate::physics::Shape::Ball { radius } => out.extend([0, f(radius), 0, 0]),
            crate::physics::Shape::Cuboid { half_extents: h } => {
                out.extend([1, f(h[0]), f(h[1]), f(h[2])])
            }
        }
        out.push(f(self.inv_mass()));
        out.extend(self.inv_inertia().iter().map(|&v| f(v)));
        out.extend([f(self.friction()), f(self.restitution())]);
        out.extend(self.position.iter().map(|&v| f(v)));
        let q = self.rotation.quaternion();
        out.extend([f(q.w), f(q.i), f(q.j), f(q.k)]);
        out.extend(self.linvel.iter().map(|&v| f(v)));
        out.extend(self.angvel.iter().map(|&v| f(v)));
        out.push(u64::from(self.rest_steps));
        out.push(u64::from(self.support_depth));
    }

    fn from_words(words: &[u64]) -> Result<Self, StateDecodeError> {
        use crate::math::{Quat, Vec3};
        use crate::physics::Shape;
        if words.len() != 26 {
            return Err(StateDecodeError::WordCount {
                what: "a body",
                expected: 26,
                found: words.len(),
            });
        }
        let mut floats = [0f32; 23];
        for (k, &w) in words[2..].iter().take(23).enumerate() {
            let bits = u32::try_from(w).map_err(|_| StateDecodeError::Not32Bits(k + 2))?;
            floats[k] = f32::from_bits(bits);
        }
        if let Some(k) = floats[..22].iter().position(|v| !v.is_finite()) {
            return Err(StateDecodeError::NotFinite(k + 2));
        }
        let v3 = |k: usize| Vec3::new(floats[k], floats[k + 1], floats[k + 2]);
        let shape = match words[1] {
            0 => Shape::Ball { radius: floats[0] },
            1 => Shape::Cuboid {
                half_extents: [floats[0], floats[1], floats[2]],
            },
            other => {
                return Err(StateDecodeError::BadValue(format!(
                    "shape kind {other} is neither 0 (ball) nor 1 (cuboid)"
                )))
            }
        };
        let rest_steps = u16::try_from(words[24]).map_err(|_| {
            StateDecodeError::BadValue("the rest-step count is more than 65535".into())
        })?;
        let support_depth = u16::try_from(words[25]).map_err(|_| {
            StateDecodeError::BadValue("the support depth is more than 65535".into())
        })?;
        let q = nalgebra::Quaternion::new(floats[12], floats[13], floats[14], floats[15]);
        let props =
            crate::physics::BodyProps::from_parts(shape, floats[3], v3(4), floats[7], floats[8]);
        // The bits written were a unit quaternion's: taken as they are, not renormalised.
        let mut body =
            crate::physics::Body::with_props(words[0], props, v3(9), Quat::new_unchecked(q));
        body.linvel = v3(16);
        body.angvel = v3(19);
        body.rest_steps = rest_steps;
        body.support_depth = support_depth;
        Ok(body)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, Vec3};
    use crate::physics::{Body, Material, RigidBodyModel, Shape};
    use proptest::prelude::*;

    fn body(id: u64, ball: bool, f: [f32; 12], rest_steps: u16) -> Body {
        let shape = if ball {
            Shape::Ball {
                radius: f[0].abs() + 0.01,
            }
        } else {
            Shape::Cuboid {
                half_extents: [f[0].abs() + 0.01, f[1].abs() + 0.01, f[2].abs() + 0.01],
            }
        };
        let rotation = Quat::from_euler_angles(f[3], f[4], f[5]);
        let mut b = Body::new(
            id,
            shape,
            Material::default(),
            Vec3::new(f[6], f[7], f[8]),
            rotation,
        );
        b.linvel = Vec3::new(f[9], f[10], f[11]);
        b.angvel = Vec3::new(f[11], f[9], -f[10]);
        b.rest_steps = rest_steps;
        b
    }

    proptest! {
        /// Any body's words read back as the same bits (every field, compared bitwise).
        #[test]
        fn body_words_read_back_bit_identical(
            id in any::<u64>(),
            ball in any::<bool>(),
            f in prop::array::uniform12(-50.0f32..50.0),
            rest_steps in any::<u16>(),
            support_depth in any::<u16>(),
        ) {
            let mut b = body(id, ball, f, rest_steps);
            b.support_depth = support_depth;
            let mut words = Vec::new();
            b.to_words(&mut words);
            let back = Body::from_words(&words).unwrap();
            let mut again = Vec::new();
            back.to_words(&mut again);
            prop_assert_eq!(words, again);
            prop_assert_eq!(back, b);
        }
    }

    #[test]
    fn checkpoint_text_reads_back_with_its_states_and_hash() {
        let bodies: Vec<Body> = (0..20)
            .rev()
            .map(|i| body(i * 7, i % 2 == 0, [0.3 + i as f32 * 0.01; 12], i as u16))
            .collect();
        let refs: Vec<&Body> = bodies.iter().collect();
        let c = Checkpoint::new::<RigidBodyModel>("rigid-bodies", 42, &refs, "run".to_string());
        let text = c.to_text().unwrap();
        let back = Checkpoint::<String>::from_text(&text, "rigid-bodies").unwrap();
        assert_eq!(back.step, 42);
        assert_eq!(back.run, "run");
        let states = back.states::<RigidBodyModel>().unwrap();
        let mut sorted = bodies.clone();
        sorted.sort_by_key(|b| b.id());
        assert_eq!(states, sorted);
        assert_eq!(
            Checkpoint::<String>::from_text(&text, "epidemic").unwrap_err(),
            CheckpointError::WrongModel {
                found: "rigid-bodies".into(),
                expected: "epidemic".into()
            }
        );
    }

    #[test]
    fn words_that_are_not_a_body_are_refused_with_the_reason() {
        let mut words = Vec::new();
        body(1, true, [0.5; 12], 0).to_words(&mut words);
        let reason = |w: &[u64]| Body::from_words(w).unwrap_err().to_string();
        assert!(reason(&words[..24]).contains("26 words"));
        let mut bad_shape = words.clone();
        bad_shape[1] = 7;
        assert!(reason(&bad_shape).contains("shape kind 7"));
        let mut nan = words.clone();
        nan[12] = u64::from(f32::NAN.to_bits());
        assert_eq!(
            Body::from_words(&nan).unwrap_err(),
            StateDecodeError::NotFinite(12)
        );
        let mut wide = words;
        wide[5] = 1 << 40;
        assert!(reason(&wide).contains("word 5"));
    }
}
