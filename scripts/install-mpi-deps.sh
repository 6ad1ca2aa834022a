#!/usr/bin/env bash
# Installs what the MPI executor needs (cargo feature `mpi`, tests/mpi.rs): Debian's Open MPI
# (`openmpi-bin`: the `mpirun` launcher; `libopenmpi-dev`: the headers and libraries rsmpi
# links against) and `libclang-dev`, which rsmpi's build script uses to generate its
# bindings. Installs only the packages that are missing; does nothing if all are there.
# .ci/run calls it.
set -euo pipefail
missing=()
for pkg in openmpi-bin libopenmpi-dev libclang-dev; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "ok installed"; then
    missing+=("$pkg")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
command -v mpirun && command -v mpicc
