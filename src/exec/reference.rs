//! The reference executor: one thread, no worlds. Each step computes every occupied cell in
//! topological order from the previous step's state, then re-bins bodies by home cell.

use crate::frame::{Event, Frame};
use crate::grid::Grid;
use crate::model::{CellModel, Step};
use crate::state::CellStates;

/// The single-threaded reference run of a cell model.
pub struct ReferenceRun<M: CellModel> {
    model: M,
    grid: Grid,
    state: CellStates<M::State>,
    step: Step,
}

impl<M: CellModel> ReferenceRun<M> {
    /// A run starting at step 0 from `initial`. Entities outside the grid are reported as
    /// `LeftDomain` events in the returned list.
    pub fn new(model: M, grid: Grid, initial: Vec<M::State>) -> (Self, Vec<Event>) {
        let mut events = Vec::new();
        let state = CellStates::binned::<M>(&grid, initial, 0, &mut events);
        (
            ReferenceRun {
                model,
                grid,
                state,
                step: 0,
            },
            events,
        )
    }

    /// The current step.
    pub fn step_number(&self) -> Step {
        self.step
    }

    /// The current state.
    pub fn state(&self) -> &CellStates<M::State> {
        &self.state
    }

    /// The grid.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The frame of the current state (no events).
    pub fn frame(&self) -> Frame {
        Frame {
            step: self.step,
            hash: self.state.hash::<M>(),
            bodies: self.state.len(),
            events: Vec::new(),
        }
    }

    /// Computes one step and returns its committed frame.
    pub fn advance(&mut self) -> Frame {
        let mut next = Vec::with_capacity(self.state.len());
        let mut events = Vec::new();
        for i in self.state.occupied() {
            let c = self.grid.coord(i);
            let nb = self.state.neighbourhood(&self.grid, c);
            self.model
                .step_cell(self.step, &self.grid, &nb, &mut next, &mut events);
        }
        self.state = CellStates::binned::<M>(&self.grid, next, self.step, &mut events);
        events.sort();
        self.step += 1;
        Frame {
            step: self.step,
            hash: self.state.hash::<M>(),
            bodies: self.state.len(),
            events,
        }
    }
}
