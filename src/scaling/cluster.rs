//! A **model** of the MPI executor on a cluster (SPEC.md §12, §14): R ranks, one world each,
//! over a network of stated latency and bandwidth, predicted from what one reference run
//! measured on this machine (every cell computation's time and every cell's occupancy per
//! step) and from the measured cost of putting a state on the wire and hashing it.
//!
//! Per step `t` and world `w` (a dataflow schedule, as [`super::predict`], plus messages):
//!
//! - `w` starts step `t` once it has finished `t − 1` and the ghosts of every neighbouring
//!   world's step `t − 1` have arrived; it then computes its cells (their measured times)
//!   and encodes what it sends and decodes what it received (the wire cost per state).
//! - Ghosts: each world sends each neighbouring world one batch per step holding the states
//!   of its cells next to that world's territory; the batch arrives `latency + bytes /
//!   bandwidth` after the step is done.
//! - GVT rounds are synchronous (SPEC.md §14): every `steps_per_round` steps every rank
//!   waits for the slowest, then an all-reduce (`2 · latency · ⌈log₂ R⌉`), then rank 0
//!   gathers every state of the round's steps over its one link and decodes and hashes them
//!   (the full-state commit as implemented) while every rank waits at the next round. This
//!   counts rank 0's own states too, which it reads without the wire (bytes overstated by
//!   `R/(R−1)`), and charges the encoding to rank 0 (SPEC.md §12).
//!
//! Not modelled: rollbacks (the optimistic ideal: every speculation right), the window,
//! load imbalance beyond the measured cell costs, contention in the network, caches. The
//! model is labelled as such wherever it is printed.

use super::Prediction;
use crate::exec::reference::CellCost;
use crate::grid::Grid;
use crate::kernel::Partition;
use std::collections::BTreeMap;

/// A network between ranks: one latency and one bandwidth for every pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Network {
    /// Its name, for tables.
    pub name: &'static str,
    /// One-way latency of a message, s.
    pub latency_seconds: f64,
    /// Bandwidth of one link, bytes/s.
    pub bytes_per_second: f64,
}

impl std::fmt::Display for Network {
    /// Its name, latency and bandwidth: `InfiniBand HDR100 (1.5 us, 12.5 GB/s)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({} us, {} GB/s)",
            self.name,
            self.latency_seconds * 1e6,
            self.bytes_per_second / 1e9
        )
    }
}

impl Network {
    /// InfiniBand HDR100 as vendors state it: 1.5 µs, 100 Gbit/s (12.5 GB/s).
    pub const INFINIBAND_HDR100: Network = Network {
        name: "InfiniBand HDR100",
        latency_seconds: 1.5e-6,
        bytes_per_second: 12.5e9,
    };

    /// 10 Gigabit Ethernet with TCP: 25 µs, 1.25 GB/s.
    pub const ETHERNET_10G: Network = Network {
        name: "10 GbE TCP",
        latency_seconds: 25e-6,
        bytes_per_second: 1.25e9,
    };
}

/// The costs of one state on the wire, measured on this machine for the model at hand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WireCosts {
    /// Bytes of one state in a batch (its words plus its home cell).
    pub bytes_per_state: f64,
    /// CPU time to encode one state and decode it again, s.
    pub encode_decode_seconds: f64,
    /// CPU time to hash one state, s.
    pub hash_seconds: f64,
    /// Bytes of a batch besides its states (header, checksum, per-message fields).
    pub batch_overhead_bytes: f64,
}

/// How the ranks run: GVT rounds and commits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterRun {
    /// Steps between two GVT rounds.
    pub steps_per_round: f64,
    /// Whether rank 0 gathers, decodes and hashes every state of every committed step (the
    /// executor as implemented); `false` predicts a commit that costs nothing.
    pub full_state_commit: bool,
}

/// What the model predicts for one partition and network.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterPrediction {
    /// Ranks (= worlds).
    pub ranks: usize,
    /// Sum of every cell computation's measured time: the sequential time, s.
    pub sequential_seconds: f64,
    /// The same partition with free messages, rounds and commits (the dataflow model), s.
    pub dataflow_seconds: f64,
    /// With the network, GVT rounds and commits, s.
    pub cluster_seconds: f64,
    /// Ghost bytes sent between ranks, summed over the steps.
    pub ghost_bytes: f64,
    /// Bytes gathered at rank 0 for commits, summed over the steps.
    pub commit_bytes: f64,
}

impl ClusterPrediction {
    /// Sequential time over the cluster time.
    pub fn speedup(&self) -> f64 {
        self.sequential_seconds / self.cluster_seconds.max(1e-12)
    }

    /// The speed-up per rank.
    pub fn efficiency(&self) -> f64 {
        self.speedup() / self.ranks as f64
    }
}

/// Predicts the MPI executor on `partition`'s worlds (one per rank) over `network`, from the
/// cell costs of steps `0..steps` and `occupancy[t][cell]`, the states in each cell when step
/// `t` is computed.
pub fn predict_cluster(
    grid: &Grid,
    partition: &Partition,
    costs: &[CellCost],
    occupancy: &[Vec<u32>],
    wire: &WireCosts,
    network: &Network,
    run: &ClusterRun,
) -> ClusterPrediction {
    let n = partition.worlds();
    let steps = occupancy.len();
    let dataflow: Prediction = super::predict(grid, partition, costs, steps as u64);
    let mut compute = vec![vec![0.0f64; n]; steps];
    // Sums in (step, cell) order, whatever order the costs came in.
    let mut sorted: Vec<&CellCost> = costs.iter().filter(|c| (c.step as usize) < steps).collect();
    sorted.sort_by_key(|c| (c.step, c.cell));
    for c in sorted {
        compute[c.step as usize][partition.owner(c.cell) as usize] += c.seconds;
    }
    // For each world, its border cells towards each neighbouring world (ascending ids).
    let borders: Vec<BTreeMap<usize, Vec<u32>>> = (0..n)
        .map(|w| {
            let mut to: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
            for &c in partition.cells_of(w as u32) {
                let mut seen: Vec<usize> = Vec::new();
                for nb in grid.neighbours(grid.coord(c as usize)) {
                    let v = partition.owner(grid.index(nb) as u32) as usize;
                    if v != w && !seen.contains(&v) {
                        seen.push(v);
                        to.entry(v).or_default().push(c);
                    }
                }
            }
            to
        })
        .collect();
    let all_reduce = 2.0 * network.latency_seconds * (n.max(2) as f64).log2().ceil();
    let round = run.steps_per_round.max(1.0);
    let mut finish = vec![0.0f64; n];
    // arrival[w][v]: when v's ghosts of the previous step reach w.
    let mut arrival: Vec<BTreeMap<usize, f64>> = vec![BTreeMap::new(); n];
    let (mut ghost_bytes, mut commit_bytes) = (0.0f64, 0.0f64);
    let mut round_states = 0.0f64;
    let mut next_round = round;
    for t in 0..steps {
        let states = &occupancy[t];
        let sent: Vec<BTreeMap<usize, f64>> = borders
            .iter()
            .map(|to| {
                to.iter()
                    .map(|(&v, cells)| {
                        let k: f64 = cells.iter().map(|&c| f64::from(states[c as usize])).sum();
                        (v, k)
                    })
                    .collect()
            })
            .collect();
        let mut done = vec![0.0f64; n];
        for w in 0..n {
            let ready = arrival[w].values().copied().fold(finish[w], f64::max);
            let out: f64 = sent[w].values().sum();
            let got: f64 = sent.iter().filter_map(|to| to.get(&w).copied()).sum();
            done[w] = ready + compute[t][w] + (out + got) * wire.encode_decode_seconds;
        }
        let mut next: Vec<BTreeMap<usize, f64>> = vec![BTreeMap::new(); n];
        for (v, to) in sent.iter().enumerate() {
            for (&w, &k) in to {
                let bytes = k * wire.bytes_per_state + wire.batch_overhead_bytes;
                ghost_bytes += bytes;
                let at =
                    done[v] + network.latency_seconds + bytes / network.bytes_per_second.max(1.0);
                next[w].insert(v, at);
            }
        }
        arrival = next;
        finish = done;
        let step_states: f64 = states.iter().map(|&k| f64::from(k)).sum();
        round_states += step_states;
        if (t + 1) as f64 >= next_round || t + 1 == steps {
            next_round += round;
            // Every rank waits for the slowest, then the all-reduce; then rank 0 gathers,
            // decodes and hashes the round's states over its one link.
            let mut barrier = finish.iter().copied().fold(0.0, f64::max) + all_reduce;
            if run.full_state_commit && n > 1 {
                let bytes = round_states * wire.bytes_per_state;
                commit_bytes += bytes;
                barrier += network.latency_seconds
                    + bytes / network.bytes_per_second.max(1.0)
                    + round_states * (wire.encode_decode_seconds + wire.hash_seconds);
            }
            finish.iter_mut().for_each(|f| *f = barrier);
            for a in &mut arrival {
                a.values_mut().for_each(|x| *x = x.min(barrier));
            }
            round_states = 0.0;
        }
    }
    ClusterPrediction {
        ranks: n,
        sequential_seconds: dataflow.sequential_seconds,
        dataflow_seconds: dataflow.dataflow_seconds,
        cluster_seconds: finish.iter().copied().fold(0.0, f64::max),
        ghost_bytes,
        commit_bytes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::PartitionKind;
    use crate::math::Vec3;

    /// A 16 × 1 × 16 grid, one state per cell, every cell costing 1 ms for `steps` steps.
    fn uniform(steps: usize) -> (Grid, Vec<CellCost>, Vec<Vec<u32>>) {
        let grid = Grid::covering(Vec3::zeros(), Vec3::new(16.0, 1.0, 16.0), 1.0);
        assert_eq!(grid.cell_count(), 256);
        let cells = grid.cell_count();
        let costs = (0..steps as u64)
            .flat_map(|step| {
                (0..cells as u32).map(move |cell| CellCost {
                    step,
                    cell,
                    seconds: 1e-3,
                })
            })
            .collect();
        (grid, costs, vec![vec![1; cells]; steps])
    }

    fn free_wire() -> WireCosts {
        WireCosts {
            bytes_per_state: 0.0,
            encode_decode_seconds: 0.0,
            hash_seconds: 0.0,
            batch_overhead_bytes: 0.0,
        }
    }

    const FREE: Network = Network {
        name: "free",
        latency_seconds: 0.0,
        bytes_per_second: f64::MAX,
    };

    fn partition(grid: &Grid, worlds: usize) -> Partition {
        Partition::build(&PartitionKind::Blocks, grid, worlds, &[], 0)
    }

    #[test]
    fn a_free_network_without_rounds_or_commits_is_the_dataflow_model() {
        let (grid, costs, occ) = uniform(20);
        for worlds in [1, 4, 16] {
            let p = partition(&grid, worlds);
            let run = ClusterRun {
                steps_per_round: 1e9,
                full_state_commit: false,
            };
            let m = predict_cluster(&grid, &p, &costs, &occ, &free_wire(), &FREE, &run);
            assert!(
                (m.cluster_seconds - m.dataflow_seconds).abs() <= 1e-9 * m.dataflow_seconds,
                "{m:?}"
            );
        }
    }

    #[test]
    fn latency_bandwidth_rounds_and_commits_each_only_add_time() {
        let (grid, costs, occ) = uniform(30);
        let p = partition(&grid, 8);
        let wire = WireCosts {
            bytes_per_state: 200.0,
            encode_decode_seconds: 1e-6,
            hash_seconds: 1e-7,
            batch_overhead_bytes: 64.0,
        };
        let none = ClusterRun {
            steps_per_round: 1e9,
            full_state_commit: false,
        };
        let rounds = ClusterRun {
            steps_per_round: 4.0,
            full_state_commit: false,
        };
        let commits = ClusterRun {
            steps_per_round: 4.0,
            full_state_commit: true,
        };
        let t = |wire: &WireCosts, net: &Network, run: &ClusterRun| {
            predict_cluster(&grid, &p, &costs, &occ, wire, net, run).cluster_seconds
        };
        let base = t(&free_wire(), &FREE, &none);
        let with_wire = t(&wire, &FREE, &none);
        let slow = t(&wire, &Network::ETHERNET_10G, &none);
        let with_rounds = t(&wire, &Network::ETHERNET_10G, &rounds);
        let with_commits = t(&wire, &Network::ETHERNET_10G, &commits);
        assert!(
            base < with_wire && with_wire < slow,
            "{base} {with_wire} {slow}"
        );
        assert!(slow < with_rounds && with_rounds < with_commits);
        // The faster network is faster.
        assert!(t(&wire, &Network::INFINIBAND_HDR100, &commits) < with_commits);
    }

    #[test]
    fn ghost_and_commit_bytes_count_border_and_all_states() {
        let (grid, costs, occ) = uniform(8);
        let p = partition(&grid, 2);
        let wire = WireCosts {
            bytes_per_state: 100.0,
            encode_decode_seconds: 0.0,
            hash_seconds: 0.0,
            batch_overhead_bytes: 0.0,
        };
        let run = ClusterRun {
            steps_per_round: 1.0,
            full_state_commit: true,
        };
        let m = predict_cluster(&grid, &p, &costs, &occ, &wire, &FREE, &run);
        // Every state of every step goes to rank 0.
        assert_eq!(m.commit_bytes, 8.0 * 256.0 * 100.0);
        // Two halves of a 16 × 16 slab: 16 border cells on each side, both ways.
        assert_eq!(m.ghost_bytes, 8.0 * 2.0 * 16.0 * 100.0);
    }
}
