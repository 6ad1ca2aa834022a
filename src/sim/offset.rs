//! A model whose steps are counted from a later origin: the kernel runs steps `0, 1, …`
//! while the model sees `origin, origin + 1, …` (a resumed run continues a run's step
//! numbers, which a model's randomness or events may depend on, without the kernel knowing).

use crate::frame::Event;
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::model::{BodyId, CellModel, Neighbourhood, Step};

/// `inner` with its steps shifted by `origin` ([module docs](self)). Events reach the
/// kernel with local steps; the runner shifts frames and events back.
#[derive(Clone)]
pub(crate) struct Offset<M> {
    pub inner: M,
    pub origin: Step,
}

impl<M: CellModel> CellModel for Offset<M> {
    type State = M::State;
    type Event = M::Event;

    fn id(state: &Self::State) -> BodyId {
        M::id(state)
    }

    fn position(state: &Self::State) -> [f32; 3] {
        M::position(state)
    }

    fn step_cell(
        &self,
        step: Step,
        grid: &Grid,
        nb: &Neighbourhood<'_, Self::State>,
        out: &mut Vec<Self::State>,
        events: &mut Vec<Event<Self::Event>>,
    ) {
        let first = events.len();
        self.inner
            .step_cell(step + self.origin, grid, nb, out, events);
        for e in &mut events[first..] {
            e.step -= self.origin;
        }
    }

    fn may_affect(&self, reader: &Self::State, other: &Self::State) -> bool {
        self.inner.may_affect(reader, other)
    }

    fn hash_state(state: &Self::State, hasher: &mut StateHash) {
        M::hash_state(state, hasher)
    }

    fn same_bits(a: &Self::State, b: &Self::State) -> bool {
        M::same_bits(a, b)
    }

    fn fields(state: &Self::State) -> Vec<(String, String)> {
        M::fields(state)
    }

    fn event_name(kind: &Self::Event) -> String {
        M::event_name(kind)
    }

    fn wire() -> Option<crate::model::Wire<Self::State, Self::Event>> {
        M::wire()
    }
}
