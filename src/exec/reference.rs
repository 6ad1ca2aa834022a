//! The reference executor: one thread, no worlds. Each step computes every occupied cell in
//! topological order from the previous step's state, re-bins entities by home cell, then
//! applies the inputs of the new step (SPEC.md §8). A cell whose whole neighbourhood is at
//! rest ([`CellModel::at_rest`]) is not computed: its state is kept as it is, and a step in
//! which no cell changed keeps the previous frame's hash.

use super::contract::{self, CellResult};
use super::error::{ExecError, InputError};
use super::sync::panic_message;
use crate::frame::{Event, Frame};
use crate::grid::Grid;
use crate::kernel::Input;
use crate::model::{BodyId, CellModel, Hint, Neighbourhood, Step};
use crate::state::{CellStates, Derived, Scratch};
use std::collections::{BTreeMap, BTreeSet};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// The single-threaded reference run of a cell model.
pub struct ReferenceRun<M: CellModel> {
    model: M,
    grid: Grid,
    state: CellStates<M::State>,
    step: Step,
    costs: Option<Vec<CellCost>>,
    /// Inputs not yet applied, by step, in the order they were added.
    inputs: BTreeMap<Step, Vec<Input<M::State>>>,
    /// Whether every step is checked against the model contract ([`contract`]).
    check: bool,
    /// An emptied entity vector kept from the previous step (the previous state's or the
    /// one its outputs came in): the next step's states go into it (no new allocation of
    /// a state's size each step).
    spare: Vec<M::State>,
    /// Per cell (linear index): whether every entity of its state is at rest
    /// ([`CellModel::at_rest`]; an empty cell is). Kept for the current state.
    rest: Vec<bool>,
    /// The canonical hash of the current state.
    hash: u64,
    /// Working memory of the binning and the hash, kept from step to step.
    scratch: Scratch,
    /// The model's hints of the current state's entities ([`CellStates::hints`]), or empty:
    /// filled while a step that computed most entities bins the next state (the next step
    /// then likely computes most of them too), else when a step computing most of them
    /// starts. Kept for its capacity.
    hints: Vec<Hint>,
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
    /// [`LeftGrid`](crate::frame::LeftGrid) events in the returned list.
    pub fn new(model: M, grid: Grid, initial: Vec<M::State>) -> (Self, Vec<Event<M::Event>>) {
        let mut events = Vec::new();
        let state = CellStates::binned::<M>(&grid, initial, 0, &mut events);
        let mut scratch = Scratch::default();
        let hash = state.hash_with::<M>(&mut scratch);
        let mut run = ReferenceRun {
            model,
            grid,
            state,
            step: 0,
            costs: None,
            inputs: BTreeMap::new(),
            check: false,
            spare: Vec::new(),
            rest: Vec::new(),
            hash,
            scratch,
            hints: Vec::new(),
        };
        run.rest = (0..run.state.cell_count())
            .map(|i| run.cell_at_rest(i))
            .collect();
        (run, events)
    }

    /// Whether every entity of cell `i` of the current state is at rest.
    fn cell_at_rest(&self, i: usize) -> bool {
        self.state.cell_at(i).iter().all(|s| self.model.at_rest(s))
    }

    /// Recomputes the at-rest flag of the cells `touched` (linear indices) from the current
    /// state (binning recomputes every cell's, [`Derived::rest`]).
    fn update_rest(&mut self, touched: &[usize]) {
        for &i in touched {
            self.rest[i] = self.cell_at_rest(i);
        }
    }

    /// Whether every cell of the 27-neighbourhood of cell `i` is at rest (cells outside the
    /// grid are empty, hence at rest).
    fn neighbourhood_at_rest(&self, i: usize) -> bool {
        let c = self.grid.coord(i);
        (0..27).all(|k| {
            let n = c.offset(Neighbourhood::<M::State>::offset(k));
            !self.grid.contains(n) || self.rest[self.grid.index(n)]
        })
    }

    /// The occupied cells to compute this step, ascending: every occupied cell next to (or
    /// being) a cell that is not at rest. The others step to their own states (the promise
    /// of [`CellModel::at_rest`]).
    fn restless_cells(&self) -> Vec<usize> {
        // Every occupied cell that is not at rest marks itself: when no occupied cell is at
        // rest (a gas), they are all computed.
        if self.state.occupied().all(|i| !self.rest[i]) {
            return self.state.occupied().collect();
        }
        let mut marked: Vec<bool> = Vec::new();
        for (i, _) in self.rest.iter().enumerate().filter(|(_, r)| !**r) {
            if marked.is_empty() {
                marked = vec![false; self.rest.len()];
            }
            let c = self.grid.coord(i);
            for k in 0..27 {
                let n = c.offset(Neighbourhood::<M::State>::offset(k));
                if self.grid.contains(n) {
                    marked[self.grid.index(n)] = true;
                }
            }
        }
        marked
            .iter()
            .enumerate()
            .filter(|&(i, &m)| m && !self.state.cell_at(i).is_empty())
            .map(|(i, _)| i)
            .collect()
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

    /// Turns the contract checker on (or off): from now on every step checks unique ids,
    /// one-cell moves, id-sorted outputs, and computes every cell a second time in a
    /// shuffled order to check that `step_cell` reads nothing but its neighbourhood
    /// (about twice the cost). A violation makes [`try_advance`](Self::try_advance) return
    /// [`ExecError::Contract`]. Turning it on checks the current state's ids at once.
    pub fn check_contract(&mut self, on: bool) -> Result<(), ExecError> {
        self.check = on;
        if on {
            contract::check_unique_ids::<M>(&self.grid, &self.state, self.step)?;
        }
        Ok(())
    }

    /// Schedules an input at step `step` (at least the next step): it applies to the state of
    /// that step once computed, before it is used, with the kernel's rule (SPEC.md §K12):
    /// all removals at a step first (a replacement removes its id), then all additions in the
    /// order they were added.
    pub fn add_input(&mut self, step: Step, input: Input<M::State>) -> Result<(), InputError> {
        super::check_input::<M>(&self.grid, self.step + 1, step, &input)?;
        self.inputs.entry(step).or_default().push(input);
        Ok(())
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
    pub fn frame(&self) -> Frame<M::Event> {
        Frame {
            step: self.step,
            hash: self.hash,
            bodies: self.state.len(),
            events: Vec::new(),
        }
    }

    /// Computes one step and returns its committed frame.
    ///
    /// # Panics
    /// If [`try_advance`](Self::try_advance) fails (the model panicked or broke the
    /// contract), with its message.
    pub fn advance(&mut self) -> Frame<M::Event> {
        self.try_advance().unwrap_or_else(|e| panic!("{e}"))
    }

    /// Computes one step and returns its committed frame; a panic of the model is an
    /// [`ExecError::CellPanicked`] naming the cell and step, a contract violation (when
    /// checked) an [`ExecError::Contract`]. After an error the run stays at its last step.
    pub fn try_advance(&mut self) -> Result<Frame<M::Event>, ExecError> {
        let step = self.step + 1;
        // Every occupied cell is computed when the contract is checked (the checker covers
        // every cell, and checks the promise of `at_rest` on the cells at rest) or when
        // inputs apply (they may edit or remove any entity, wherever it is).
        let whole = self.check || self.inputs.contains_key(&step);
        let cells: Vec<usize> = if whole {
            self.state.occupied().collect()
        } else {
            self.restless_cells()
        };
        let mut next = std::mem::take(&mut self.spare);
        next.reserve(self.state.len());
        // Hints once per entity when most entities are in a computed cell (each is read by
        // every computed neighbourhood that holds it); none when few are (a pile mostly
        // at rest costs nothing per entity at rest). The outputs are the same either way.
        // They are computed while the previous step binned this state when that step
        // computed most entities too (`self.hints` is empty or this state's hints).
        let computed: usize = cells.iter().map(|&i| self.state.cell_at(i).len()).sum();
        let hinted = computed * 2 >= self.state.len();
        if hinted && self.hints.is_empty() {
            self.state.hints(&self.model, &mut self.hints);
        }
        let hints: &[Hint] = if hinted { &self.hints } else { &[] };
        let mut events = Vec::new();
        let mut firsts: Vec<CellResult<M>> = Vec::new();
        // One neighbourhood, moved from cell to cell.
        let mut walk = self.state.walk(&self.grid, hints);
        for &i in &cells {
            let nb = walk.at(i);
            let c = nb.centre;
            let t0 = self.costs.is_some().then(std::time::Instant::now);
            let (start, first_event) = (next.len(), events.len());
            let (model, grid, step) = (&self.model, &self.grid, self.step);
            catch_unwind(AssertUnwindSafe(|| {
                model.step_cell(step, grid, nb, &mut next, &mut events)
            }))
            .map_err(|p| ExecError::CellPanicked {
                step,
                cell: [c.x, c.y, c.z],
                message: panic_message(&*p),
            })?;
            if let (Some(costs), Some(t0)) = (&mut self.costs, t0) {
                costs.push(CellCost {
                    step: self.step,
                    cell: i as u32,
                    seconds: t0.elapsed().as_secs_f64(),
                });
            }
            if self.check {
                contract::check_cell_outputs::<M>(&self.grid, c, self.step, &next[start..])?;
                if self.neighbourhood_at_rest(i) {
                    contract::check_at_rest::<M>(
                        c,
                        self.step,
                        self.state.cell_at(i),
                        &next[start..],
                        &events[first_event..],
                    )?;
                }
                firsts.push(CellResult {
                    cell: i,
                    out: next[start..].to_vec(),
                    events: events[first_event..].to_vec(),
                });
            }
        }
        if self.check {
            let (model, grid, state, step) = (&self.model, &self.grid, &self.state, self.step);
            catch_unwind(AssertUnwindSafe(|| {
                contract::check_pure::<M>(model, grid, state, step, &firsts)
            }))
            .map_err(|p| ExecError::CellPanicked {
                step,
                cell: [0, 0, 0],
                message: format!(
                    "the model panicked when a cell was computed a second time (hidden state?): {}",
                    panic_message(&*p)
                ),
            })??;
        }
        let unchanged = !whole && cells.is_empty();
        if !unchanged && !hinted {
            self.hints.clear();
        }
        if whole {
            if let Some(inputs) = self.inputs.remove(&step) {
                next = apply_inputs::<M>(&self.grid, step, next, &inputs)?;
            }
            let derived = Derived {
                hints: hinted.then_some(&mut self.hints),
                rest: Some(&mut self.rest),
            };
            (self.spare, self.hash) = self.state.rebin_derived(
                &self.grid,
                &self.model,
                next,
                self.step,
                &mut events,
                &mut self.scratch,
                derived,
            );
            if self.check {
                contract::check_unique_ids::<M>(&self.grid, &self.state, step)?;
            }
        } else if !cells.is_empty() {
            // The computed cells are replaced by what lands in them; every other cell keeps
            // its state, which is its own output (the promise of `at_rest`), unless an output
            // of a computed neighbour lands in it.
            // With most cells computed, every cell's flag is recomputed while binning (the
            // same flags, without sorting the touched cells).
            let touched = (cells.len() * 4 < self.rest.len()).then(|| {
                let mut touched = cells.clone();
                touched.extend(
                    next.iter()
                        .filter_map(|s| self.grid.cell_of(M::position(s)))
                        .map(|c| self.grid.index(c)),
                );
                touched.sort_unstable();
                touched.dedup();
                touched
            });
            let derived = Derived {
                hints: hinted.then_some(&mut self.hints),
                rest: touched.is_none().then_some(&mut self.rest),
            };
            (self.spare, self.hash) = self.state.replace_cells(
                &self.grid,
                &self.model,
                &cells,
                next,
                self.step,
                &mut events,
                &mut self.scratch,
                derived,
            );
            if let Some(touched) = &touched {
                self.update_rest(touched);
            }
        }
        // With no cell computed and no input, the state is the previous one, bit for bit,
        // and so is its hash (and its hints).
        events.sort();
        self.step = step;
        Ok(Frame {
            step: self.step,
            hash: self.hash,
            bodies: self.state.len(),
            events,
        })
    }
}

/// The states after the inputs of step `step`: edits first (in input order, each to the
/// state its entity has then), then every removed (or replaced) id goes, then the added
/// states are appended in input order (SPEC.md §8). An edit that moves its entity to
/// another cell is an error.
pub(crate) fn apply_inputs<M: CellModel>(
    grid: &Grid,
    step: Step,
    mut states: Vec<M::State>,
    inputs: &[Input<M::State>],
) -> Result<Vec<M::State>, ExecError> {
    for i in inputs {
        if let Input::Edit(id, edit) = i {
            if let Some(s) = states.iter_mut().find(|s| M::id(s) == *id) {
                let edited = edit.apply(s);
                if grid.cell_of(M::position(&edited)) != grid.cell_of(M::position(s)) {
                    return Err(InputError::EditLeftCell { step, id: *id }.into());
                }
                *s = edited;
            }
        }
    }
    let removed: BTreeSet<BodyId> = inputs
        .iter()
        .filter_map(|i| match i {
            Input::Remove(id) => Some(*id),
            Input::Replace(s) => Some(M::id(s)),
            Input::Spawn(_) | Input::Edit(..) => None,
        })
        .collect();
    if !removed.is_empty() {
        states.retain(|s| !removed.contains(&M::id(s)));
    }
    for i in inputs {
        if let Input::Spawn(s) | Input::Replace(s) = i {
            states.push(s.clone());
        }
    }
    Ok(states)
}
