#!/usr/bin/env bash
# Installs the Debian packages the project builds and runs against (idempotent; as root or through sudo):
# PETSc 3.18 with MUMPS/hypre/SuperLU (petsc-dev), an optimised single-threaded BLAS (BLIS, serial: it
# becomes the system BLAS through Debian's alternatives and makes MUMPS's factorisations 2.4x faster than the
# reference BLAS, with no threads of its own to compete with rayon; docs/benchmarks.md), Open MPI (mpirun),
# HDF5 (openmpi flavour, the one PETSc links), libclang for bindgen, pkg-config, and fontconfig/freetype + a
# font for the PNG plots.
set -euo pipefail

packages=(petsc-dev libblis4-serial libhdf5-openmpi-dev openmpi-bin libclang-dev pkg-config
          libfontconfig1-dev libfreetype-dev fonts-dejavu-core)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}"
  sudo=()
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "install-deps: need root or sudo to apt-get install ${missing[*]}" >&2; exit 1; }
    sudo=(sudo)
  fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo[@]}" apt-get update -qq
  "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null; then
  echo "install-deps: cargo not found; install a Rust toolchain >= 1.85 (https://rustup.rs)" >&2
  exit 1
fi
pkg-config --exists PETSc || { echo "install-deps: PETSc not visible to pkg-config after installation" >&2; exit 1; }
