#!/usr/bin/env bash
# Reproduces the shipped room-layout model (assets/models/layout.json) and the README's layout table.
#
#   bash assets/reproduce-layout.sh
#
# BIN (default target/release/cog-gpu, built first) is the binary that runs. WORK (default
# /tmp/cog-gpu-layout) receives the data sets, models, layouts and logs; nothing in the checkout is changed
# (copy WORK/manhattan.json to assets/models/layout.json to ship a new model).
# Data (320x240, synth's default room mix; seeds never shared between sets):
#   train  400 frames, seed 11;   test  200 frames, seed 12;
#   timing   3 frames at 640x480 (Xtion), seed 21.
# Real frame: ../shared/data/sunrgbd/kv1-b3dodata-img_0063 (the only frame there with a room annotation).
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/cog-gpu-layout}
BIN=${BIN:-target/release/cog-gpu}
export NODEVICE_SELECT=1 RUST_LOG=${RUST_LOG:-info}

cargo build --release --locked
mkdir -p "$WORK"
[ -d "$WORK/train" ] || "$BIN" synth --out "$WORK/train" --frames 400 --seed 11 --width 320 --height 240
[ -d "$WORK/test" ] || "$BIN" synth --out "$WORK/test" --frames 200 --seed 12 --width 320 --height 240
[ -d "$WORK/timing" ] || "$BIN" synth --out "$WORK/timing" --frames 3 --seed 21 --sensor xtion

for disc in manhattan cubical; do
    "$BIN" train-layout --data "$WORK/train" --out "$WORK/$disc.json" --discretisation "$disc" --c 1000 \
        2>&1 | grep -v "SSVM iteration" | tee "$WORK/train-$disc.log"
done

echo "== held-out synthetic test set (200 frames): mean free-space IoU =="
for method in manhattan cubical heuristic; do
    if [ "$method" = heuristic ]; then model=(--heuristic); else model=(--model "$WORK/$method.json"); fi
    "$BIN" layout "$WORK/test" "${model[@]}" --out "$WORK/out-$method" --no-overlay > "$WORK/layout-$method.log"
    echo "$method: $("$BIN" eval --layout --data "$WORK/test" --detections "$WORK/out-$method" | tail -1)"
done

echo "== real annotated frame =="
REAL=../shared/data/sunrgbd/kv1-b3dodata-img_0063
for method in manhattan heuristic; do
    if [ "$method" = heuristic ]; then model=(--heuristic); else model=(--model "$WORK/$method.json"); fi
    "$BIN" layout "$REAL" "${model[@]}" --out "$WORK/real-$method" --ply | head -1
    echo "$method: $("$BIN" eval --layout --data "$REAL" --detections "$WORK/real-$method" | tail -1)"
done

echo "== layout time per 640x480 frame (hypotheses, features, scoring; after reading the frame) =="
"$BIN" --cpu layout "$WORK/timing" --model "$WORK/manhattan.json" --out "$WORK/timing-cpu" --no-overlay | tail -1
"$BIN" layout "$WORK/timing" --model "$WORK/manhattan.json" --out "$WORK/timing-gpu" --no-overlay | tail -1
