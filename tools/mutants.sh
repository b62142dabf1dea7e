#!/usr/bin/env bash
# Mutation testing of camsim's physics core with cargo-mutants (crates.io).
# Not run by CI: on 2 cores a module takes 15 min to several hours, so run one
# module per invocation, across sessions if need be (docs/testing.md).
#
#   cargo install cargo-mutants --locked      # once
#   tools/mutants.sh MODULE [SHARD]           # e.g. tools/mutants.sh pinhole
#                                             #      tools/mutants.sh sfr 3/10
#
# MODULE picks the source files and the test binaries that exercise them
# (the module's unit tests plus its integration tests; a mutant counts as
# caught only by these, so the score is a lower bound for the whole suite).
# SHARD (k/n) tests every n-th mutant starting at k (round-robin), so n runs
# with k = 0..n-1 together test every mutant once.
#
# Builds use the `mutants` profile (Cargo.toml: opt-level 1, incremental), in
# which a mutant rebuilds in ~5–10 s instead of ~70 s in release. Mutations are
# made in place in a scratch git worktree ($MUTANTS_TREE, default
# ../camsim-mutants), never in the tree you work in; results go to
# $MUTANTS_OUT/MODULE[-shard-k-of-n]/mutants.out (caught.txt, missed.txt,
# timeout.txt, unviable.txt, outcomes.json).
set -euo pipefail
MODULE="${1:?usage: tools/mutants.sh MODULE [k/n]  (modules: see the case list)}"
SHARD="${2:-}"
HERE="$(cd "$(dirname "$0")/.." && pwd)"
TREE="${MUTANTS_TREE:-$HERE/../camsim-mutants}"
OUT_ROOT="${MUTANTS_OUT:-$HERE/target/mutants}"

case "$MODULE" in
  pinhole)    FILES=(src/optics/pinhole.rs)
              TESTS=(--lib --test=optics_pinhole --test=render_physics --test=render_cli) ;;
  thin-lens)  FILES=(src/optics/thin_lens.rs)
              TESTS=(--lib --test=render_cli --test=render_physics --test=pbrt_parse) ;;
  rtf)        FILES=(src/optics/rtf.rs)
              TESTS=(--lib --test=optics_rtf --test=optics_p4a_zemax --test=experiment_lens_rtf) ;;
  sfr)        FILES=(src/measure/sfr.rs)
              TESTS=(--lib --test=measure_sfr --test=measure_options --test=params_reach
                     --test=measure_cli) ;;
  noise)      FILES=(src/measure/noise.rs)
              TESTS=(--lib --test=measure_noise --test=sensor_noise --test=measure_options
                     --test=params_reach --test=sensor_figures --test=measure_cli) ;;
  sensor)     FILES=(src/sensor/pipeline.rs src/sensor/readout.rs src/sensor/rng.rs
                     src/sensor/relative_illumination.rs)
              TESTS=(--lib --test=sensor_pipeline --test=sensor_noise --test=sensor_output
                     --test=sensor_calibration --test=sensor_figures) ;;
  units)      FILES=(src/spectrum/units.rs)
              TESTS=(--lib --test=sensor_pipeline --test=render_cli) ;;
  *) echo "unknown module '$MODULE' (pinhole thin-lens rtf sfr noise sensor units)" >&2; exit 2 ;;
esac

if [ ! -d "$TREE" ]; then
    git -C "$HERE" worktree add --detach "$TREE" HEAD
else
    git -C "$TREE" checkout --detach --quiet "$(git -C "$HERE" rev-parse HEAD)"
fi
git -C "$TREE" diff --quiet || { echo "$TREE has uncommitted changes (an interrupted run?): git -C $TREE checkout ." >&2; exit 1; }

# Link with the toolchain's own rust-lld when it is there (rustup ships it):
# with ~5 test binaries per mutant, linking is a good part of each build. The
# flags change the build's fingerprint, so the first run after switching
# rebuilds the dependencies once.
LLD_DIR="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/gcc-ld"
if [ -x "$LLD_DIR/ld.lld" ] && [ -z "${RUSTFLAGS:-}" ]; then
    export RUSTFLAGS="-C link-arg=-fuse-ld=lld -C link-arg=-B$LLD_DIR"
fi
# The sfr tests are light enough that an unoptimised crate wins overall
# (measured: build of a mutant 3.6 s against 9.9 s at opt-level 1; a full test
# run 7 s against 3.5 s, and most mutants stop at the first failing test).
if [ "$MODULE" = sfr ] && [ -z "${CARGO_PROFILE_MUTANTS_OPT_LEVEL:-}" ]; then
    export CARGO_PROFILE_MUTANTS_OPT_LEVEL=0
fi

# A mutant that turns a loop endless (`l -= 1` → `l /= 1`) runs to the
# timeout: 300 s where the tests take minutes when optimised (rtf, noise), 60 s
# for sfr, whose unoptimised tests take ~7 s ($MUTANTS_TIMEOUT overrides).
TIMEOUT="${MUTANTS_TIMEOUT:-300}"
if [ "$MODULE" = sfr ] && [ -z "${MUTANTS_TIMEOUT:-}" ]; then
    TIMEOUT=60
fi

# MUTANTS_LIB_ONLY=1 tests each mutant with the module's own unit tests alone
# (one test binary to build and link per mutant, not five or six, and only the
# unit tests under the module's path: ~1 s instead of ~5 s for all 212): a
# quick first pass. Then run again without it and with MUTANTS_ARGS=--iterate,
# so only the mutants the unit tests missed meet the whole test set.
FILTER=()
if [ -n "${MUTANTS_LIB_ONLY:-}" ]; then
    TESTS=(--lib)
    case "$MODULE" in
      pinhole) FILTER=(optics::pinhole) ;;  thin-lens) FILTER=(optics::thin_lens) ;;
      rtf) FILTER=(optics::rtf) ;;          sfr) FILTER=(measure::sfr) ;;
      noise) FILTER=(measure::noise) ;;     sensor) FILTER=(sensor::) ;;
      units) FILTER=(spectrum::units) ;;
    esac
fi

# The unit tests alone take about a second: a mutant that loops forever
# (a rejection sampler that never accepts) is given 30 s, not 300.
if [ -n "${MUTANTS_LIB_ONLY:-}" ] && [ -z "${MUTANTS_TIMEOUT:-}" ]; then
    TIMEOUT=30
fi

NAME="$MODULE"
ARGS=()
if [ -n "$SHARD" ]; then
    NAME="$MODULE-shard-${SHARD/\//-of-}"
    ARGS+=(--shard "$SHARD" --sharding round-robin)
fi
OUT="$OUT_ROOT/$NAME"
mkdir -p "$OUT"
# Keep every run's outcomes (cargo-mutants keeps only the last two):
# tools/mutants_score.py combines $OUT/runs/0, 1, … and the current one.
if [ -f "$OUT/mutants.out/outcomes.json" ]; then
    mkdir -p "$OUT/runs"
    cp -r "$OUT/mutants.out" "$OUT/runs/$(find "$OUT/runs" -mindepth 1 -maxdepth 1 | wc -l)"
fi
for f in "${FILES[@]}"; do ARGS+=(-f "$f"); done
cd "$TREE"
# The test targets go to every cargo invocation (-C), not only to the test
# run: cargo-mutants builds each mutant with `cargo test --no-run`, which
# otherwise links all ~55 test binaries for every mutant.
for t in "${TESTS[@]}"; do ARGS+=("--cargo-arg=$t"); done
# One unit test of the light sampler takes 14 s unoptimised (the rest of the
# library's 141 take 3 s); none of the modules here is the integrator, so it
# is skipped. $MUTANTS_ARGS passes further cargo-mutants options (e.g.
# --iterate to re-test only what the previous run in $OUT did not catch).
# shellcheck disable=SC2086
cargo mutants --in-place --profile mutants --timeout "$TIMEOUT" "${ARGS[@]}" ${MUTANTS_ARGS:-} -o "$OUT" \
    -- -- "${FILTER[@]}" --skip render::integrator::tests::very_dim_point_light_beside_a_bright_one_is_unbiased
