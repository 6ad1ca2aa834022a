//! `soda view`: runs a scene on the chosen executor and shows it live in the browser — the
//! bodies in 3D tinted by the world that owns them, GVT and every world's LVT, rollbacks as
//! flashes on the territories that rolled back — and turns clicks into inputs stamped at
//! steps not yet committed, logged so that the interactive run replays to the same bits.
//!
//! Data flows one way: the run's frame sink encodes each committed frame ([`frames`]) into
//! the bounded buffer of the display stage ([`playback`]); a display clock shows one per
//! tick; the server ([`server`]) sends pages the frame shown. Acts from pages queue at the
//! [`actions::InputDesk`], which the sink stamps and posts at its next frame.

mod actions;
mod assets;
pub(super) mod frames;
pub(super) mod playback;
mod server;

use super::exec_args::{ExecutorArg, ExecutorArgs};
use super::numbers::whole;
use super::source::SceneArgs;
use anyhow::{Context, Result};
use soda::app::plan::OutputPlan;
use soda::frame::StatesWanted;
use soda::scene::{InputScript, SceneFormat};

use soda::sim::{run_scene_controlled, ExecutorKind};
use std::net::{Ipv4Addr, SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Shown after `soda view --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda view                                    falling cubes on the threaded executor, http://127.0.0.1:7878/
  soda view --scene dense-pile --worlds 8 --balance on
  soda view --port 0 --buffer 240              a free port; 4 s of frames ahead of the display

In the page: drag to orbit, wheel to zoom; click a body to push it away from the camera,
shift-click to drop a new cube there, Delete removes the selected body; Space pauses,
+ and - change the speed; \"save run\" writes PREFIX.scene.json and PREFIX.inputs.json and
prints the `soda run` command that replays the run to the step shown, to the same hash.";

/// `soda view` options.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Steps to run; the last frame stays on show until Ctrl-C.
    #[arg(long, value_name = "N", default_value_t = 100_000, value_parser = whole(1, u64::MAX))]
    steps: u64,
    /// An input script to start from (as for `soda run --inputs`); the page's acts are
    /// added to it.
    #[arg(long, value_name = "FILE")]
    inputs: Option<PathBuf>,
    #[command(flatten)]
    executor: ExecutorArgs,
    /// Port on 127.0.0.1 (the server binds to loopback only); 0 picks a free one.
    #[arg(long, value_name = "PORT", default_value_t = 7878)]
    port: u16,
    /// Committed frames the buffer holds ahead of the display: the run waits when it is
    /// this far ahead, and the display starves if the run falls behind for longer.
    #[arg(long, value_name = "FRAMES", default_value_t = 120, value_parser = whole(1, 100_000))]
    buffer: u64,
    /// Display rate at speed 1, frames per second (one step per frame).
    #[arg(long, value_name = "FPS", default_value_t = 60, value_parser = whole(1, 1000))]
    fps: u64,
    /// Steps between the step shown and the step a page's act is stamped at (or the
    /// earliest step still open, if later).
    #[arg(long, value_name = "STEPS", default_value_t = 3, value_parser = whole(1, 1_000_000))]
    input_lead: u64,
    /// Where "save run" writes: PREFIX.scene.json and PREFIX.inputs.json.
    #[arg(long, value_name = "PREFIX", default_value = "soda-view")]
    save: PathBuf,
}

/// Runs `soda view`; `matches` tell whether `--executor` was given (the viewer's default is
/// the threaded executor, whose worlds are the point of the view).
pub fn view(args: &ViewArgs, matches: &clap::ArgMatches) -> Result<()> {
    let mut executor = args.executor.clone();
    if matches.value_source("executor") != Some(clap::parser::ValueSource::CommandLine) {
        executor.executor = ExecutorArg::Threaded;
    }
    let options = executor.options()?;
    let (scene, _origin, _source) = args.scene.load_with_source()?;
    let script = match &args.inputs {
        Some(path) => super::run::read_script(path)?,
        None => InputScript::default(),
    };
    let origin = args
        .inputs
        .as_ref()
        .map_or(String::new(), |p| p.display().to_string());
    let scripted = script
        .to_inputs(&scene, &origin, 1)
        .with_context(|| format!("cannot use the input script `{origin}`"))?;
    let save_to = plan_save(&args.save, args.scene.file(), args.inputs.as_deref())?;
    let scene_file = SceneFormat::Json
        .render(&scene)
        .context("cannot write the scene as a scene file for \"save run\"")?;
    let listener = TcpListener::bind(SocketAddr::from((Ipv4Addr::LOCALHOST, args.port)))
        .with_context(|| {
            format!(
                "--port {}: cannot listen on 127.0.0.1:{} (in use by another program?); give another port, or --port 0 for a free one",
                args.port, args.port
            )
        })?;
    let address = listener.local_addr().context("the listening address")?;

    let grid = scene.grid();
    let playback = playback::Playback::new(args.buffer as usize, args.fps as f64);
    let desk = Arc::new(actions::InputDesk::new(
        scene.clone(),
        script,
        args.input_lead,
    ));
    let (events, _) = tokio::sync::broadcast::channel(256);
    let state = Arc::new(server::ViewerState {
        playback: playback.clone(),
        desk: desk.clone(),
        scene_json: scene_message(&scene, &options, args),
        events: events.clone(),
        save_to,
        scene_file,
    });
    std::thread::Builder::new()
        .name("soda-view-server".into())
        .spawn(move || {
            if let Err(e) = server::serve(listener, state) {
                eprintln!("soda view: the server stopped: {e}");
            }
        })
        .context("cannot start the server thread")?;
    let clock = playback.clone();
    std::thread::Builder::new()
        .name("soda-view-display".into())
        .spawn(move || clock.run_clock())
        .context("cannot start the display thread")?;
    if let Err(e) = soda::app::interrupt::install() {
        eprintln!("warning: Ctrl-C will end the viewer at once: {e}");
    }
    super::output::print_line(format_args!(
        "soda view: http://{address}/  ({}, {} bodies, {} executor{}; Ctrl-C stops)",
        scene.name,
        scene.bodies.len(),
        options.executor.name(),
        if options.executor == ExecutorKind::Reference {
            String::new()
        } else {
            format!(", {} worlds", options.kernel.worlds)
        }
    ))?;

    let committed = AtomicU64::new(0);
    let last_hash = AtomicU64::new(0);
    let mut last_look = Instant::now() - Duration::from_secs(1);
    let mut look = frames::Look::new(None, &grid);
    let stop_asked = || soda::app::interrupt::requested();
    let wanted = StatesWanted {
        every: 1,
        step: None,
        unexpected: None,
    };
    let report = run_scene_controlled(
        &scene,
        &options,
        args.steps,
        &wanted,
        scripted,
        |frame, states, control| {
            let bodies = states.unwrap_or(&[]);
            let post_acts = |control: &mut soda::RunControl<'_, soda::physics::Body>| {
                for outcome in desk.post_waiting(bodies, playback.shown_step(), control) {
                    match &outcome {
                        actions::Outcome::Stamped {
                            action, id, step, ..
                        } => {
                            eprintln!("soda view: input {action} body {id} stamped at step {step}")
                        }
                        actions::Outcome::Rejected { reason } => {
                            eprintln!("soda view: refused a page's act: {reason}")
                        }
                    }
                    let _ = events.send(serde_json::to_string(&outcome).expect("JSON"));
                }
            };
            // The worlds are looked at about as often as the display shows frames.
            if last_look.elapsed() >= Duration::from_millis(15) {
                if let Some(status) = control.live_status() {
                    look = frames::Look::new(Some(status), &grid);
                }
                last_look = Instant::now();
            }
            let mut encoded = frames::encode(frame.step, frame.hash, bodies, &grid, &look);
            committed.store(frame.step, Ordering::SeqCst);
            last_hash.store(frame.hash, Ordering::SeqCst);
            // Wait for room in the buffer; acts that come meanwhile (the display paused, say)
            // are stamped now, not when it resumes.
            loop {
                post_acts(control);
                if stop_asked() || playback.closing() {
                    control.stop();
                    return;
                }
                match playback.offer(encoded) {
                    Ok(()) => break,
                    Err(back) => encoded = back,
                }
            }
        },
    );
    playback.finish();
    let report = report?;
    let step = committed.load(Ordering::SeqCst);
    if !soda::app::interrupt::requested() {
        super::output::print_line(format_args!(
            "soda view: ran {step} steps, hash {}; the last frame stays on show, Ctrl-C stops",
            report.hash
        ))?;
        while !soda::app::interrupt::requested() {
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    playback.close();
    super::output::print_line(format_args!(
        "soda view: stopped; committed up to step {step} (hash {:016x}), showing step {}",
        last_hash.load(Ordering::SeqCst),
        playback.shown_step()
    ))?;
    std::process::exit(i32::from(soda::app::interrupt::exit_status()));
}

/// Checks before the run, with the other commands' output checks, that "save run" can write
/// `PREFIX.scene.json` and `PREFIX.inputs.json` and would overwrite neither the scene file
/// nor the input script given; returns the two paths to write.
fn plan_save(
    prefix: &Path,
    scene: Option<&Path>,
    inputs: Option<&Path>,
) -> Result<(PathBuf, PathBuf)> {
    let mut plan = OutputPlan::new();
    if let Some(scene) = scene {
        plan.input("the scene file", scene);
    }
    if let Some(inputs) = inputs {
        plan.input("the input script", inputs);
    }
    let scene_out = plan.file("--save", &server::with_suffix(prefix, ".scene.json"))?;
    let inputs_out = plan.file("--save", &server::with_suffix(prefix, ".inputs.json"))?;
    Ok((scene_out, inputs_out))
}

/// The scene as the page needs it (sent once per connection).
fn scene_message(
    scene: &soda::scene::Scene,
    options: &soda::sim::RunOptions,
    args: &ViewArgs,
) -> String {
    let grid = scene.grid();
    let env = &scene.environment;
    let cuboids: Vec<serde_json::Value> = env
        .cuboids
        .iter()
        .map(|c| {
            let q =
                soda::math::Quat::from_euler_angles(c.rotation[0], c.rotation[1], c.rotation[2]);
            let q = q.quaternion().coords;
            serde_json::json!({
                "position": c.position,
                "half_extents": c.half_extents,
                "rotation": [q.x, q.y, q.z, q.w],
            })
        })
        .collect();
    serde_json::json!({
        "type": "scene",
        "name": scene.name,
        "bodies": scene.bodies.len(),
        "dt": scene.dt,
        "domain": { "min": scene.domain.min, "max": scene.domain.max },
        "ground": env.ground,
        "walls": env.walls,
        "ceiling": env.ceiling,
        "cuboids": cuboids,
        "grid": { "min": [grid.min.x, grid.min.y, grid.min.z], "edge": grid.edge, "dims": grid.dims },
        "executor": options.executor.name(),
        "worlds": if options.executor == ExecutorKind::Reference { 1 } else { options.kernel.worlds },
        "steps": args.steps,
        "fps": args.fps,
        "buffer": args.buffer,
        "lead": args.input_lead,
    })
    .to_string()
}
