//! The contract checker: verifies, while a reference run steps, the rules every
//! [`CellModel`] must keep (SPEC.md §4): unique ids, moves of at most one cell per step,
//! outputs sorted by id, and `step_cell` reading nothing but its neighbourhood (every cell is
//! computed a second time, in a shuffled order, and must give the same bits). Each violation
//! is a [`ContractViolation`] naming the rule, the entity, the cell and the step.
//!
//! Turned on with [`ReferenceRun::check_contract`](super::reference::ReferenceRun::check_contract);
//! `verify` always runs it.

use super::error::{ContractRule, ContractViolation};
use crate::frame::Event;
use crate::grid::{CellCoord, Grid};
use crate::model::{CellModel, Step};
use crate::state::CellStates;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn violation(
    rule: ContractRule,
    step: Step,
    cell: CellCoord,
    entity: u64,
    detail: String,
) -> ContractViolation {
    ContractViolation {
        rule,
        step,
        cell: [cell.x, cell.y, cell.z],
        entity,
        detail,
    }
}

/// Checks the outputs `out` of cell `cell` at `step`: strictly ascending ids, and every
/// output homed in the 27-cell neighbourhood of `cell` (or outside the grid: it left).
pub fn check_cell_outputs<M: CellModel>(
    grid: &Grid,
    cell: CellCoord,
    step: Step,
    out: &[M::State],
) -> Result<(), ContractViolation> {
    let mut ids: Vec<u64> = out.iter().map(|s| M::id(s)).collect();
    ids.sort_unstable();
    if let Some(pair) = ids.windows(2).find(|p| p[0] == p[1]) {
        return Err(violation(
            ContractRule::UniqueIds,
            step,
            cell,
            pair[0],
            format!("the cell's output holds id {} twice", pair[0]),
        ));
    }
    if let Some(pair) = out.windows(2).find(|p| M::id(&p[0]) > M::id(&p[1])) {
        let (a, b) = (M::id(&pair[0]), M::id(&pair[1]));
        return Err(violation(
            ContractRule::SortedOutputs,
            step,
            cell,
            b,
            format!("id {b} was appended after id {a}"),
        ));
    }
    for s in out {
        if let Some(home) = grid.cell_of(M::position(s)) {
            if home.chebyshev(cell) > 1 {
                return Err(violation(
                    ContractRule::OneCellMove,
                    step,
                    cell,
                    M::id(s),
                    format!(
                        "its new home cell ({}, {}, {}) is {} cells away",
                        home.x,
                        home.y,
                        home.z,
                        home.chebyshev(cell)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks the promise of [`CellModel::at_rest`] for cell `cell`, whose neighbourhood's
/// entities are all at rest at `step`: its outputs `out` must be its own states `own`, the
/// same bits in the same order, and it must have raised no event (`events`, its events).
pub fn check_at_rest<M: CellModel>(
    cell: CellCoord,
    step: Step,
    own: &[M::State],
    out: &[M::State],
    events: &[Event<M::Event>],
) -> Result<(), ContractViolation> {
    if let Some(e) = events.first() {
        return Err(violation(
            ContractRule::AtRest,
            step,
            cell,
            e.body,
            format!("it raised the event {:?}", e.kind),
        ));
    }
    for k in 0..own.len().max(out.len()) {
        match (own.get(k), out.get(k)) {
            (Some(a), Some(b)) if M::same_bits(a, b) => {}
            (Some(a), Some(b)) => {
                let (fa, fb) = (M::fields(a), M::fields(b));
                let field = fa.iter().zip(&fb).find(|(x, y)| x != y).map_or_else(
                    || "a bit no field shows".to_string(),
                    |(x, y)| format!("{}: {} became {}", x.0, x.1, y.1),
                );
                return Err(violation(
                    ContractRule::AtRest,
                    step,
                    cell,
                    M::id(a),
                    format!("entity {} became entity {} ({field})", M::id(a), M::id(b)),
                ));
            }
            (Some(a), None) => {
                return Err(violation(
                    ContractRule::AtRest,
                    step,
                    cell,
                    M::id(a),
                    format!("entity {} was dropped", M::id(a)),
                ))
            }
            (None, Some(b)) => {
                return Err(violation(
                    ContractRule::AtRest,
                    step,
                    cell,
                    M::id(b),
                    format!("entity {} was added", M::id(b)),
                ))
            }
            (None, None) => unreachable!("k is below one of the lengths"),
        }
    }
    Ok(())
}

/// Checks that no id appears twice in `state` (the whole domain at `step`).
pub fn check_unique_ids<M: CellModel>(
    grid: &Grid,
    state: &CellStates<M::State>,
    step: Step,
) -> Result<(), ContractViolation> {
    let mut ids: Vec<(u64, usize)> = state
        .occupied()
        .flat_map(|i| state.cell_at(i).iter().map(move |s| (M::id(s), i)))
        .collect();
    ids.sort_unstable();
    for pair in ids.windows(2) {
        if pair[0].0 == pair[1].0 {
            let (a, b) = (grid.coord(pair[0].1), grid.coord(pair[1].1));
            return Err(violation(
                ContractRule::UniqueIds,
                step,
                b,
                pair[0].0,
                format!(
                    "id {} is held at step {step} in cells ({}, {}, {}) and ({}, {}, {})",
                    pair[0].0, a.x, a.y, a.z, b.x, b.y, b.z
                ),
            ));
        }
    }
    Ok(())
}

/// One cell's computation in the first pass: its outputs and events.
pub struct CellResult<M: CellModel> {
    /// The cell (linear index).
    pub cell: usize,
    /// Its outputs, in the order `step_cell` appended them.
    pub out: Vec<M::State>,
    /// Its events.
    pub events: Vec<Event<M::Event>>,
}

/// Computes every cell of `first` again from `state`, in an order shuffled by ChaCha8 seeded
/// with `step`, and checks that each gives the same bits as the first time: a model that
/// keeps hidden state between calls, draws unseeded randomness or iterates a hash map seeded
/// per instance shows here.
pub fn check_pure<M: CellModel>(
    model: &M,
    grid: &Grid,
    state: &CellStates<M::State>,
    step: Step,
    first: &[CellResult<M>],
) -> Result<(), ContractViolation> {
    let mut order: Vec<usize> = (0..first.len()).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(step ^ 0x5eed_c0de));
    let (mut out, mut events) = (Vec::new(), Vec::new());
    for k in order {
        let r = &first[k];
        let c = grid.coord(r.cell);
        out.clear();
        events.clear();
        let nb = state.neighbourhood(grid, c);
        model.step_cell(step, grid, &nb, &mut out, &mut events);
        let differs = out.len() != r.out.len()
            || out.iter().zip(&r.out).any(|(a, b)| !M::same_bits(a, b))
            || events != r.events;
        if differs {
            let entity = out
                .iter()
                .zip(&r.out)
                .find(|(a, b)| !M::same_bits(a, b))
                .map_or_else(
                    || nb.own().first().map_or(0, |s| M::id(s)),
                    |(a, _)| M::id(a),
                );
            return Err(violation(
                ContractRule::PureStep,
                step,
                c,
                entity,
                format!(
                    "computing the cell a second time from the same neighbourhood gave {} outputs and {} events, the first time {} and {}{}",
                    out.len(),
                    events.len(),
                    r.out.len(),
                    r.events.len(),
                    if out.len() == r.out.len() { " (different bits)" } else { "" }
                ),
            ));
        }
    }
    Ok(())
}
