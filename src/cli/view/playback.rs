//! The display stage: committed frames flow one way from the run into a bounded buffer, and
//! a display clock takes one frame from it per display tick (the thesis's renderer drawing
//! committed frames at a steady rate while the buffer absorbs the computation's peaks).
//!
//! The run waits when the buffer is full (it is then more than the buffer ahead of what is
//! shown), never because of a page: pages get whatever frame is shown when they are ready
//! for one, so a slow or absent browser only drops display frames.

use super::frames::{fill_display_fields, DisplayFields, EncodedFrame};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// A frame as shown: its step and hash, and the bytes sent to pages.
#[derive(Debug)]
pub struct Shown {
    /// The step shown.
    pub step: u64,
    /// Its state hash.
    pub hash: u64,
    /// The frame's bytes with the display fields filled in.
    pub bytes: Vec<u8>,
}

/// The buffer between the run and the display, and the display's controls.
pub struct Playback {
    queue: Mutex<VecDeque<EncodedFrame>>,
    space: Condvar,
    capacity: usize,
    /// Display frames per second at speed 1.
    fps: f64,
    paused: AtomicBool,
    /// The playback speed's bits (f64).
    speed: AtomicU64,
    starved: AtomicU32,
    /// The step the display was waiting for at each starvation.
    starved_steps: Mutex<Vec<u64>>,
    /// When the first and the latest frame were shown.
    shown_span: Mutex<Option<(Instant, Instant)>>,
    /// Whether the run delivered its last frame.
    finished: AtomicBool,
    /// Whether the viewer is shutting down.
    closing: AtomicBool,
    /// The frame shown now, for the pages.
    shown: watch::Sender<Option<Arc<Shown>>>,
}

impl Playback {
    /// A display of `fps` frames per second at speed 1 with a buffer of `capacity` frames.
    pub fn new(capacity: usize, fps: f64) -> Arc<Playback> {
        Arc::new(Playback {
            queue: Mutex::new(VecDeque::with_capacity(capacity)),
            space: Condvar::new(),
            capacity: capacity.max(1),
            fps,
            paused: AtomicBool::new(false),
            speed: AtomicU64::new(1.0f64.to_bits()),
            starved: AtomicU32::new(0),
            starved_steps: Mutex::new(Vec::new()),
            shown_span: Mutex::new(None),
            finished: AtomicBool::new(false),
            closing: AtomicBool::new(false),
            shown: watch::channel(None).0,
        })
    }

    /// Hands a committed frame to the display if the buffer has room, waiting up to 20 ms
    /// for it; gives the frame back if the buffer stayed full (the caller does what it must
    /// meanwhile and tries again) or the viewer is closing.
    pub fn offer(&self, frame: EncodedFrame) -> Result<(), EncodedFrame> {
        let mut q = self.queue.lock().expect("playback buffer");
        if q.len() >= self.capacity && !self.closing.load(Ordering::SeqCst) {
            q = self
                .space
                .wait_timeout(q, Duration::from_millis(20))
                .expect("playback buffer")
                .0;
        }
        if q.len() >= self.capacity || self.closing.load(Ordering::SeqCst) {
            return Err(frame);
        }
        q.push_back(frame);
        Ok(())
    }

    /// Whether the viewer is closing.
    pub fn closing(&self) -> bool {
        self.closing.load(Ordering::SeqCst)
    }

    /// The step the display was waiting for at each starvation so far (a tick that found
    /// the buffer empty while playing, after the buffer first filled).
    pub fn starved_steps(&self) -> Vec<u64> {
        self.starved_steps.lock().expect("starvations").clone()
    }

    /// Seconds from the first frame shown to the latest (0 before two frames).
    pub fn showing_seconds(&self) -> f64 {
        self.shown_span
            .lock()
            .expect("shown span")
            .map_or(0.0, |(first, last)| (last - first).as_secs_f64())
    }

    /// Frames waiting to be shown.
    pub fn buffered(&self) -> usize {
        self.queue.lock().expect("playback buffer").len()
    }

    /// Pauses or resumes the display (the run goes on until the buffer is full).
    pub fn set_paused(&self, paused: bool) {
        self.paused.store(paused, Ordering::SeqCst);
    }

    /// Sets the playback speed (1 = real time: one step per `dt` of wall time at the
    /// scene's 60 Hz); clamped to 1/16…16.
    pub fn set_speed(&self, speed: f64) {
        self.speed
            .store(speed.clamp(1.0 / 16.0, 16.0).to_bits(), Ordering::SeqCst);
    }

    /// Notes that the run delivered its last frame (an empty buffer is then no starvation).
    pub fn finish(&self) {
        self.finished.store(true, Ordering::SeqCst);
    }

    /// Stops the display clock and releases a run waiting for space.
    pub fn close(&self) {
        self.closing.store(true, Ordering::SeqCst);
        self.space.notify_all();
    }

    /// A receiver of the frame shown now (pages wait on it).
    pub fn subscribe(&self) -> watch::Receiver<Option<Arc<Shown>>> {
        self.shown.subscribe()
    }

    /// The frame shown now.
    pub fn shown(&self) -> Option<Arc<Shown>> {
        self.shown.borrow().clone()
    }

    /// The step shown now (0 before the first frame).
    pub fn shown_step(&self) -> u64 {
        self.shown.borrow().as_ref().map_or(0, |s| s.step)
    }

    /// The display clock: once the buffer is full (or the run over), shows the next
    /// buffered frame every `1 / (fps · speed)` seconds until [`close`](Self::close), like a
    /// video player that prerolls before it plays. Runs on its own thread.
    pub fn run_clock(&self) {
        while !self.closing.load(Ordering::SeqCst)
            && !self.finished.load(Ordering::SeqCst)
            && self.buffered() < self.capacity
        {
            std::thread::sleep(Duration::from_millis(5));
        }
        let started = Instant::now();
        let mut next = Instant::now();
        // Frames shown in the last second, for the measured rate.
        let mut recent: VecDeque<Instant> = VecDeque::new();
        let mut last_shown: Option<Arc<Shown>> = None;
        while !self.closing.load(Ordering::SeqCst) {
            let speed = f64::from_bits(self.speed.load(Ordering::SeqCst));
            let period = Duration::from_secs_f64(1.0 / (self.fps * speed));
            let now = Instant::now();
            if now < next {
                std::thread::sleep((next - now).min(Duration::from_millis(20)));
                continue;
            }
            // Late ticks are not made up for: the display keeps its rate, not a schedule.
            next = if now - next > period {
                now + period
            } else {
                next + period
            };
            let paused = self.paused.load(Ordering::SeqCst);
            let frame = if paused {
                None
            } else {
                let mut q = self.queue.lock().expect("playback buffer");
                let f = q.pop_front();
                self.space.notify_all();
                f
            };
            while recent
                .front()
                .is_some_and(|t| now - *t > Duration::from_secs(1))
            {
                recent.pop_front();
            }
            let fields = |recent: &VecDeque<Instant>, buffered: usize| DisplayFields {
                buffered: buffered as u32,
                starved: self.starved.load(Ordering::SeqCst),
                rate: if now - started < Duration::from_secs(1) {
                    recent.len() as f32 / (now - started).as_secs_f32().max(period.as_secs_f32())
                } else {
                    recent.len() as f32
                },
                speed: speed as f32,
                paused,
            };
            match frame {
                Some(EncodedFrame {
                    step,
                    hash,
                    mut bytes,
                }) => {
                    recent.push_back(now);
                    let mut span = self.shown_span.lock().expect("shown span");
                    *span = Some((span.map_or(now, |s| s.0), now));
                    drop(span);
                    fill_display_fields(&mut bytes, fields(&recent, self.buffered()));
                    let shown = Arc::new(Shown { step, hash, bytes });
                    last_shown = Some(shown.clone());
                    self.shown.send_replace(Some(shown));
                }
                None => {
                    if !paused && !self.finished.load(Ordering::SeqCst) && last_shown.is_some() {
                        self.starved.fetch_add(1, Ordering::SeqCst);
                    }
                    // Refresh the shown frame's display fields a few times a second (paused,
                    // starved or finished), so pages see the buffer fill and the pause.
                    if let Some(prev) = &last_shown {
                        if recent.is_empty() || paused {
                            let mut bytes = prev.bytes.clone();
                            fill_display_fields(&mut bytes, fields(&recent, self.buffered()));
                            let shown = Arc::new(Shown {
                                step: prev.step,
                                hash: prev.hash,
                                bytes,
                            });
                            last_shown = Some(shown.clone());
                            self.shown.send_replace(Some(shown));
                            next = now + Duration::from_millis(250).max(period);
                        }
                    }
                }
            }
        }
    }
}
