#!/usr/bin/env bash
# The ray traversal alone, camsim against Mitsuba 3 (its Embree-backed
# `ray_intersect_preliminary` and `ray_test`, `llvm_ad_spectral`), on the
# same kind of rays in mitsuba_compare.sh's box: diffuse bounce rays from
# where random rays inside the box land, and shadow rays from there to the
# ceiling light; timed as drawn and sorted by direction octant and origin
# cell. One thread each. camsim's side is the ignored test
# `render::bvh4_packet::tests::packet_timing_cornell_box`; Mitsuba's is
# bench/mitsuba_trace.py. Not run by the test suite.
#
# Usage: bench/mitsuba_trace.sh
# Environment: as mitsuba_compare.sh (bench/mitsuba_env.sh).
set -euo pipefail
# shellcheck source=bench/mitsuba_env.sh
source "$(dirname "$0")/mitsuba_env.sh"

echo "camsim (cargo test --release --lib packet_timing_cornell_box, one thread):"
(cd "$HERE" && CARGO_TARGET_DIR="$TARGET" cargo test --release --quiet --lib packet_timing_cornell_box \
    -- --ignored --nocapture --test-threads 1 2>/dev/null | grep -E 'rays |ns/ray')
echo "Mitsuba:"
exec "$VENV/bin/python" "$HERE/bench/mitsuba_trace.py" --threads 1
