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
    costs: Option<Vec<CellCost>>,
}

/// The measured cost of one cell computation (for the scalability model, `crate::scaling`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellCost {
    /// The step computed.
    pub step: Step,
    /// The cell (linear index).
    pub cell: u32,
    /// Wall time of its `step_cell` call, s.
    pub seconds: f64,
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
                costs: None,
            },
            events,
        )
    }

    /// Starts (or stops) timing every cell computation. Timing only observes: the states are
    /// the same either way.
    pub fn record_costs(&mut self, on: bool) {
        self.costs = on.then(Vec::new);
    }

    /// The cell costs recorded so far, in computation order.
    pub fn take_costs(&mut self) -> Vec<CellCost> {
        self.costs.as_mut().map(std::mem::take).unwrap_or_default()
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
            let t0 = self.costs.is_some().then(std::time::Instant::now);
            self.model
                .step_cell(self.step, &self.grid, &nb, &mut next, &mut events);
            if let (Some(costs), Some(t0)) = (&mut self.costs, t0) {
                costs.push(CellCost {
                    step: self.step,
                    cell: i as u32,
                    seconds: t0.elapsed().as_secs_f64(),
                });
            }
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
