# Sourced by the Mitsuba benchmarks (mitsuba_compare.sh, mitsuba_depths.sh):
# Mitsuba 3 in a venv and camsim built, as set up once on a fresh machine.
# Sets HERE, TARGET, BENCH_DIR, VENV and CAMSIM. Environment: CARGO_TARGET_DIR,
# BENCH_DIR, MITSUBA_VENV, CAMSIM, CAMSIM_NO_BUILD (use the binary as it is).
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
TARGET="${CARGO_TARGET_DIR:-$HERE/target}"
BENCH_DIR="${BENCH_DIR:-$TARGET/mitsuba-bench}"
VENV="${MITSUBA_VENV:-$BENCH_DIR/venv}"
CAMSIM="${CAMSIM:-$TARGET/release/camsim}"

if ! ldconfig -p | grep -q 'libLLVM.so.19\|libLLVM-19'; then
    echo "note: Debian's libllvm19 not found; Mitsuba's llvm_* variants need it: apt-get install libllvm19" >&2
    echo "      (without it the script falls back to the much slower scalar_spectral variant)" >&2
fi
mkdir -p "$BENCH_DIR"
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
fi
if ! "$VENV/bin/python" -c "import mitsuba, numpy" 2>/dev/null; then
    "$VENV/bin/pip" install --quiet mitsuba numpy
fi
if [ -z "${CAMSIM_NO_BUILD:-}" ]; then
    (cd "$HERE" && CARGO_TARGET_DIR="$TARGET" cargo build --release --quiet)
fi
[ -x "$CAMSIM" ] || { echo "camsim binary not found at $CAMSIM" >&2; exit 1; }
