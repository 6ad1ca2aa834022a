//! Models registered with the command line: a name, a one-line description and how to build
//! a model, its grid and its initial states from a size and a seed.

use crate::exec::error::ExecError;
use crate::grid::Grid;
use crate::model::CellModel;
use crate::sim::{ModelReport, RunOptions, Runner};
use crate::verify::{verify_with_progress, RunCheck, VerifyOptions, VerifyReport, VerifySetup};

/// The size and seed a registered model is built with (`--entities`, `--seed`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModelSize {
    /// Entities at step 0 (`None`: the model's default).
    pub entities: Option<usize>,
    /// Seed of the initial placement and of the model's randomness.
    pub seed: u64,
}

/// A model the command line can run, whatever its state type.
pub trait RegisteredModel: Send + Sync {
    /// The name `--model` takes.
    fn name(&self) -> &str;
    /// One line about it.
    fn about(&self) -> &str;
    /// Runs it with `options` for `steps` steps (the trace is kept if `options` ask).
    fn run(
        &self,
        size: &ModelSize,
        options: &RunOptions,
        steps: u64,
    ) -> Result<ModelReport, ExecError>;
    /// Verifies it, handing every run's check to `progress`.
    fn verify(
        &self,
        size: &ModelSize,
        options: &VerifyOptions,
        progress: &mut dyn FnMut(&RunCheck),
    ) -> VerifyReport;
}

/// A model and the function that builds its scene.
struct Entry<F> {
    name: String,
    about: String,
    build: F,
}

impl<M, F> RegisteredModel for Entry<F>
where
    M: CellModel + Clone + 'static,
    F: Fn(&ModelSize) -> (M, Grid, Vec<M::State>) + Send + Sync,
{
    fn name(&self) -> &str {
        &self.name
    }

    fn about(&self) -> &str {
        &self.about
    }

    fn run(
        &self,
        size: &ModelSize,
        options: &RunOptions,
        steps: u64,
    ) -> Result<ModelReport, ExecError> {
        let (model, grid, initial) = (self.build)(size);
        Runner::new(model, grid, initial)
            .options(options.clone())
            .run_quiet(steps)
    }

    fn verify(
        &self,
        size: &ModelSize,
        options: &VerifyOptions,
        progress: &mut dyn FnMut(&RunCheck),
    ) -> VerifyReport {
        let (model, grid, initial) = (self.build)(size);
        verify_with_progress(&VerifySetup::new(model, grid, initial), options, progress)
    }
}

/// The models a command line knows, by name.
#[derive(Default)]
pub struct Registry {
    models: Vec<Box<dyn RegisteredModel>>,
}

impl Registry {
    /// No model.
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers a model under `name`: `build` makes the model, its grid and its initial
    /// states from a [`ModelSize`].
    pub fn register<M, F>(mut self, name: &str, about: &str, build: F) -> Self
    where
        M: CellModel + Clone + 'static,
        F: Fn(&ModelSize) -> (M, Grid, Vec<M::State>) + Send + Sync + 'static,
    {
        self.models.push(Box::new(Entry {
            name: name.to_string(),
            about: about.to_string(),
            build,
        }));
        self
    }

    /// The model registered as `name`.
    pub fn get(&self, name: &str) -> Option<&dyn RegisteredModel> {
        self.models
            .iter()
            .find(|m| m.name() == name)
            .map(|m| m.as_ref())
    }

    /// Every registered model, in registration order.
    pub fn models(&self) -> impl Iterator<Item = &dyn RegisteredModel> {
        self.models.iter().map(|m| m.as_ref())
    }

    /// The example models of [`crate::models`]: `epidemic` and `phold`.
    pub fn examples() -> Self {
        use crate::models::epidemic::Epidemic;
        use crate::models::phold::{Phold, PholdParams};
        Registry::new()
            .register(
                "epidemic",
                "SIR epidemic among flocking agents, with births and deaths (--entities agents, default 2,000)",
                |s: &ModelSize| {
                    let n = s.entities.unwrap_or(2000);
                    let side = ((n as f64 / 8.0).cbrt().ceil() as i32).max(2);
                    Epidemic::default().scene(n, (n / 100).max(1), [side * 2, side, side * 2], s.seed)
                },
            )
            .register(
                "phold",
                "PHOLD-like workload: 4 jobs per cell, remote 0.1, grain 64, coupling 0.5 (--entities jobs, default 16,384)",
                |s: &ModelSize| {
                    let n = s.entities.unwrap_or(16_384);
                    let cells = (n / 4).max(1);
                    let side = ((cells as f64 / 4.0).sqrt().ceil() as i32).max(1);
                    Phold::scene(PholdParams {
                        dims: [side, side, 4],
                        per_cell: 4,
                        seed: s.seed,
                        ..PholdParams::default()
                    })
                },
            )
    }
}
