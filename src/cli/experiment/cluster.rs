//! `soda experiment cluster-model`: a **model** of the MPI executor on 16, 64 and 256 ranks of
//! a cluster (`soda::scaling::cluster`, SPEC.md §12), built from what this machine measures:
//! every cell computation's time and every cell's occupancy in reference runs of
//! `falling-cubes` and `sparse-gas` at several sizes, and the time to encode, decode and hash
//! one body. Writes `cluster-model.csv` and `cluster-model.svg` and prints, per network and
//! rank count, the smallest size at which the model's parallel efficiency reaches one half.

use super::super::table::csv_line;
use super::{f, median, scene};
use anyhow::Result;
use soda::app::charts;
use soda::exec::reference::ReferenceRun;
use soda::hash::StateHash;
use soda::kernel::{Partition, PartitionKind};
use soda::scaling::cluster::{predict_cluster, ClusterRun, Network, WireCosts};
use soda::{CellModel, RigidBodyModel};
use std::path::Path;
use std::time::Instant;

/// Steps between GVT rounds: measured on this machine by the MPI executor, 35 rounds over
/// 120 steps of `falling-cubes` 8,000 on 2 ranks (README, "Across processes").
const STEPS_PER_ROUND: f64 = 120.0 / 35.0;

/// Bytes of a batch besides its bodies: the header and checksum words and one message's
/// fields (step, kind, worlds, cell and sequence: SPEC.md §14's batch layout), 8 words.
const BATCH_OVERHEAD_BYTES: f64 = 64.0;

/// The efficiency at which the model says a cluster pays.
const PAYS: f64 = 0.5;

pub(super) fn cluster_model(quick: bool, csv: &Path, svg: &Path) -> Result<()> {
    // (scene, sizes, steps): the benchmark pile, and a gas that fills its domain evenly.
    let plan: [(&str, &[usize], u64); 2] = if quick {
        [
            ("falling-cubes", &[1_000, 8_000], 20),
            ("sparse-gas", &[8_000], 20),
        ]
    } else {
        [
            ("falling-cubes", &[8_000, 27_000, 64_000], 90),
            ("sparse-gas", &[64_000, 250_000, 1_000_000], 30),
        ]
    };
    let ranks = [16usize, 64, 256];
    let networks = [Network::INFINIBAND_HDR100, Network::ETHERNET_10G];
    let mut text = String::from(
        "scene,bodies,steps,ranks,network,latency_seconds,bytes_per_second,commit,sequential_seconds,dataflow_seconds,\
         cluster_seconds,speedup,efficiency,ghost_bytes_per_step,commit_bytes_per_step\n",
    );
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut pays: Vec<(String, usize, Option<usize>)> = Vec::new();
    for (name, sizes, steps) in plan {
        for &bodies in sizes {
            let s = scene(name, bodies, 0)?;
            let grid = s.grid();
            let initial = s.initial_bodies();
            let wire = wire_costs(&initial);
            let (mut run, _) = ReferenceRun::new(s.model(), grid.clone(), initial);
            run.record_costs(true);
            let mut occupancy = Vec::with_capacity(steps as usize);
            for _ in 0..steps {
                let state = run.state();
                occupancy.push(
                    (0..grid.cell_count())
                        .map(|c| state.cell_at(c).len() as u32)
                        .collect(),
                );
                run.advance();
            }
            let costs = run.take_costs();
            let positions: Vec<[f32; 3]> = s.bodies.iter().map(|b| b.position).collect();
            super::super::output::print_line(format_args!(
                "{name} {bodies}: {steps} steps measured; a body on the wire {:.0} B, \
             encode + decode {:.3} us, hash {:.3} us",
                wire.bytes_per_state,
                wire.encode_decode_seconds * 1e6,
                wire.hash_seconds * 1e6
            ))?;
            // One partition per rank count, for every network and commit.
            let parts: Vec<Partition> = ranks
                .iter()
                .map(|&r| Partition::build(&PartitionKind::Blocks, &grid, r, &positions, 0))
                .collect();
            for network in &networks {
                for full in [true, false] {
                    let mut points = Vec::new();
                    for (&r, part) in ranks.iter().zip(&parts) {
                        let m = predict_cluster(
                            &grid,
                            part,
                            &costs,
                            &occupancy,
                            &wire,
                            network,
                            &ClusterRun {
                                steps_per_round: STEPS_PER_ROUND,
                                full_state_commit: full,
                            },
                        );
                        text.push_str(&csv_line([
                            name.to_string(),
                            bodies.to_string(),
                            steps.to_string(),
                            r.to_string(),
                            network.name.to_string(),
                            network.latency_seconds.to_string(),
                            network.bytes_per_second.to_string(),
                            (if full { "full-state" } else { "free" }).to_string(),
                            f(m.sequential_seconds),
                            f(m.dataflow_seconds),
                            f(m.cluster_seconds),
                            f(m.speedup()),
                            f(m.efficiency()),
                            f(m.ghost_bytes / steps as f64),
                            f(m.commit_bytes / steps as f64),
                        ]));
                        points.push((r as f64, m.speedup()));
                        let commit = if full {
                            "full-state commit"
                        } else {
                            "free commit"
                        };
                        let key = format!("{name}, {network}, {commit}");
                        let ok = m.efficiency() >= PAYS;
                        match pays.iter_mut().find(|p| p.0 == key && p.1 == r) {
                            Some(e) => {
                                if ok && e.2.is_none() {
                                    e.2 = Some(bodies);
                                }
                            }
                            None => pays.push((key, r, ok.then_some(bodies))),
                        }
                    }
                    if full {
                        series.push((format!("{name} {bodies}, {network}"), points));
                    }
                }
            }
        }
    }
    soda::app::atomic::write(csv, text.as_bytes())?;
    charts::line_chart(
        svg,
        "MODEL of the MPI executor on a cluster (blocks partition, full-state commit)",
        ("ranks", "speed-up over sequential"),
        &series,
    )?;
    super::super::output::print_line(format_args!(
        "MODEL (not a measurement): where a cluster reaches parallel efficiency {PAYS}"
    ))?;
    for (network, r, size) in pays {
        super::super::output::print_line(format_args!(
            "  {r:>4} ranks, {network}: {}",
            size.map_or("none of the sizes tried".to_string(), |b| format!(
                "from {b} bodies"
            ))
        ))?;
    }
    super::super::output::print_line(format_args!("wrote {}", csv.display()))?;
    super::super::output::print_line(format_args!("wrote {}", svg.display()))?;
    Ok(())
}

/// The wire and hash costs of the scene's bodies, measured here: bytes of a body's words and
/// its home cell, and the time to encode, decode and hash one (the median of 5 passes over
/// the bodies).
fn wire_costs(bodies: &[soda::Body]) -> WireCosts {
    let wire = RigidBodyModel::wire().expect("the rigid-body model has a wire");
    let mut words = Vec::new();
    if let Some(b) = bodies.first() {
        (wire.state_to_words)(b, &mut words);
    }
    let bytes_per_state = 8.0 * (words.len() as f64 + 1.0);
    let n = bodies.len().max(1) as f64;
    let mut coding = Vec::new();
    let mut hashing = Vec::new();
    for _ in 0..5 {
        let started = Instant::now();
        let mut kept = 0usize;
        for b in bodies {
            words.clear();
            (wire.state_to_words)(b, &mut words);
            if (wire.state_from_words)(&words).is_ok() {
                kept += 1;
            }
        }
        assert_eq!(kept, bodies.len(), "every body decodes");
        coding.push(started.elapsed().as_secs_f64() / n);
        let started = Instant::now();
        let mut h = StateHash::new();
        for b in bodies {
            RigidBodyModel::hash_state(b, &mut h);
        }
        std::hint::black_box(h.finish());
        hashing.push(started.elapsed().as_secs_f64() / n);
    }
    WireCosts {
        bytes_per_state,
        encode_decode_seconds: median(coding),
        hash_seconds: median(hashing),
        batch_overhead_bytes: BATCH_OVERHEAD_BYTES,
    }
}
