//! Targeted properties of one world, on hand-built scenes of the synthetic particle model in a
//! row of six cells: cells 0–2 belong to world 0, cells 3–5 to world 1. World 1 runs ahead
//! with no news from world 0; then world 0's ghost of cell 2 at step 0 arrives as a straggler.

use soda::kernel::synthetic::{Particle, Particles};
use soda::kernel::{
    KernelConfig, Message, MessageKind, Partition, RollbackMode, Sign, World, WorldId,
};
use soda::state::CellStates;
use soda::Grid;
use std::sync::Arc;

fn particle(id: u64, x: f32, vx: f32) -> Particle {
    Particle {
        id,
        pos: [x, 0.5, 0.5],
        vel: [vx, 0.0, 0.0],
    }
}

struct Row {
    model: Arc<Particles>,
    grid: Arc<Grid>,
    part: Arc<Partition>,
    init: CellStates<Particle>,
}

fn row(bodies: Vec<Particle>) -> Row {
    let (model, grid, _) = Particles::scene(0, [6, 1, 1], false, 0);
    let part = Partition::from_owners(&grid, 2, vec![0, 0, 0, 1, 1, 1]);
    let init = CellStates::binned::<Particles>(&grid, bodies, 0, &mut Vec::new());
    Row {
        model: Arc::new(model),
        grid: Arc::new(grid),
        part: Arc::new(part),
        init,
    }
}

impl Row {
    fn world(&self, id: WorldId, mode: RollbackMode) -> World<Particles> {
        let cfg = KernelConfig::new(2).mode(mode).window(64);
        World::new(
            id,
            self.model.clone(),
            self.grid.clone(),
            self.part.clone(),
            &cfg,
            &self.init,
        )
    }

    /// World 1 computed `steps` steps ahead with no ghost from world 0, and the messages it
    /// sent doing so.
    fn world1_ahead(
        &self,
        mode: RollbackMode,
        steps: u64,
    ) -> (World<Particles>, Vec<Message<Particle>>) {
        let mut w1 = self.world(1, mode);
        let mut sent = w1.start();
        w1.set_end(steps);
        for _ in 0..steps {
            sent.extend(w1.act(1));
        }
        assert_eq!(w1.head(), steps);
        (w1, sent)
    }

    /// World 0's ghost of cell 2 at step 0, addressed to world 1.
    fn ghost_of_cell_2(&self) -> Message<Particle> {
        let mut w0 = self.world(0, RollbackMode::Cell);
        let mut msgs: Vec<_> = w0
            .start()
            .into_iter()
            .filter(|m| m.dst_world == 1 && m.kind == MessageKind::Ghost && m.src_cell == 2)
            .collect();
        assert_eq!(msgs.len(), 1);
        msgs.remove(0)
    }

    /// World 0's ghosts of cell 2 at steps 0 and 1, addressed to world 1, after world 0
    /// computed step 0 (alone, its particles keep their states): the ghost of step 0
    /// announces the ghost of step 1 (`follows`, delta ghosts).
    fn ghosts_of_cell_2(&self) -> [Message<Particle>; 2] {
        let mut w0 = self.world(0, RollbackMode::Cell);
        let mut sent = w0.start();
        w0.set_end(1);
        sent.extend(w0.act(1));
        let mut msgs: Vec<_> = sent
            .into_iter()
            .filter(|m| m.dst_world == 1 && m.kind == MessageKind::Ghost && m.src_cell == 2)
            .collect();
        assert_eq!(msgs.len(), 2);
        assert!(msgs[0].step == 0 && msgs[0].follows);
        assert!(msgs[1].step == 1 && !msgs[1].follows);
        let g1 = msgs.pop().unwrap();
        [msgs.pop().unwrap(), g1]
    }
}

/// Cell 2 holds a particle close enough to the one in cell 3 to push it; cell 5 holds an
/// independent particle.
fn pushing_scene() -> Row {
    row(vec![
        particle(0, 2.9, 0.0),
        particle(1, 3.1, 0.0),
        particle(2, 5.5, 0.0),
    ])
}

#[test]
fn straggler_ghost_recomputes_exactly_the_dependent_cells() {
    let r = pushing_scene();
    let (mut w1, _) = r.world1_ahead(RollbackMode::Cell, 4);
    w1.set_recording(true);
    for g in r.ghosts_of_cell_2() {
        w1.receive(g);
    }
    settle(&mut w1);
    // Only cell 3 depends on cell 2's particle (cell 4 is empty, cell 5 is out of reach).
    assert_eq!(
        w1.take_record().recomputations(),
        vec![(0, 3), (1, 3), (2, 3), (3, 3)]
    );
    let c = w1.counters();
    assert_eq!((c.rollbacks_primary, c.rollback_length_primary), (1, 4));
    assert_eq!(w1.lvt(), 4);
}

#[test]
fn a_repair_waits_for_the_ghost_its_straggler_announced() {
    // The ghost of step 0 alone: cell 3 is re-executed at step 0, and its changed state
    // dirties it at step 1, where it reads cell 2's view, which the ghost announced to
    // change. The repair waits there (SPEC.md §K5) instead of running to the head with a
    // view about to change; the announced ghost resumes it, and each cell-step is
    // re-executed once, as when both ghosts arrive together.
    let r = pushing_scene();
    let (mut w1, _) = r.world1_ahead(RollbackMode::Cell, 4);
    w1.set_recording(true);
    let [g0, g1] = r.ghosts_of_cell_2();
    w1.receive(g0);
    settle(&mut w1);
    assert_eq!(w1.take_record().recomputations(), vec![(0, 3)]);
    assert_eq!(w1.lvt(), 1);
    assert!(!w1.wants_to_act(1), "a waiting repair waits for a message");
    w1.receive(g1);
    assert!(w1.wants_to_act(1));
    settle(&mut w1);
    assert_eq!(
        w1.take_record().recomputations(),
        vec![(1, 3), (2, 3), (3, 3)]
    );
    assert_eq!(w1.lvt(), 4);
    // Two stragglers (steps 0 and 1: lengths 4 and 3), each cell-step re-executed once.
    let c = w1.counters();
    assert_eq!((c.rollbacks_primary, c.rollback_length_primary), (2, 7));
    assert_eq!(c.cells_recomputed, 4);
}

#[test]
fn world_mode_recomputes_the_whole_territory() {
    let r = pushing_scene();
    let (mut w1, _) = r.world1_ahead(RollbackMode::World, 4);
    w1.set_recording(true);
    w1.receive(r.ghost_of_cell_2());
    settle(&mut w1);
    let expected: Vec<(u64, u32)> = (0..4).flat_map(|s| [(s, 3), (s, 5)]).collect();
    assert_eq!(w1.take_record().recomputations(), expected);
}

#[test]
fn a_changed_particle_out_of_reach_of_every_neighbour_dirties_nothing() {
    // Cell 2's particle is 1.2 from cell 3's, beyond the model's reach (0.5): no particle of
    // cell 3 may read it (`CellModel::may_affect`), so the straggler is absorbed unrecomputed.
    let r = row(vec![particle(0, 2.2, 0.0), particle(1, 3.4, 0.0)]);
    let (mut w1, _) = r.world1_ahead(RollbackMode::Cell, 4);
    w1.set_recording(true);
    w1.receive(r.ghost_of_cell_2());
    let sent = settle(&mut w1);
    assert_eq!(w1.take_record().recomputations(), vec![]);
    assert!(sent.is_empty(), "nothing changed: {sent:?}");
    let c = w1.counters();
    assert_eq!((c.rollbacks_primary, c.stragglers_absorbed), (0, 1));
}

#[test]
fn early_cutoff_stops_propagation_when_recomputed_states_are_unchanged() {
    // Cell 2's particle is just within reach of cell 3's, which moves at twice the speed
    // cap: the push (~2e-8) rounds away in its velocity and the cap gives the same state,
    // so recomputing cell 3 at step 0 gives the same output and nothing propagates.
    let r = row(vec![particle(0, 2.75, 0.0), particle(1, 3.2499998, 0.6)]);
    let (mut w1, _) = r.world1_ahead(RollbackMode::Cell, 4);
    let before: Vec<Vec<Particle>> = (1..=4)
        .map(|t| w1.cell_state(3, t).unwrap().to_vec())
        .collect();
    w1.set_recording(true);
    let sent = {
        w1.receive(r.ghost_of_cell_2());
        settle(&mut w1)
    };
    assert_eq!(w1.take_record().recomputations(), vec![(0, 3)]);
    assert!(
        sent.is_empty(),
        "nothing changed, nothing is re-sent: {sent:?}"
    );
    let after: Vec<Vec<Particle>> = (1..=4)
        .map(|t| w1.cell_state(3, t).unwrap().to_vec())
        .collect();
    assert_eq!(before, after);
}

/// Lets a world apply its inbox and repair (re-execute) up to its head, or until its repair
/// waits for an announced ghost; the messages sent.
fn settle(w: &mut World<Particles>) -> Vec<Message<Particle>> {
    let mut out = Vec::new();
    while w.wants_to_act(1) {
        out.extend(w.act(1));
    }
    out
}

fn anti_of(m: &Message<Particle>) -> Message<Particle> {
    Message {
        sign: Sign::Anti,
        bodies: Default::default(),
        ..m.clone()
    }
}

fn states_of_cell_3(w: &World<Particles>) -> Vec<Vec<Particle>> {
    (0..=w.head())
        .map(|t| w.cell_state(3, t).unwrap().to_vec())
        .collect()
}

#[test]
fn anti_message_overtaking_its_positive_annihilates() {
    let r = pushing_scene();
    let (control, _) = r.world1_ahead(RollbackMode::Cell, 4);
    let ghost = r.ghost_of_cell_2();

    // The anti-message arrives and is applied first, its positive twin later.
    let (mut w1, _) = r.world1_ahead(RollbackMode::Cell, 4);
    w1.receive(anti_of(&ghost));
    assert!(w1.act(1).is_empty());
    w1.receive(ghost.clone());
    let sent = settle(&mut w1);
    assert!(
        sent.is_empty(),
        "an annihilated pair changes nothing: {sent:?}"
    );
    assert_eq!(states_of_cell_3(&w1), states_of_cell_3(&control));
    assert_eq!(w1.counters().annihilated, 1);
    assert_eq!(w1.counters().rollbacks(), 0);

    // Both in the same batch, in either arrival order.
    for anti_first in [true, false] {
        let (mut w1, _) = r.world1_ahead(RollbackMode::Cell, 4);
        if anti_first {
            w1.receive(anti_of(&ghost));
            w1.receive(ghost.clone());
        } else {
            w1.receive(ghost.clone());
            w1.receive(anti_of(&ghost));
        }
        settle(&mut w1);
        assert_eq!(states_of_cell_3(&w1), states_of_cell_3(&control));
        assert_eq!(w1.counters().rollbacks(), 0);
    }
}

#[test]
fn migration_across_a_border_inside_a_rolled_back_interval_is_cancelled() {
    // Cell 3's particle drifts left and crosses into world 0's cell 2 within five steps —
    // unless cell 2's particle, which world 1 learns about late, pushes it back.
    let r = row(vec![particle(0, 2.9, 0.0), particle(1, 3.02, -0.01)]);
    let (mut w1, sent) = r.world1_ahead(RollbackMode::Cell, 5);
    let migrate: Vec<&Message<Particle>> = sent
        .iter()
        .filter(|m| m.kind == MessageKind::Migrate && m.sign == Sign::Positive)
        .collect();
    assert_eq!(
        migrate.len(),
        1,
        "the speculative crossing migrates: {sent:?}"
    );
    let crossing = migrate[0].clone();
    assert_eq!(crossing.bodies.len(), 1);
    assert_eq!(crossing.bodies[0].cell, 2);
    assert!(w1.cell_state(3, 5).unwrap().is_empty());

    for g in r.ghosts_of_cell_2() {
        w1.receive(g);
    }
    let repair = settle(&mut w1);
    let antis: Vec<&Message<Particle>> = repair
        .iter()
        .filter(|m| m.kind == MessageKind::Migrate)
        .collect();
    assert_eq!(
        antis.len(),
        1,
        "exactly the migration is cancelled: {repair:?}"
    );
    assert_eq!(antis[0].key(), anti_of(&crossing).key());
    for t in 1..=5 {
        let cell = w1.cell_state(3, t).unwrap();
        assert_eq!(cell.len(), 1, "particle 1 stays in cell 3 at step {t}");
        assert_eq!(cell[0].id, 1);
    }
}
