#!/usr/bin/env bash
# Compare camsim's spectral path tracer with Mitsuba 3 on Mitsuba's own
# cornell_box() scene: 256×256, max_depth 7 (camsim max_bounces 6), 2 threads.
#
# Installs Mitsuba from PyPI into a private virtualenv (its LLVM variants need
# Debian's libllvm19: `apt-get install libllvm19`), renders the scene with
# `llvm_ad_spectral` (falls back to `scalar_spectral`), then runs
# `camsim bench render` and prints paths/s of both and their ratio.
#
# Not run by the test suite. Usage: bench/mitsuba_compare.sh [SPP]
set -euo pipefail
SPP="${1:-64}"
HERE="$(cd "$(dirname "$0")/.." && pwd)"
VENV="${MITSUBA_VENV:-$HERE/target/mitsuba-venv}"
CAMSIM="${CAMSIM:-$HERE/target/release/camsim}"

if ! ldconfig -p | grep -q libLLVM; then
    echo "note: libLLVM not found; install Debian's libllvm19 for the llvm_* variants (sudo apt-get install libllvm19)" >&2
fi
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet mitsuba
fi
[ -x "$CAMSIM" ] || (cd "$HERE" && cargo build --release)

MITSUBA_OUT="$("$VENV/bin/python" - "$SPP" <<'PY'
import sys, time
import mitsuba as mi
spp = int(sys.argv[1])
variant = None
for v in ("llvm_ad_spectral", "scalar_spectral"):
    try:
        mi.set_variant(v)
        variant = v
        break
    except Exception:
        pass
if variant is None:
    sys.exit("no spectral Mitsuba variant available")
try:
    import drjit as dr
    dr.set_thread_count(2)
except Exception:
    pass
scene_dict = mi.cornell_box()
scene_dict.setdefault("integrator", {"type": "path"})["max_depth"] = 7
scene_dict["sensor"]["film"]["width"] = 256
scene_dict["sensor"]["film"]["height"] = 256
scene = mi.load_dict(scene_dict)
mi.render(scene, spp=1)  # JIT warm-up, not timed
t0 = time.perf_counter()
c0 = time.process_time()
img = mi.render(scene, spp=spp)
if hasattr(dr, "eval"):
    dr.eval(img)
t = time.perf_counter() - t0
c = time.process_time() - c0
paths = 256 * 256 * spp
print(f"{variant} {spp} {t:.4f} {paths / t:.1f} {c:.4f} {paths / c:.1f}")
PY
)"
read -r VARIANT MSPP MTIME MPPS MCPU MPPC <<<"$MITSUBA_OUT"
echo "Mitsuba 3 ($VARIANT): $MSPP spp in $MTIME s = $(awk -v p="$MPPS" 'BEGIN{printf "%.3f", p/1e6}') M paths/s wall; $MCPU CPU s = $(awk -v p="$MPPC" 'BEGIN{printf "%.3f", p/1e6}') M paths per CPU-second (4 wavelengths per path)"

CAMSIM_OUT="$("$CAMSIM" bench render --spp "$SPP" --ref-spp "$SPP" --threads 2)"
echo "$CAMSIM_OUT"
CPPS="$(echo "$CAMSIM_OUT" | awk '/Bvh2:/ { for (i = 1; i <= NF; i++) if ($i == "M" && $(i+1) == "paths/s") { print $(i-1) * 1e6; exit } }')"
CPPC="$(echo "$CAMSIM_OUT" | awk '/Bvh2:/ { for (i = 1; i <= NF; i++) if ($i == "paths" && $(i+1) == "per" && $(i+2) == "CPU-second") { print $(i-2) * 1e6; exit } }')"
awk -v c="$CPPS" -v m="$MPPS" 'BEGIN { printf "camsim / Mitsuba paths/s ratio (wall): %.3f (camsim carries 31 bands per path, Mitsuba 4)\n", c / m }'
awk -v c="$CPPC" -v m="$MPPC" 'BEGIN { printf "camsim / Mitsuba paths per CPU-second ratio: %.3f (robust to a loaded machine)\n", c / m }'
