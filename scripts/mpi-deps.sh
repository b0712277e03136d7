#!/usr/bin/env bash
# Installs what fshape-cli's `mpi` feature needs to build and run, from
# Debian's packages, if it is missing: Open MPI (library, headers, mpirun)
# and libclang (the mpi crate generates its bindings with bindgen). Root
# only, as on CI's machine; elsewhere install the same packages yourself.
set -euo pipefail
if command -v mpirun > /dev/null && ls /usr/lib/llvm-*/lib/libclang*.so* > /dev/null 2>&1; then
    exit 0
fi
echo "installing Open MPI and libclang (Debian packages)"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq libopenmpi-dev openmpi-bin libclang-dev > /dev/null
