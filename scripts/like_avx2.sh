#!/usr/bin/env bash
# Run a command with the vector code paths of an x86-64 CPU without AVX-512 (AVX2), on any x86-64
# CPU: numpy's SIMD dispatch, OpenBLAS, oneDNN and MKL (torch), torch's own kernels and numba take
# their AVX2 paths. The variables are drivelab.isa.PINNED_ISA's, less its thread counts
# (tests/test_isa.py holds the two lists equal). On an AVX-512 machine it reproduces what an AVX2
# machine computes: drivelab/isa.py says what was checked. Example:
#   bash scripts/like_avx2.sh bash .ci/run
set -euo pipefail
export NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"
export OPENBLAS_CORETYPE=Haswell
export ATEN_CPU_CAPABILITY=avx2
export ONEDNN_MAX_CPU_ISA=AVX2
export MKL_ENABLE_INSTRUCTIONS=AVX2
export NUMBA_CPU_NAME=haswell
exec "$@"
