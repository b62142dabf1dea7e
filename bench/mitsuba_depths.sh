#!/usr/bin/env bash
# camsim and Mitsuba 3 timed at bounce limits 1, 2, 3, 4 and 7 (Mitsuba
# max_depth; camsim max_bounces one less) on mitsuba_compare.sh's scene, so
# that a path's time splits into the camera's share and each bounce's: see
# bench/mitsuba_depths.py for what each step holds. Not run by the test suite.
#
# Usage: bench/mitsuba_depths.sh [SPP]   (default 32)
# Environment: as mitsuba_compare.sh (bench/mitsuba_env.sh), and DEPTHS
#   (default 1,2,3,4,7), REPEATS (3 renders each, the least kept); MITSUBA_ISA
#   (native or avx2) and CAMSIM_RENDER_ISA as for mitsuba_compare.sh.
set -euo pipefail
SPP="${1:-32}"
# shellcheck source=bench/mitsuba_env.sh
source "$(dirname "$0")/mitsuba_env.sh"

exec "$VENV/bin/python" "$HERE/bench/mitsuba_depths.py" --camsim "$CAMSIM" --spp "$SPP" \
    --depths "${DEPTHS:-1,2,3,4,7}" --repeats "${REPEATS:-3}" --threads 2 \
    --mitsuba-isa "${MITSUBA_ISA:-native}"
