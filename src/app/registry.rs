//! Models registered with the command line: a name, a one-line description and how to build
//! a model, its grid and its initial states from a size and a seed.

use super::checkpoint::{AppRun, CheckpointPlan};
use crate::checkpoint::{Checkpoint, CheckpointError, ExactState};
use crate::exec::error::ExecError;
use crate::frame::StatesWanted;
use crate::grid::Grid;
use crate::model::{CellModel, Step};
use crate::sim::{ModelReport, RunOptions, Runner};
use crate::verify::{verify_with_progress, RunCheck, VerifyOptions, VerifyReport, VerifySetup};
use anyhow::{bail, Context};

/// The size and seed a registered model is built with (`--entities`, `--seed`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
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
    /// Whether its states can be checkpointed ([`Registry::register_checkpointed`]).
    fn checkpoints(&self) -> bool;
    /// Runs it with `options` to step `last_step`, from step 0 or from the committed states
    /// of `from` (a checkpoint of this model), writing checkpoints as `checkpoints` says.
    /// Returns the report and the step of the last checkpoint written.
    fn run_from(
        &self,
        size: &ModelSize,
        options: &RunOptions,
        from: Option<&Checkpoint<AppRun>>,
        last_step: Step,
        checkpoints: Option<&CheckpointPlan>,
    ) -> anyhow::Result<(ModelReport, Option<Step>)>;
}

/// Makes the checkpoint of a model's committed states (model name, step, states, run).
type WriteStates<S> = fn(&str, Step, &[&S], AppRun) -> Checkpoint<AppRun>;

/// Reads a model's states back from a checkpoint, checked.
type ReadStates<S> = fn(&Checkpoint<AppRun>) -> Result<Vec<S>, CheckpointError>;

/// Turns a model's committed states into a checkpoint and back.
struct Codec<M: CellModel> {
    write: WriteStates<M::State>,
    read: ReadStates<M::State>,
}

fn write_states<M: CellModel>(
    name: &str,
    step: Step,
    states: &[&M::State],
    run: AppRun,
) -> Checkpoint<AppRun>
where
    M::State: ExactState,
{
    Checkpoint::new::<M>(name, step, states, run)
}

fn read_states<M: CellModel>(c: &Checkpoint<AppRun>) -> Result<Vec<M::State>, CheckpointError>
where
    M::State: ExactState,
{
    c.states::<M>()
}

/// A model and the function that builds its scene.
struct Entry<M: CellModel, F> {
    name: String,
    about: String,
    build: F,
    codec: Option<Codec<M>>,
}

impl<M, F> RegisteredModel for Entry<M, F>
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

    fn checkpoints(&self) -> bool {
        self.codec.is_some()
    }

    fn run_from(
        &self,
        size: &ModelSize,
        options: &RunOptions,
        from: Option<&Checkpoint<AppRun>>,
        last_step: Step,
        checkpoints: Option<&CheckpointPlan>,
    ) -> anyhow::Result<(ModelReport, Option<Step>)> {
        let codec = match (&self.codec, from.is_some() || checkpoints.is_some()) {
            (Some(codec), _) => Some(codec),
            (None, false) => None,
            (None, true) => bail!(
                "the model `{}` was registered without checkpoints: implement \
                 soda::checkpoint::ExactState for its state and register it with \
                 Registry::register_checkpointed",
                self.name
            ),
        };
        let (model, grid, mut initial) = (self.build)(size);
        let advice = "the grid is the one the model's builder makes: a smaller cell edge gives \
                      more cells";
        if let Some(warning) = super::worlds_beyond_cells_warning(options, &grid, advice) {
            if prints_here(options) {
                eprintln!("{warning}");
            }
        }
        let mut origin = 0;
        if let (Some(c), Some(codec)) = (from, codec) {
            initial = (codec.read)(c)?;
            origin = c.step;
        }
        if last_step < origin {
            return Err(super::usage(format!(
                "--steps {last_step} is before the checkpoint's step {origin}: give {origin} or more"
            )));
        }
        let wanted = match checkpoints {
            Some(plan) => StatesWanted {
                every: plan.every,
                step: Some(last_step),
                ..StatesWanted::none()
            },
            None => StatesWanted::none(),
        };
        let mut written = None;
        let mut failure: Option<anyhow::Error> = None;
        let report = Runner::new(model, grid, initial)
            .options(options.clone())
            .start_at(origin)
            .states(wanted)
            .run(last_step - origin, |frame, states, control| {
                if super::interrupt::requested() {
                    control.stop();
                }
                let (Some(plan), Some(codec), Some(states)) = (checkpoints, codec, states) else {
                    return;
                };
                if failure.is_some() {
                    return;
                }
                let run = AppRun {
                    size: *size,
                    options: options.clone(),
                    last_step,
                    checkpoint_every: plan.every,
                };
                let checkpoint = (codec.write)(&self.name, frame.step, states, run);
                match plan.write(&checkpoint) {
                    Ok(()) => written = Some(frame.step),
                    Err(e) => failure = Some(e),
                }
            })?;
        if let Some(e) = failure {
            return Err(e).with_context(|| {
                format!(
                    "the run finished with hash {}, but a checkpoint was not written (the last \
                     whole one is at step {})",
                    report.hash,
                    written.map_or("none".into(), |s: Step| s.to_string())
                )
            });
        }
        Ok((report, written))
    }
}

/// Whether this process prints a run's warnings: every process but the ranks other than 0
/// of an MPI run whose session is open.
fn prints_here(options: &RunOptions) -> bool {
    if options.executor != crate::sim::ExecutorKind::Mpi {
        return true;
    }
    #[cfg(feature = "mpi")]
    {
        crate::exec::mpi::Session::open_rank().is_none_or(|rank| rank == 0)
    }
    #[cfg(not(feature = "mpi"))]
    {
        true
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
            codec: None,
        }));
        self
    }

    /// [`register`](Self::register) a model whose states are [`ExactState`], so its runs
    /// can write checkpoints (`run --checkpoint FILE`) and be resumed (`resume FILE`).
    pub fn register_checkpointed<M, F>(mut self, name: &str, about: &str, build: F) -> Self
    where
        M: CellModel + Clone + 'static,
        M::State: ExactState,
        F: Fn(&ModelSize) -> (M, Grid, Vec<M::State>) + Send + Sync + 'static,
    {
        self.models.push(Box::new(Entry {
            name: name.to_string(),
            about: about.to_string(),
            build,
            codec: Some(Codec {
                write: write_states::<M>,
                read: read_states::<M>,
            }),
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
            .register_checkpointed(
                "epidemic",
                "SIR epidemic among flocking agents, with births and deaths (--entities agents, default 2,000)",
                |s: &ModelSize| {
                    let n = s.entities.unwrap_or(2000);
                    let side = ((n as f64 / 8.0).cbrt().ceil() as i32).max(2);
                    Epidemic::default().scene(n, (n / 100).max(1), [side * 2, side, side * 2], s.seed)
                },
            )
            .register_checkpointed(
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
