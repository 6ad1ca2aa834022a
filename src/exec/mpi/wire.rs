//! The MPI executor's wire format: what ranks send each other, as 64-bit words.
//!
//! Every payload is a list of words that starts with a magic word naming its kind and the
//! format's version and ends with a checksum (word-wise FNV-1a over every word before it).
//! States are the exact words of the model's [`Wire`] (for the built-in models, their
//! [`ExactState`](crate::checkpoint::ExactState) words), so a decoded state has the bits of
//! the sent one. Decoding checks everything it reads — magic, lengths, every header field,
//! every state and event, the checksum and that nothing is left over — and a payload that
//! fails any check is a [`WireError`], never a message with other contents.
//!
//! ```text
//! batch    MAGIC_BATCH  n  message*n  checksum
//! message  step  header  worlds  cell_seq  n_bodies  (cell_len  word*len)*n_bodies
//!          header = kind (1 ghost, 2 migrate) | sign << 2 (0 anti, 1 positive) | follows << 3
//!          worlds = src_world << 32 | dst_world;  cell_seq = src_cell << 32 | seq
//!          cell_len = home cell << 32 | state words
//! frames   MAGIC_FRAMES  first_step  n_steps  (n_states (len word*len)*n_states
//!          n_events (step body kind)*n_events)*n_steps  checksum
//! counters MAGIC_COUNTERS  n_worlds  (world  value*25)*n_worlds  checksum
//! ```

use crate::frame::Event;
use crate::kernel::counters::WorldCounters;
use crate::kernel::message::{Homed, Message, MessageKind, Sign};
use crate::kernel::partition::WorldId;
use crate::model::{Step, Wire};
use std::sync::Arc;
use thiserror::Error;

/// First word of a batch of kernel messages (`SODAMPI`, version 1).
pub const MAGIC_BATCH: u64 = 0x534f_4441_4d50_4901;
/// First word of a rank's committed states and events of a range of steps.
pub const MAGIC_FRAMES: u64 = 0x534f_4441_4d50_4902;
/// First word of a rank's worlds' counters.
pub const MAGIC_COUNTERS: u64 = 0x534f_4441_4d50_4903;

/// Why words received from another rank do not decode.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum WireError {
    /// Too few words for even the magic, a count and the checksum.
    #[error("the payload has {0} words, too few for a header and a checksum")]
    Short(usize),
    /// The first word is not the magic word expected.
    #[error("the payload starts with {found:#018x}, not {expected:#018x} (another kind or version of payload)")]
    BadMagic {
        /// The word found.
        found: u64,
        /// The magic word expected.
        expected: u64,
    },
    /// The checksum does not match the words: damaged in transit, or cut.
    #[error("the payload's checksum is {stored:#018x}, its words hash to {computed:#018x}")]
    Checksum {
        /// The checksum in the payload.
        stored: u64,
        /// The checksum of its words.
        computed: u64,
    },
    /// The words end in the middle of something.
    #[error("the payload ends inside {what} (at word {at} of {len})")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// The word it needed.
        at: usize,
        /// The payload's words before the checksum.
        len: usize,
    },
    /// Words are left after the last item.
    #[error("{0} words are left over after the payload's last item")]
    Trailing(usize),
    /// A message header holds no kind, sign and flag of the format.
    #[error("message {index}: {what} {word:#x} is not valid")]
    BadField {
        /// The message's position in its batch.
        index: usize,
        /// Which field.
        what: &'static str,
        /// Its word.
        word: u64,
    },
    /// A state's words do not decode as a state of the model.
    #[error("a state does not decode: {0}")]
    BadState(String),
    /// An event word is no event kind of the model.
    #[error("event word {0} is no event kind of this model")]
    BadEvent(u64),
    /// An input message (they are never sent between ranks: every rank posts its own).
    #[error("input messages are not sent between ranks")]
    InputOnWire,
}

/// Word-wise FNV-1a over `words` (one multiply per word, so cheap on big payloads).
pub fn checksum(words: &[u64]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &w in words {
        h ^= w;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Appends the checksum of `out` to it.
fn seal(out: &mut Vec<u64>) {
    let c = checksum(out);
    out.push(c);
}

/// Checks magic and checksum; returns a reader over the words between them.
fn open(words: &[u64], magic: u64) -> Result<Reader<'_>, WireError> {
    if words.len() < 3 {
        return Err(WireError::Short(words.len()));
    }
    if words[0] != magic {
        return Err(WireError::BadMagic {
            found: words[0],
            expected: magic,
        });
    }
    let (body, stored) = words.split_at(words.len() - 1);
    let computed = checksum(body);
    if stored[0] != computed {
        return Err(WireError::Checksum {
            stored: stored[0],
            computed,
        });
    }
    Ok(Reader { words: body, at: 1 })
}

/// Reads words in order, every read checked.
struct Reader<'a> {
    words: &'a [u64],
    at: usize,
}

impl<'a> Reader<'a> {
    fn word(&mut self, what: &'static str) -> Result<u64, WireError> {
        let w = self
            .words
            .get(self.at)
            .copied()
            .ok_or(WireError::Truncated {
                what,
                at: self.at,
                len: self.words.len(),
            })?;
        self.at += 1;
        Ok(w)
    }

    fn slice(&mut self, n: u64, what: &'static str) -> Result<&'a [u64], WireError> {
        let end = usize::try_from(n)
            .ok()
            .and_then(|n| self.at.checked_add(n))
            .filter(|&e| e <= self.words.len())
            .ok_or(WireError::Truncated {
                what,
                at: self.words.len(),
                len: self.words.len(),
            })?;
        let s = &self.words[self.at..end];
        self.at = end;
        Ok(s)
    }

    /// A count of items of at least `min_words` words each, checked against what is left.
    fn count(&mut self, what: &'static str, min_words: usize) -> Result<usize, WireError> {
        let n = self.word(what)?;
        let left = (self.words.len() - self.at) as u64;
        if n.saturating_mul(min_words as u64) > left {
            return Err(WireError::Truncated {
                what,
                at: self.words.len(),
                len: self.words.len(),
            });
        }
        Ok(n as usize)
    }

    fn finish(self) -> Result<(), WireError> {
        match self.words.len() - self.at {
            0 => Ok(()),
            n => Err(WireError::Trailing(n)),
        }
    }
}

/// Encodes `msgs` (ghosts, migrations, their anti-messages and null messages) as one batch.
pub fn encode_batch<S, E>(wire: &Wire<S, E>, msgs: &[Message<S>]) -> Result<Vec<u64>, WireError> {
    let mut out = vec![MAGIC_BATCH, msgs.len() as u64];
    for m in msgs {
        let kind = match m.kind {
            MessageKind::Input => return Err(WireError::InputOnWire),
            MessageKind::Ghost => 1u64,
            MessageKind::Migrate => 2,
        };
        debug_assert!(m.removes.is_empty() && m.edits.is_empty());
        let sign = u64::from(m.sign == Sign::Positive);
        out.push(m.step);
        out.push(kind | sign << 2 | u64::from(m.follows) << 3);
        out.push(u64::from(m.src_world) << 32 | u64::from(m.dst_world));
        out.push(u64::from(m.src_cell) << 32 | u64::from(m.seq));
        out.push(m.bodies.len() as u64);
        for b in m.bodies.iter() {
            let at = out.len();
            out.push(0);
            (wire.state_to_words)(&b.state, &mut out);
            let len = (out.len() - at - 1) as u64;
            out[at] = u64::from(b.cell) << 32 | len;
        }
    }
    seal(&mut out);
    Ok(out)
}

/// Decodes a batch [`encode_batch`] wrote.
pub fn decode_batch<S, E>(wire: &Wire<S, E>, words: &[u64]) -> Result<Vec<Message<S>>, WireError> {
    let mut r = open(words, MAGIC_BATCH)?;
    let n = r.count("the message count", 5)?;
    let mut msgs = Vec::with_capacity(n);
    for index in 0..n {
        let step = r.word("a message's step")?;
        let header = r.word("a message's header")?;
        let bad = |what, word| WireError::BadField { index, what, word };
        if header >> 4 != 0 {
            return Err(bad("header", header));
        }
        let kind = match header & 3 {
            1 => MessageKind::Ghost,
            2 => MessageKind::Migrate,
            _ => return Err(bad("kind", header)),
        };
        let sign = if header >> 2 & 1 == 1 {
            Sign::Positive
        } else {
            Sign::Anti
        };
        let follows = header >> 3 & 1 == 1;
        let worlds = r.word("a message's worlds")?;
        let cell_seq = r.word("a message's cell and sequence")?;
        let count = r.count("a message's body count", 1)?;
        if sign == Sign::Anti && count > 0 {
            return Err(bad("anti-message body count", count as u64));
        }
        let mut bodies = Vec::with_capacity(count);
        for _ in 0..count {
            let cell_len = r.word("a body's cell")?;
            let words = r.slice(cell_len & 0xffff_ffff, "a body's state")?;
            let state = (wire.state_from_words)(words).map_err(WireError::BadState)?;
            bodies.push(Homed {
                cell: (cell_len >> 32) as u32,
                state,
            });
        }
        msgs.push(Message {
            step,
            kind,
            sign,
            src_world: (worlds >> 32) as WorldId,
            dst_world: worlds as u32 as WorldId,
            src_cell: (cell_seq >> 32) as u32,
            seq: cell_seq as u32,
            bodies: Arc::new(bodies),
            removes: Vec::new(),
            edits: Vec::new(),
            follows,
            view: None,
        });
    }
    r.finish()?;
    Ok(msgs)
}

/// One step's part of the committed frames a rank sends to rank 0: its worlds' states at the
/// step (any order) and the events raised computing it.
pub struct StepPart<S, E> {
    /// The states.
    pub states: Vec<S>,
    /// The events.
    pub events: Vec<Event<E>>,
}

/// Encodes a rank's committed parts of steps `first, first + 1, …` (one per step).
pub fn encode_frames<'a, S: 'a, E: 'a>(
    wire: &Wire<S, E>,
    first: Step,
    steps: impl ExactSizeIterator<Item = (Vec<&'a S>, Vec<&'a Event<E>>)>,
) -> Vec<u64> {
    let mut out = vec![MAGIC_FRAMES, first, steps.len() as u64];
    for (states, events) in steps {
        out.push(states.len() as u64);
        for s in states {
            let at = out.len();
            out.push(0);
            (wire.state_to_words)(s, &mut out);
            out[at] = (out.len() - at - 1) as u64;
        }
        out.push(events.len() as u64);
        for e in events {
            out.extend([e.step, e.body, (wire.event_to_word)(&e.kind)]);
        }
    }
    seal(&mut out);
    out
}

/// Decodes what [`encode_frames`] wrote: the first step and one part per step.
pub fn decode_frames<S, E>(
    wire: &Wire<S, E>,
    words: &[u64],
) -> Result<(Step, Vec<StepPart<S, E>>), WireError> {
    let mut r = open(words, MAGIC_FRAMES)?;
    let first = r.word("the first step")?;
    let n = r.count("the step count", 2)?;
    let mut parts = Vec::with_capacity(n);
    for _ in 0..n {
        let count = r.count("a state count", 1)?;
        let mut states = Vec::with_capacity(count);
        for _ in 0..count {
            let len = r.word("a state's length")?;
            let words = r.slice(len, "a state")?;
            states.push((wire.state_from_words)(words).map_err(WireError::BadState)?);
        }
        let count = r.count("an event count", 3)?;
        let mut events = Vec::with_capacity(count);
        for _ in 0..count {
            let step = r.word("an event's step")?;
            let body = r.word("an event's entity")?;
            let word = r.word("an event's kind")?;
            let kind = (wire.event_from_word)(word).ok_or(WireError::BadEvent(word))?;
            events.push(Event { step, body, kind });
        }
        parts.push(StepPart { states, events });
    }
    r.finish()?;
    Ok((first, parts))
}

/// The 25 counters of a world, in a fixed order (the order of [`WorldCounters`]' fields).
macro_rules! counter_fields {
    ($m:ident) => {
        $m!(
            steps_computed,
            steps_committed,
            steps_rolled_back,
            cells_computed,
            cells_recomputed,
            cells_committed,
            cells_rolled_back,
            cells_ahead,
            cells_ahead_dropped,
            steps_reexecuted,
            rollbacks_primary,
            rollbacks_secondary,
            rollback_length_primary,
            rollback_length_secondary,
            rollback_length_max,
            stragglers_absorbed,
            messages_sent,
            ghosts_sent,
            migrates_sent,
            null_messages_sent,
            anti_messages_sent,
            messages_received,
            annihilated,
            idle_acts,
            peak_log_bytes
        )
    };
}

/// Words per world in a counters payload: its id and its 25 counters.
const COUNTER_WORDS: usize = 26;

/// Encodes worlds' counters (world id, counters).
pub fn encode_counters<'a>(
    worlds: impl ExactSizeIterator<Item = (WorldId, &'a WorldCounters)>,
) -> Vec<u64> {
    let mut out = vec![MAGIC_COUNTERS, worlds.len() as u64];
    for (id, c) in worlds {
        out.push(u64::from(id));
        macro_rules! push {
            ($($f:ident),*) => { $(out.push(c.$f);)* };
        }
        counter_fields!(push);
    }
    seal(&mut out);
    out
}

/// Decodes what [`encode_counters`] wrote.
pub fn decode_counters(words: &[u64]) -> Result<Vec<(WorldId, WorldCounters)>, WireError> {
    let mut r = open(words, MAGIC_COUNTERS)?;
    let n = r.count("the world count", COUNTER_WORDS)?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let id = r.word("a world id")?;
        let id = WorldId::try_from(id).map_err(|_| WireError::BadField {
            index: out.len(),
            what: "world id",
            word: id,
        })?;
        let mut c = WorldCounters::default();
        macro_rules! read {
            ($($f:ident),*) => { $(c.$f = r.word("a counter")?;)* };
        }
        counter_fields!(read);
        out.push((id, c));
    }
    r.finish()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::CellModel;
    use crate::models::phold::{Job, Phold};

    fn wire() -> Wire<Job, crate::frame::LeftGrid> {
        Phold::wire().expect("phold has a wire")
    }

    fn job(id: u64) -> Job {
        Job {
            id,
            pos: [0.5 + id as f32, -0.0, 1e-30],
            value: id * 7 + 1,
        }
    }

    fn batch() -> Vec<Message<Job>> {
        let positive = Message {
            step: 12,
            kind: MessageKind::Migrate,
            sign: Sign::Positive,
            src_world: 3,
            dst_world: 1,
            src_cell: 77,
            seq: 4,
            bodies: Arc::new(vec![
                Homed {
                    cell: 5,
                    state: job(9),
                },
                Homed {
                    cell: 6,
                    state: job(10),
                },
            ]),
            removes: Vec::new(),
            edits: Vec::new(),
            follows: false,
            view: None,
        };
        let anti = Message {
            kind: MessageKind::Ghost,
            sign: Sign::Anti,
            bodies: Arc::new(Vec::new()),
            follows: true,
            seq: u32::MAX,
            src_cell: u32::MAX - 1,
            ..positive.clone()
        };
        vec![positive, anti]
    }

    #[test]
    fn batches_round_trip_to_the_bit() {
        let msgs = batch();
        let words = encode_batch(&wire(), &msgs).unwrap();
        let back = decode_batch(&wire(), &words).unwrap();
        assert_eq!(back, msgs);
        assert_eq!(
            back[0].bodies[0].state.pos[1].to_bits(),
            (-0.0f32).to_bits()
        );
    }

    #[test]
    fn every_damaged_batch_is_an_error() {
        let words = encode_batch(&wire(), &batch()).unwrap();
        // Every single flipped bit and every cut is refused (the checksum, then the fields).
        for i in 0..words.len() {
            for bit in [0, 17, 63] {
                let mut w = words.clone();
                w[i] ^= 1 << bit;
                assert!(decode_batch(&wire(), &w).is_err(), "word {i} bit {bit}");
            }
            assert!(decode_batch(&wire(), &words[..i]).is_err(), "cut at {i}");
        }
        // A well-sealed batch with a bad field is refused by the field checks.
        let mut w = words[..words.len() - 1].to_vec();
        w[3] = 7; // the first message's header: kind 3
        seal(&mut w);
        assert!(matches!(
            decode_batch(&wire(), &w),
            Err(WireError::BadField { what: "kind", .. })
        ));
        let mut w = words[..words.len() - 1].to_vec();
        w[1] = u64::MAX; // a message count larger than the batch
        seal(&mut w);
        assert!(matches!(
            decode_batch(&wire(), &w),
            Err(WireError::Truncated { .. })
        ));
        assert!(matches!(
            decode_frames(&wire(), &words),
            Err(WireError::BadMagic { .. })
        ));
    }

    #[test]
    fn a_state_that_does_not_decode_is_an_error() {
        let mut msgs = batch();
        msgs.truncate(1);
        let mut words = encode_batch(&wire(), &msgs).unwrap();
        words.pop();
        // The first body's x coordinate: the bits of a NaN.
        words[9] = u64::from(f32::NAN.to_bits());
        seal(&mut words);
        assert!(matches!(
            decode_batch(&wire(), &words),
            Err(WireError::BadState(_))
        ));
    }

    #[test]
    fn inputs_are_never_encoded() {
        let mut msgs = batch();
        msgs[0].kind = MessageKind::Input;
        assert_eq!(encode_batch(&wire(), &msgs), Err(WireError::InputOnWire));
    }

    #[test]
    fn frames_and_counters_round_trip() {
        let states = [job(1), job(2)];
        let event = Event {
            step: 3,
            body: 2,
            kind: crate::frame::LeftGrid,
        };
        let parts = vec![
            (states.iter().collect::<Vec<_>>(), vec![&event]),
            (Vec::new(), Vec::new()),
        ];
        let words = encode_frames(&wire(), 4, parts.into_iter());
        let (first, back) = decode_frames(&wire(), &words).unwrap();
        assert_eq!(first, 4);
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].states, states);
        assert_eq!(back[0].events, vec![event]);
        assert!(back[1].states.is_empty() && back[1].events.is_empty());
        let mut w = words.clone();
        w[6] ^= 1;
        assert!(decode_frames(&wire(), &w).is_err());

        let c = WorldCounters {
            steps_computed: 5,
            peak_log_bytes: 99,
            rollback_length_max: 3,
            ..WorldCounters::default()
        };
        let words = encode_counters([(7, &c)].into_iter());
        assert_eq!(decode_counters(&words).unwrap(), vec![(7, c)]);
    }
}
