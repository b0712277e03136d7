#!/usr/bin/env bash
# Installs what fshape-cli's `mpi` feature needs to build and run, from
# Debian's packages, if it is missing: Open MPI (library, headers, mpirun)
# and libclang (the mpi crate generates its bindings with bindgen). Root
# only, as on CI's machine; elsewhere install the same packages yourself.
set -euo pipefail
libclang() {
    compgen -G "/usr/lib/llvm-*/lib/libclang.so*" > /dev/null || compgen -G "/usr/lib/llvm-*/lib/libclang-[0-9]*.so*" > /dev/null
}
if command -v mpirun > /dev/null && command -v mpicc > /dev/null && libclang; then
    exit 0
fi
echo "installing Open MPI and libclang (Debian packages)"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq libopenmpi-dev openmpi-bin libclang-dev > /dev/null
