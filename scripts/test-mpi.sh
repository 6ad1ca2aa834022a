#!/usr/bin/env bash
# The MPI executor's tests (tests/mpi.rs, issue 22) on a fresh machine: installs Open MPI and
# libclang if missing, builds `soda` with the `mpi` feature (the binary alone: the test
# harness needs no MPI, so the dev-dependencies keep their default-feature build), keeps it
# as target/mpi/soda, and runs the tests under `mpirun` against it. .ci/run calls it.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-mpi-deps.sh >/dev/null
cargo build --release --features mpi --bin soda
mkdir -p target/mpi
# Written whole, then renamed: the next default build overwrites target/release/soda.
cp target/release/soda target/mpi/soda.partial
mv target/mpi/soda.partial target/mpi/soda
SODA_MPI_BIN="$PWD/target/mpi/soda" cargo test --release --test mpi -- --ignored
