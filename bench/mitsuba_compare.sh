#!/usr/bin/env bash
# Compare camsim's spectral path tracer with Mitsuba 3 on Mitsuba's own
# cornell_box() scene in one run: 256×256, Mitsuba max_depth 7 (= camsim
# max_bounces 6), 2 threads, box pixel filter, Mitsuba `llvm_ad_spectral`.
#
# Prints for both renderers: paths/s, the relative RMSE of CIE Y luminance at
# equal spp and at equal time against ONE converged Mitsuba reference, how
# well camsim's converged image agrees with Mitsuba's, and two final lines
#   CPU SIMD flags: <the flags of /proc/cpuinfo that decide the vector width>
#   RATIO camsim/Mitsuba: paths/s … ; equal-time RMSE … ; CPU <model> (<vector width>), load …
# (the vector width is avx512f, avx2+fma or sse: Mitsuba's LLVM back end runs 16,
# 8 or 4 paths per instruction, so the ratio depends on it; quote it with the ratio;
# the line ends with what Mitsuba's kernels were compiled for and how many lanes).
# The method is documented in bench/mitsuba_compare.py and in
# src/render/bench.rs (scene, spectra, compared quantity).
#
# Set-up (once, done by this script except the Debian package):
#   apt-get install libllvm19 python3-venv   # Mitsuba's LLVM variants need libllvm19
#   python3 -m venv target/mitsuba-bench/venv && pip install mitsuba numpy
# The Mitsuba reference (1024 spp) and camsim's converged image are rendered
# once and cached under $BENCH_DIR (camsim's keyed by the binary's hash).
#
# Not run by the test suite. Usage:
#   bench/mitsuba_compare.sh [MITSUBA_SPP]        (default 32)
# Environment: CARGO_TARGET_DIR, BENCH_DIR, MITSUBA_VENV, CAMSIM,
#   REF_SPP (1024), CONV_SPP (256 per half; 0 skips the agreement check),
#   SEEDS (4 timed renders per measurement), BATCHES (camsim's sample
#   batches, 1: one image with no standard error, as Mitsuba renders; 8 is the
#   renderer's default for experiments, which estimate their error from the
#   batch spread at the cost of stratifying only spp/8 points per batch),
#   SAMPLER (camsim's sampler: sobol, the default, or independent);
#   CAMSIM_RENDER_ISA=sse|avx2 (lower camsim's kernel) and CAMSIM_RENDER_PACKETS=0|1
#   (one path / 16 paths at a time; default 16 at avx2 and avx512) pass through to
#   camsim; MITSUBA_ISA=avx2 has Dr.Jit compile Mitsuba's kernels as for an
#   AVX2+FMA machine (8 lanes; native, the default, is the machine's widest;
#   Dr.Jit has no SSE-only target). With both at avx2 the run stands in for an
#   AVX2-only machine of the same clock and memory. The RATIO line names the
#   levels of both renderers.
set -euo pipefail
SPP="${1:-32}"
# shellcheck source=bench/mitsuba_env.sh
source "$(dirname "$0")/mitsuba_env.sh"

exec "$VENV/bin/python" "$HERE/bench/mitsuba_compare.py" \
    --camsim "$CAMSIM" --cache "$BENCH_DIR" --spp "$SPP" \
    --ref-spp "${REF_SPP:-1024}" --camsim-conv-spp "${CONV_SPP:-256}" --seeds "${SEEDS:-4}" --threads 2 \
    --batches "${BATCHES:-1}" --sampler "${SAMPLER:-sobol}" --mitsuba-isa "${MITSUBA_ISA:-native}"
