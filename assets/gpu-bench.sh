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
#      every shipped model, at `--detect-step 0.1` (the issue's setting; with the GPU debug log) and at the
#      models' own steps, each path also with IN_FLIGHT frames in flight (`--in-flight`); at 0.1 m the GPU
#      path alone with 3 and 4 frames in flight, and with 3 and four buffer-pool sets
#      (COG_GPU_POOL_SLOTS=4); both paths at 0.1 m with `--normals window` (the normal_window kernel beside
#      the image_gradients kernel, which every GPU pass runs, in one submission),
#      and `bench --compare-normals` of the 4 frames; with BASE_BIN, that binary's GPU
#      path at 0.1 m (a baseline, same machine), one frame at a time and then BASE_IN_FLIGHT frames in
#      flight;
#   3. the README's main command, `cog-gpu detect` of the shipped sample frames with overlays, timed from
#      process start to exit (and BASE_BIN's).
# Results go to $OUT (set by the device tool; default gpu-bench-out/), six files: fast-bed.json,
# detect-0.1.json, detect-own.json, variants.jsonl (one line per variant of 2 and 2c: {"variant", "report"}),
# sample-detect.txt and log.txt (every step's stderr: adapter, GPU debug log). On an H200 and its 16-core
# host the whole run (without the own steps, with a baseline) took 140 s (2026-11-27).
#
# Environment: BIN (default .dev/cog-gpu, else target/release/cog-gpu), BASE_BIN (none; e.g. an earlier
# build's .dev/cog-gpu copied aside before `prepare` replaces it), BASE_IN_FLIGHT (3: the baseline's
# throughput with 3 frames in flight, comparable with gpu-in-flight-3 of the same run; 0 leaves that pass
# out, for a BASE_BIN older than `--in-flight`, 2026-11-27), SIZES (default
# .dev/sunrgbd-size-stats.json, else ../shared/data/sunrgbd-size-stats.json), REPEAT (2), IN_FLIGHT (2),
# STEPS ("0.1 own"), QUICK=1 (one
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
IN_FLIGHT=${IN_FLIGHT:-2}
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

frames=4 steps=(${STEPS:-0.1 own}) hypothesis_limit=()
[ "${QUICK:-0}" = 1 ] && frames=1 steps=("own") REPEAT=1 hypothesis_limit=(--limit 20000)
# The steps' time limits add up to 540 s (530 with BASE_BIN and STEPS=0.1; the device tool allows 600 per
# command); SLOW multiplies them
# (default 1; QUICK on a 2-core machine: 6).
SLOW=${SLOW:-$([ "${QUICK:-0}" = 1 ] && echo 6 || echo 1)}
step synth-standard 30 "$BIN" synth --out "$work/standard" --frames 1 --seed 1 --sensor xtion > /dev/null
step synth-frames 40 "$BIN" synth --out "$work/frames" --frames "$frames" --seed 1 --sensor xtion > /dev/null

# 1. The bed window on the standard frame, fast path, both paths.
step fast-bed 60 env RUST_LOG=cog_gpu::gpu=debug "$BIN" bench --frame "$work/standard/synth-000000" --sizes "$SIZES" \
    --features fast --both "${hypothesis_limit[@]}" --json > "$OUT/fast-bed.json"

# 2. End to end, every shipped model, both paths, at 0.1 m and at the models' own steps (at 0.1 m with the
#    GPU debug log: where each fast-path call's time goes); each path then again with IN_FLIGHT frames in
#    flight (its wall-clock seconds per frame, detections compared).
for s in "${steps[@]}"; do
    step_args=()
    [ "$s" = own ] || step_args=(--detect-step "$s")
    step "detect-$s" "$([ "$s" = own ] && echo 100 || echo 150)" env RUST_LOG="$([ "$s" = own ] || echo cog_gpu::gpu=debug)" \
        "$BIN" bench --detect "$work/frames" "${step_args[@]}" --both --repeat "$REPEAT" --in-flight "$IN_FLIGHT" --json \
        > "$OUT/detect-$s.json"
done
# variant NAME SECONDS COMMAND...: a step whose JSON report goes to variants.jsonl as one line
# {"variant": NAME, "report": ...} (few files: the device tool returns a limited number).
variant() {
    local name=$1 limit=$2
    shift 2
    step "$name" "$limit" "$@" > "$work/variant.json"
    printf '{"variant":"%s","report":%s}\n' "$name" "$(cat "$work/variant.json")" >> "$OUT/variants.jsonl"
}
# 2b. The GPU path alone at 0.1 m with more frames in flight, and with more buffer-pool sets.
if [ "${QUICK:-0}" != 1 ]; then
    gpu_at_0_1=("$BIN" bench --detect "$work/frames" --detect-step 0.1 --gpu --repeat "$REPEAT" --json)
    variant gpu-in-flight-3 40 "${gpu_at_0_1[@]}" --in-flight 3
    variant gpu-in-flight-3-pool-4 40 env COG_GPU_POOL_SLOTS=4 "${gpu_at_0_1[@]}" --in-flight 3
    variant gpu-in-flight-4 40 "${gpu_at_0_1[@]}" --in-flight 4
    # The window normals (README "Normals in an image window"): the neighbour search by the normal_window
    # kernel on the GPU path, its twin on the CPU path, both paths; and the two searches' time and agreement.
    variant window-normals-0.1 60 "$BIN" bench --detect "$work/frames" --detect-step 0.1 --both --repeat "$REPEAT" \
        --normals window --json
    variant compare-normals 30 "$BIN" bench --compare-normals "$work/frames" --json
fi
# 2c. A baseline build (BASE_BIN, e.g. the previous release), GPU path, same machine, same frames.
if [ -n "${BASE_BIN:-}" ]; then
    base_in_flight=()
    [ "${BASE_IN_FLIGHT:-3}" = 0 ] || base_in_flight=(--in-flight "${BASE_IN_FLIGHT:-3}")
    variant base-detect-0.1 50 "$BASE_BIN" bench --detect "$work/frames" --detect-step 0.1 --gpu --repeat "$REPEAT" \
        --json "${base_in_flight[@]}"
fi

# 3. The README's main command, process start to exit, overlays written (and the baseline's, with BASE_BIN).
sample_detect() {
    local name=$1 bin=$2 started elapsed_ms
    started=$(date +%s%N)
    echo "== $name" >> "$OUT/sample-detect.txt"
    step "$name" 40 "$bin" detect --out "$work/$name" >> "$OUT/sample-detect.txt"
    elapsed_ms=$((($(date +%s%N) - started) / 1000000))
    echo "wall seconds, process start to exit: $((elapsed_ms / 1000)).$(printf %03d $((elapsed_ms % 1000)))" \
        >> "$OUT/sample-detect.txt"
}
sample_detect sample-detect "$BIN"
[ -z "${BASE_BIN:-}" ] || sample_detect base-sample-detect "$BASE_BIN"
grep -h -m1 -i "adapter" "$log" >&2 || true
ls -l "$OUT" >&2
