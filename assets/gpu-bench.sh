#!/usr/bin/env bash
# The README's GPU measurements ("The fast path", "End to end: `cog-gpu bench --detect`") as one prepared
# run for a lent GPU machine (the `device` tool: one short call instead of commands typed during the
# lease), or as a smoke test anywhere else.
#
#   bash assets/gpu-bench.sh prepare   # here, after `cargo build --release`: ../shared/tools/device-prep
#                                      # (stripped binary and Vulkan loader into the ignored .dev/ and .gl/)
#                                      # and the size quantiles copied into .dev/ (../shared does not travel)
#   .dev/with-vulkan bash assets/gpu-bench.sh   # on the GPU machine: `run` with carry [".dev", ".gl"],
#                                               # timeout_s 600 (the wrapper installs the carried Vulkan
#                                               # loader once, then runs the script)
#
# What runs (the GPU and the CPU path of each in the same process, so compare their ratio, not figures
# from different machines), each under `timeout` so that one stuck step does not take the lease:
#   1. the standard frame (`synth --frames 1 --seed 1 --sensor xtion`, 640x480): the bed window on the
#      fast path, `bench --features fast --both --json` with the GPU debug log (per-pass GPU timestamps);
#   2. the 4 frames of `synth --frames 4 --seed 1 --sensor xtion`: `bench --detect --both --json` with
#      every shipped model, at `--detect-step 0.1` (the issue's setting) and at the models' own steps;
#   3. the README's main command, `cog-gpu detect` of the shipped sample frames with overlays, timed from
#      process start to exit.
# Results go to $OUT (set by the device tool; default gpu-bench-out/): fast-bed.json, detect-0.1.json,
# detect-own.json, sample-detect.txt, and log.txt (every step's stderr: adapter, GPU debug log). The run
# should take about 3 minutes on an H200 and its 16-core host (an estimate from the README's figures: not yet run
# on a GPU; the QUICK smoke test ran on lavapipe).
#
# Environment: BIN (default .dev/cog-gpu, else target/release/cog-gpu), SIZES (default
# .dev/sunrgbd-size-stats.json, else ../shared/data/sunrgbd-size-stats.json), REPEAT (2), QUICK=1 (one
# frame, one repeat, own steps only, 20 000 bed hypotheses: a smoke test, e.g. on lavapipe, where `detect` keeps the CPU fast path).
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "${1:-run}" = prepare ]; then
    [ -x target/release/cog-gpu ] || { echo "gpu-bench: build first (cargo build --release --locked)" >&2; exit 1; }
    ../shared/tools/device-prep
    cp ../shared/data/sunrgbd-size-stats.json .dev/
    echo "gpu-bench: prepared; on the device: .dev/with-vulkan bash assets/gpu-bench.sh (carry .dev and .gl)"
    exit 0
fi
[ "${1:-run}" = run ] || { echo "usage: bash assets/gpu-bench.sh [prepare|run]" >&2; exit 2; }

BIN=${BIN:-$([ -x .dev/cog-gpu ] && echo .dev/cog-gpu || echo target/release/cog-gpu)}
SIZES=${SIZES:-$([ -f .dev/sunrgbd-size-stats.json ] && echo .dev/sunrgbd-size-stats.json \
    || echo ../shared/data/sunrgbd-size-stats.json)}
REPEAT=${REPEAT:-2}
OUT=${OUT:-gpu-bench-out}
[ -x "$BIN" ] || { echo "gpu-bench: no binary at $BIN (run \`bash assets/gpu-bench.sh prepare\` first)" >&2; exit 1; }
[ -f "$SIZES" ] || { echo "gpu-bench: no size quantiles at $SIZES" >&2; exit 1; }
mkdir -p "$OUT"
export NODEVICE_SELECT=1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
log="$OUT/log.txt"
: > "$log"
# step NAME SECONDS COMMAND...: runs COMMAND with a time limit, its stderr appended to the log under a
# header; a failed or timed-out step is logged and the run goes on to the next.
step() {
    local name=$1 limit=$(($2 * SLOW))
    shift 2
    echo "== $name: $*" | tee -a "$log" >&2
    local started=$SECONDS status=0
    timeout "$limit" "$@" 2>> "$log" || status=$?
    echo "== $name: exit $status after $((SECONDS - started)) s" | tee -a "$log" >&2
}

frames=4 steps=("0.1" "own") hypothesis_limit=()
[ "${QUICK:-0}" = 1 ] && frames=1 steps=("own") REPEAT=1 hypothesis_limit=(--limit 20000)
# The steps' time limits add up to 545 s (the device tool allows 600 per command); SLOW multiplies them
# (default 1; QUICK on a 2-core machine: 6).
SLOW=${SLOW:-$([ "${QUICK:-0}" = 1 ] && echo 6 || echo 1)}
step synth-standard 45 "$BIN" synth --out "$work/standard" --frames 1 --seed 1 --sensor xtion > /dev/null
step synth-frames 60 "$BIN" synth --out "$work/frames" --frames "$frames" --seed 1 --sensor xtion > /dev/null

# 1. The bed window on the standard frame, fast path, both paths.
step fast-bed 90 env RUST_LOG=cog_gpu::gpu=debug "$BIN" bench --frame "$work/standard/synth-000000" --sizes "$SIZES" \
    --features fast --both "${hypothesis_limit[@]}" --json > "$OUT/fast-bed.json"

# 2. End to end, every shipped model, both paths, at 0.1 m and at the models' own steps.
for s in "${steps[@]}"; do
    step_args=()
    [ "$s" = own ] || step_args=(--detect-step "$s")
    step "detect-$s" "$([ "$s" = own ] && echo 120 || echo 170)" "$BIN" bench --detect "$work/frames" "${step_args[@]}" --both --repeat "$REPEAT" --json \
        > "$OUT/detect-$s.json"
done

# 3. The README's main command, process start to exit, overlays written.
started=$(date +%s%N)
step sample-detect 60 "$BIN" detect --out "$work/detections" > "$OUT/sample-detect.txt"
elapsed_ms=$((($(date +%s%N) - started) / 1000000))
echo "wall seconds, process start to exit: $((elapsed_ms / 1000)).$(printf %03d $((elapsed_ms % 1000)))" \
    >> "$OUT/sample-detect.txt"
grep -h -m1 -i "adapter" "$log" >&2 || true
ls -l "$OUT" >&2
