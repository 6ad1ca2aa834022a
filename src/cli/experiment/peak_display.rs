//! `soda experiment peak-display`: the thesis's peak-resistance question asked with a real
//! consumer. The `peak` scene's burst lands while a display drains committed frames at 24 or
//! 60 frames per second from a bounded buffer that it fills before playing — the display
//! stage of `soda view`, run without a page — and the run is held back when the buffer is
//! full. Per frame rate, buffer size and optimism window: how often the display found the
//! buffer empty during the peak (it starved), and in all.

use super::peak::{profile, PeakWindow};
use super::{cores, f, scene, Row};
use crate::cli::view::frames::EncodedFrame;
use crate::cli::view::playback::Playback;
use anyhow::{bail, Context, Result};
use soda::app::charts;
use soda::app::output::counted;
use soda::frame::StatesWanted;
use soda::kernel::KernelConfig;
use soda::sim::{run_scene_controlled, ExecutorKind, RunOptions};
use std::path::Path;
use std::time::{Duration, Instant};

/// Bytes of an empty frame: the header the display stage fills in (no bodies are drawn).
const EMPTY_FRAME: usize = 64;

pub(super) fn peak_display(quick: bool, svg: &Path) -> Result<Vec<Row>> {
    let (bodies, steps, windows, buffers, rates): (usize, u64, &[u64], &[usize], &[u64]) = if quick
    {
        (200, 150, &[1, 16], &[6, 60], &[24, 60])
    } else {
        (8000, 300, &[1, 4, 16, 64], &[6, 30, 120], &[24, 60])
    };
    let s = scene("peak", bodies, 0)?;
    let threads = cores().max(2);
    let runs = (windows.len() * buffers.len() * rates.len()) as u64;
    let bar = super::super::output::runs_bar(1 + runs);
    bar.set_message("reference: where the peak is");
    let p = profile(&s, steps);
    let w = PeakWindow::find(&p)?;
    bar.inc(1);
    let mut rows = Vec::new();
    let mut series = Vec::new();
    for &fps in rates {
        for &buffer in buffers {
            let mut points = Vec::new();
            for &window in windows {
                bar.set_message(format!("{fps} fps, buffer {buffer}, W {window}"));
                let options = RunOptions {
                    executor: ExecutorKind::Threaded,
                    kernel: KernelConfig::new(threads).window(window),
                    threads,
                    ..RunOptions::default()
                };
                let playback = Playback::new(buffer, fps as f64);
                let clock = playback.clone();
                let display = std::thread::Builder::new()
                    .name("soda-display".into())
                    .spawn(move || clock.run_clock())
                    .context("cannot start the display thread")?;
                let started = Instant::now();
                let report = run_scene_controlled(
                    &s,
                    &options,
                    steps,
                    &StatesWanted::none(),
                    Vec::new(),
                    |frame, _, _| {
                        let mut offered = EncodedFrame {
                            step: frame.step,
                            hash: frame.hash,
                            bytes: vec![0; EMPTY_FRAME],
                        };
                        while let Err(back) = playback.offer(offered) {
                            offered = back;
                        }
                    },
                );
                playback.finish();
                while playback.shown_step() < steps && started.elapsed() < Duration::from_secs(600)
                {
                    std::thread::sleep(Duration::from_millis(5));
                }
                playback.close();
                let _ = display.join();
                let report = report.context("the threaded executor failed")?;
                if report.hash != p.hash {
                    bail!(
                        "threaded run (W {window}) ended in {} but the reference in {}: a \
                         determinism bug; please report it",
                        report.hash,
                        p.hash
                    );
                }
                let starved = playback.starved_steps();
                let in_peak = starved
                    .iter()
                    .filter(|&&t| (w.landing as u64..=w.end as u64 + 1).contains(&t))
                    .count();
                let played = started.elapsed().as_secs_f64();
                let showing = playback.showing_seconds();
                // The display's own rate: below `fps` when the machine could not wake the
                // display thread on time (a loaded machine), which is no starvation.
                let shown_rate = (steps - 1) as f64 / showing.max(1e-9);
                points.push(((window as f64).log2(), in_peak as f64));
                rows.push(Row {
                    bodies,
                    extra: vec![
                        ("display_fps".into(), fps.to_string()),
                        ("buffer_frames".into(), buffer.to_string()),
                        ("peak_landing_step".into(), w.landing.to_string()),
                        ("peak_end_step".into(), w.end.to_string()),
                        ("peak_collision_ratio".into(), f(w.collision_ratio)),
                        ("starved_ticks_in_peak".into(), in_peak.to_string()),
                        ("starved_ticks".into(), starved.len().to_string()),
                        ("display_starved_in_peak".into(), (in_peak > 0).to_string()),
                        ("played_seconds".into(), f(played)),
                        ("display_rate_achieved".into(), f(shown_rate)),
                    ],
                    report,
                });
                bar.inc(1);
            }
            series.push((format!("{fps} fps, buffer {buffer} frames"), points));
        }
    }
    bar.finish_and_clear();
    charts::line_chart(
        svg,
        &format!(
            "Peak with a display: peak {bodies}, {steps} steps, threaded, {} on {}; peak x{:.1} \
             collisions at steps {}-{}",
            counted(threads, "world", "worlds"),
            counted(threads, "thread", "threads"),
            w.collision_ratio,
            w.landing,
            w.end
        ),
        (
            "log2 of the window W",
            "display ticks starved during the peak",
        ),
        &series,
    )?;
    Ok(rows)
}
