//! Settling over many random scenes (issue 23), for `benches/quality.rs`: one scene is a
//! lottery (the energy a settling pile gains, and whether a ball gas is at rest after 10 s,
//! change with every ulp of its history), so these figures are taken over `QUALITY_SEEDS`
//! seeds per kind and engine: the largest rise of mechanical energy (kinetic + potential)
//! above its lowest value so far after 5 s, and the kinetic energy left at 10 s and at the
//! end. Reported per engine as worst, median and counts over the seeds. Its wall times
//! include building every step's state for the measure (both engines alike), so they are
//! not the stepping times of the table above.

use soda::physics::metrics::{kinetic_energy, potential_energy};
use soda::physics::Body;

/// What one run of one seed showed.
#[derive(Clone, Copy, Debug, Default)]
pub struct SettlingRun {
    /// Largest rise of kinetic + potential energy above its lowest value so far, from
    /// `from_step` on, J.
    pub rise: f64,
    /// Kinetic energy after `ten_s_step` steps, J.
    pub kinetic_10s: f64,
    /// Kinetic energy at the end, J.
    pub kinetic_end: f64,
}

/// Follows one run step by step (feed it every step's bodies in order).
#[derive(Debug)]
pub struct SettlingTrack {
    gravity: soda::math::Vec3,
    from_step: u64,
    ten_s_step: u64,
    lowest: f64,
    run: SettlingRun,
}

impl SettlingTrack {
    /// A track for a scene with `gravity`, rises counted from `from_step`, the 10 s mark at
    /// `ten_s_step`.
    pub fn new(gravity: [f32; 3], from_step: u64, ten_s_step: u64) -> Self {
        Self {
            gravity: soda::math::Vec3::new(gravity[0], gravity[1], gravity[2]),
            from_step,
            ten_s_step,
            lowest: f64::INFINITY,
            run: SettlingRun::default(),
        }
    }

    /// The bodies after step `step`.
    pub fn observe(&mut self, step: u64, bodies: &[Body]) {
        let kinetic = kinetic_energy(bodies.iter());
        if step == self.ten_s_step {
            self.run.kinetic_10s = kinetic;
        }
        self.run.kinetic_end = kinetic;
        if step >= self.from_step {
            let energy = kinetic + potential_energy(bodies.iter(), self.gravity);
            self.lowest = self.lowest.min(energy);
            self.run.rise = self.run.rise.max(energy - self.lowest);
        }
    }

    /// What the run showed.
    pub fn finish(&self) -> SettlingRun {
        self.run
    }
}

/// The summary of one kind of scene for one engine over its seeds (the median of an even
/// count is the upper of the two middle values).
pub fn summary(runs: &[SettlingRun]) -> String {
    let mut rises: Vec<f64> = runs.iter().map(|r| r.rise).collect();
    rises.sort_by(f64::total_cmp);
    let median = if rises.is_empty() {
        0.0
    } else {
        rises[rises.len() / 2]
    };
    let worst = rises.last().copied().unwrap_or(0.0);
    let above_5mj = runs.iter().filter(|r| r.rise > 0.005).count();
    let moving_10s = runs.iter().filter(|r| r.kinetic_10s > 1e-4).count();
    let moving_end = runs.iter().filter(|r| r.kinetic_end > 1e-4).count();
    let worst_end = runs.iter().map(|r| r.kinetic_end).fold(0.0, f64::max);
    format!(
        "rise after 5 s: worst {worst:.4} J, median {median:.4} J, {above_5mj} of {n} above 5 mJ; \
         kinetic energy > 0.1 mJ at 10 s in {moving_10s} of {n}, at the end in {moving_end} \
         (worst {worst_end:.2e} J)",
        n = runs.len()
    )
}
