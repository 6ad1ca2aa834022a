//! What a frame sink may do while a run goes on: schedule inputs at steps not yet committed,
//! and stop the run after the current frame.

use super::error::InputError;
use super::live::LiveStatus;
use crate::kernel::Input;
use crate::model::Step;

/// Handed to a frame sink with every committed frame: the sink may schedule inputs (they
/// apply at their step on every executor with the same bits; in the optimistic modes they
/// may arrive after the worlds computed past their step and roll them back) and may stop
/// the run.
pub struct RunControl<'a, S> {
    earliest: Step,
    post: &'a mut dyn FnMut(Step, Input<S>) -> Result<(), InputError>,
    probe: Option<&'a mut dyn FnMut() -> LiveStatus>,
    stop: bool,
}

impl<'a, S> RunControl<'a, S> {
    /// A control whose inputs go to `post`; `earliest` is the earliest step an input may
    /// name at this moment (see [`earliest_input_step`](Self::earliest_input_step)).
    pub(crate) fn new(
        earliest: Step,
        post: &'a mut dyn FnMut(Step, Input<S>) -> Result<(), InputError>,
    ) -> Self {
        RunControl {
            earliest,
            post,
            probe: None,
            stop: false,
        }
    }

    /// The same control, able to show the run's [`LiveStatus`] through `probe` (the Time
    /// Warp executors).
    pub(crate) fn with_probe(mut self, probe: &'a mut dyn FnMut() -> LiveStatus) -> Self {
        self.probe = Some(probe);
        self
    }

    /// The run's progress now: GVT, each world's LVT, territory and rollbacks (`None` on
    /// the reference executor, which has no worlds). Each call looks at every world, so a
    /// display asks at its own rate, not for every frame; looking never changes the run.
    pub fn live_status(&mut self) -> Option<LiveStatus> {
        self.probe.as_mut().map(|p| p())
    }

    /// The earliest step an input could name when this frame was handed over: the step
    /// after the committed one on the reference, GVT on the Time Warp executors (the
    /// threaded executor's GVT may have moved on since; [`input`](Self::input) checks
    /// again). An input stamped a few steps later is accepted on every executor.
    pub fn earliest_input_step(&self) -> Step {
        self.earliest
    }

    /// Schedules `input` at step `step`. Refused if the step is 0 or already committed
    /// (or, in conservative mode, already made known to another world), or if an added
    /// entity lies outside the grid.
    pub fn input(&mut self, step: Step, input: Input<S>) -> Result<(), InputError> {
        (self.post)(step, input)
    }

    /// Schedules `input` at `step`, or at the earliest step still open if that is later,
    /// and returns the step it was stamped at. On the threaded executor GVT may move on
    /// between [`earliest_input_step`](Self::earliest_input_step) and the post: the input is
    /// then posted again at the earliest step the refusal names, up to 8 times. Any other
    /// refusal is returned as it is. Replaying the input as a scripted one at the returned
    /// step gives the run's bits on every executor.
    pub fn input_from(&mut self, step: Step, input: Input<S>) -> Result<Step, InputError>
    where
        S: Clone,
    {
        let mut step = step.max(self.earliest);
        let mut refused = None;
        for _ in 0..8 {
            match self.input(step, input.clone()) {
                Ok(()) => return Ok(step),
                Err(InputError::TooLate { earliest, .. }) => {
                    refused = Some(InputError::TooLate { step, earliest });
                    step = earliest;
                }
                Err(other) => return Err(other),
            }
        }
        Err(refused.expect("eight refusals"))
    }

    /// Stops the run after this frame: no further frame reaches the sink, and the run's
    /// report says where it stopped.
    pub fn stop(&mut self) {
        self.stop = true;
    }

    /// Whether [`stop`](Self::stop) was called.
    pub fn stopped(&self) -> bool {
        self.stop
    }
}
