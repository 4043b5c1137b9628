#!/usr/bin/env bash
# Reproduces the shipped models (assets/models/) and the README's AP tables on synthetic data.
#
#   bash assets/reproduce-models.sh models    # data, the ten shipped models, calibration, test AP@0.25
#   bash assets/reproduce-models.sh ablation  # the paper's Table 1 ablation (5 categories x 5 feature sets)
#   bash assets/reproduce-models.sh small     # after `models`: the nine small categories (paper Table 2)
#   bash assets/reproduce-models.sh cascade   # after `small`: the context cascade over all 19, trained and
#                                             # evaluated
#   bash assets/reproduce-models.sh exclusion # after `cascade`: its cross-category exclusion, fitted on the
#                                             # selection set and evaluated
#   bash assets/reproduce-models.sh final     # nothing trained: the shipped cascade's final calibration
#                                             # fitted again on the selection set, into WORK/final/
#   bash assets/reproduce-models.sh shipped-cascade # only the cascade's stages trained: the shipped
#                                             # models' cascade-set detections and the cascade trained on
#                                             # them, into WORK/shipped-cascade/ (needs python3)
#   bash assets/reproduce-models.sh shipped   # nothing trained: the shipped pipeline (assets/models as they
#                                             # are) on the test set, both annotation rules -- the figures of
#                                             # the README's status table, in WORK/shipped/summary.txt
#
# BIN (default target/release/cog-gpu, built first) is the binary that runs: point it at a copy to keep
# rebuilding the checkout while the script runs. WORK (default /tmp/cog-gpu-repro) receives the data
# sets, models, detections and logs; nothing in the checkout is changed (copy WORK/models/models/*.json,
# after `small` the nine of WORK/small/models/, and after `cascade` and `exclusion` WORK/small/cascade.json, to
# assets/models/ to ship new models).
# Data (all 320x240, seeds never shared between sets):
#   train        1000 frames, seed 1000, synth's default room mix;
#   train-more   1000 more, seed 1001, the same mix, frames renamed more-N: the bookshelf trains on both
#                (WORK/train2000 links the two; README "The shipped models", twice the training frames);
#   calibration   220 frames (held out: fits each model's score calibration): 40 of the default mix (seed
#                 1500), 20 bathrooms (1501), 10 bedrooms (1502), so that bathtubs and toilets occur, and the
#                 150-frame validation set (default mix, seed 1600) on which training settings were chosen;
#   test          325 frames: 80 of the default mix (seed 2000), 40 bathrooms (2001), 40 bedrooms (2002),
#                 40 living rooms (2003) -- the first 200, listed in WORK/test-first200.txt -- and 60
#                 bathrooms (2004), 45 bedrooms (2005), 20 offices (2006), so that every one of the ten
#                 categories has at least 30 test boxes (bathtub and dresser 30, bookshelf 33);
#   cascade-set 2000 frames (held out: trains the context cascade): 80 of the default mix (seed 1700),
#                 40 bathrooms (1701), 40 bedrooms (1702), 40 living rooms (1703), as the test set; and 120
#                 of the default mix (1704), 60 bathrooms (1705), 60 bedrooms (1706), 60 living rooms (1707);
#                 then the same 500 again with seeds 1708-1715 (frames dmixed-*, dbath-*, ..., dliving2-*),
#                 and twice more with seeds 1716-1723 (emixed-*, ...) and 1724-1731 (fmixed-*, ...): 2000,
#                 the CASCADE_BLOCKS (default 4) blocks of 500; up to 8 blocks (4000 frames, seeds up to
#                 1763, frames gmixed-* to jliving2-*) for `cascade` and `shipped-cascade` -- a larger set
#                 keeps the smaller one's frames and their detections (detected on, not again).
#   selection     325 frames (held out: fits the cascade's cross-category exclusion and its final calibration;
#                 `exclusion` and `final` modes only),
#                 composed as the test set with seeds 2500-2506.
# ANNOTATE (default visible) is synth's --annotate rule for every set: the shipped models' sets were made
# by generator synth-1, which annotated every object with enough visible pixels, depth or not; synth's
# default now is `depth` (only objects the sensor sees; README "Synthetic scenes"). `models` also
# evaluates the test detections against WORK/test-depth, the test set's annotations under the depth rule
# (the same images).
# Timings in the README were measured with this script on the 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/cog-gpu-repro}
ANNOTATE=${ANNOTATE:-visible}
BIN=${BIN:-target/release/cog-gpu}
# NORMALS (default kdtree, the shipped models') is every `train`'s --normals: kdtree-40 trains on the 40
# nearest neighbours' normals (README, "Normals"; not shipped). The models record it and `detect` follows
# them; the models of one directory must agree, so give it to `models` and `small` alike.
NORMALS=${NORMALS:-kdtree}
NORMALS_ARGS=(--normals "$NORMALS")
CASCADE_BLOCKS=${CASCADE_BLOCKS:-4}
case "$CASCADE_BLOCKS" in
    [1-8]) ;;
    *) echo "CASCADE_BLOCKS must be 1 to 8 (blocks of 500 cascade-set frames), not '$CASCADE_BLOCKS'" >&2; exit 1 ;;
esac
mode=${1:-models}
# shipped-cascade's comparisons read JSON with python3 (its standard library only): checked before the
# hours of detection and training rather than after them.
if [ "$mode" = shipped-cascade ] && ! command -v python3 > /dev/null; then
    echo "reproduce-models.sh shipped-cascade: python3 is needed to compare the cascade files (e.g. apt-get" \
        "install python3); nothing was run" >&2
    exit 1
fi
export NODEVICE_SELECT=1 RUST_LOG=${RUST_LOG:-info}

cargo build --release --locked
mkdir -p "$WORK"
# synth_set DIR ROOMS FRAMES SEED [PREFIX]: a synthetic set of ROOMS (a --rooms list, or "mixed": synth's
# default mix in SUN RGB-D's proportions), frames renamed PREFIX-N when PREFIX is given (as

# frame names must be unique in a data set, one detections file per name).
synth_set() {
    local dir=$1 rooms=$2 frames=$3 seed=$4 prefix=${5:-}
    [ -d "$dir" ] && return 0
    local room_args=()
    [ "$rooms" = mixed ] || room_args=(--rooms "$rooms")
    "$BIN" synth --out "$dir.partial" --frames "$frames" --seed "$seed" --width 320 --height 240 "${room_args[@]}" \
        --annotate "$ANNOTATE"
    if [ -n "$prefix" ]; then
        for frame in "$dir.partial"/synth-*; do mv "$frame" "${frame/synth-/$prefix-}"; done
    fi
    mv "$dir.partial" "$dir"
}
all_rooms=mixed
synth_set "$WORK/train" "$all_rooms" 1000 1000
synth_set "$WORK/calibration/mixed" "$all_rooms" 40 1500 calib
synth_set "$WORK/calibration/bathroom" bathroom 20 1501 calib-bathroom
synth_set "$WORK/calibration/bedroom" bedroom 10 1502 calib-bedroom
synth_set "$WORK/calibration/validation" "$all_rooms" 150 1600 calib-val
synth_set "$WORK/test/mixed" "$all_rooms" 80 2000 mixed
synth_set "$WORK/test/bathroom" bathroom 40 2001 bathroom
synth_set "$WORK/test/bedroom" bedroom 40 2002 bedroom
synth_set "$WORK/test/living_room" living_room 40 2003 living
synth_set "$WORK/test/bathroom-2" bathroom 60 2004 bathroom2
synth_set "$WORK/test/bedroom-2" bedroom 45 2005 bedroom2
synth_set "$WORK/test/office" office 20 2006 office
# The same 325 test frames annotated by synth's depth rule (objects the sensor sees; README, "The
# annotation rule, measured"): the same images, fewer boxes.
for subset in mixed:mixed:80:2000:mixed bathroom:bathroom:40:2001:bathroom bedroom:bedroom:40:2002:bedroom \
    living_room:living_room:40:2003:living bathroom-2:bathroom:60:2004:bathroom2 \
    bedroom-2:bedroom:45:2005:bedroom2 office:office:20:2006:office; do
    IFS=: read -r name rooms frames seed prefix <<< "$subset"
    ANNOTATE=depth synth_set "$WORK/test-depth/$name" "$rooms" "$frames" "$seed" "$prefix"
done
# The test set of the earlier READMEs (before the last three subsets): `eval --split` compares with them.
(cd "$WORK/test" && find mixed bathroom bedroom living_room -mindepth 1 -maxdepth 1 -type d | sort) \
    > "$WORK/test-first200.txt"
# Extra `train` arguments per category (models mode only): more training examples where they were
# measured to help on the validation set (README, "The shipped models").
declare -A CATEGORY_ARGS=()
# A category's training set when not WORK/train (models mode; the nine small ones all train on WORK/train).
declare -A CATEGORY_DATA=()
# The calibrations and the context cascade are fitted on detections without box voting (`detect`'s
# default since 2026-12-04, after they were fitted; README, "Box voting"): the calibration and cascade
# sets are detected with it off, so that the script reproduces the shipped files (with voting on, the
# box's calibration alone comes out a = 10.69 instead of 11.27). The test sets are detected as `detect`
# does by default, with voting. The markers below name the rule, so that a WORK whose calibration or
# cascade detections were voted (by this script between 2026-12-04 and 2026-12-05) is detected again.
# Since 2026-12-07 `detect` searches a second floor where the floor is not seen (README, "The floor where
# it is not seen"), also after the shipped calibrations, cascade and exclusion were fitted: their sets are
# detected on the lowest points' floor alone (`--unseen-floor off`), as they were, and so are the test sets
# of the modes whose tables were measured before (models, small, cascade); only `shipped` measures the
# pipeline as `detect` runs it today. Files detected before 2026-12-07 are those of `--unseen-floor off`,
# so the markers of those sets stay; the shipped first stage's names the second floor (FLOOR_MARK; `-2`
# since the rule also takes lowest points less than 1 m below the camera for no floor, 2026-12-07, afternoon).
FIT=(--box-voting off --unseen-floor off)
FIT_MARK=unvoted
ONE_FLOOR=(--unseen-floor off)
FLOOR_MARK=unseen-floor-2
# First-stage files (`detect --no-cascade`) carry the cross scores since 2026-12-05, which the shipped
# cascade's v7 stages read (docs/measurements.md, "Feature set v7, the cross scores"): the cascade and test detections'
# markers say so, and a WORK detected before (files without them) is detected again by `cascade`.
CROSS_MARK=cross-scores
# train_and_eval NAME CATEGORIES TEST CALIBRATE TRAIN_ARGS...: trains each category into WORK/NAME/models/;
# when CALIBRATE is "yes", detects on WORK/calibration and fits the models' calibrations; then detects on
# WORK/TEST and writes WORK/NAME/ap.txt, ap.json, diagnosis.txt and precision-recall plots.
train_and_eval() {
    local name=$1 categories=$2 test=$3 calibrate=$4
    shift 4
    local dir="$WORK/$name"
    mkdir -p "$dir/models"
    for category in ${categories//,/ }; do
        local started=$SECONDS
        local resume=()
        [ -f "$dir/models/$category.json.ckpt" ] && resume=(--resume)
        if [ ! -f "$dir/models/$category.json" ]; then
            local extra=()
            read -r -a extra <<< "${CATEGORY_ARGS[$category]:-}"
            "$BIN" train --data "${CATEGORY_DATA[$category]:-$WORK/train}" --category "$category" \
                --out "$dir/models/$category.json" \
                "${resume[@]}" "${NORMALS_ARGS[@]}" "$@" "${extra[@]}" 2> "$dir/$category.log"
            echo "$name $category $((SECONDS - started)) s" >> "$dir/times.txt"
        fi
    done
    if [ "$calibrate" = yes ]; then
        local started=$SECONDS
        # The marker holds the number of calibration frames detected, so that a WORK made before the
        # calibration set grew is detected again.
        local frames
        frames=$(find "$WORK/calibration" -mindepth 2 -maxdepth 2 -type d | wc -l)
        if [ "$(cat "$dir/calibration-detections/.done" 2>/dev/null)" != "$frames $FIT_MARK" ]; then
            "$BIN" detect "$WORK/calibration" --models "$dir/models" --out "$dir/calibration-detections" \
                --min-score -3 --no-overlay "${FIT[@]}" > /dev/null
            echo "$frames $FIT_MARK" > "$dir/calibration-detections/.done"
        fi
        "$BIN" calibrate --data "$WORK/calibration" --detections "$dir/calibration-detections" \
            --models "$dir/models" | tee "$dir/calibration.txt"
        echo "$name calibrate $((SECONDS - started)) s" >> "$dir/times.txt"
    fi
    local started=$SECONDS
    # Uncalibrated models (the ablation's) are detected without box voting: box voting demotes the boxes its
    # second NMS would drop by 6 raw units for such a model, under the cut (README, "Box voting"; `detect`
    # warns), and the ablation was measured before voting existed (2026-11-24).
    local test_options=()
    [ "$calibrate" = yes ] || test_options=(--box-voting off)
    "$BIN" detect "$WORK/$test" --models "$dir/models" --out "$dir/detections" --min-score -3 --no-overlay \
        "${ONE_FLOOR[@]}" "${test_options[@]}" > /dev/null
    echo "$name detect $((SECONDS - started)) s" >> "$dir/times.txt"
    # AP with 90 % bootstrap intervals over the test frames (1 000 resamples, seed 0).
    "$BIN" eval --data "$WORK/$test" --detections "$dir/detections" --categories "$categories" \
        --plots "$dir/pr" --bootstrap 1000 | tee "$dir/ap.txt"
    if [ "$test" = test ]; then
        "$BIN" eval --data "$WORK/$test" --detections "$dir/detections" --categories "$categories" \
            --split "$WORK/test-first200.txt" | tee "$dir/ap-first200.txt"
        # The same detections against the depth rule's annotations of the same frames.
        "$BIN" eval --data "$WORK/test-depth" --detections "$dir/detections" --categories "$categories" \
            --bootstrap 1000 | tee "$dir/ap-depth.txt"
    fi
    "$BIN" eval --data "$WORK/$test" --detections "$dir/detections" --categories "$categories" --json \
        > "$dir/ap.json"
    "$BIN" eval --data "$WORK/$test" --detections "$dir/detections" --categories "$categories" --diagnose \
        --models "$dir/models" | tee "$dir/diagnosis.txt"
}

# selection_set: WORK/selection, 325 held-out frames composed as the test set with seeds 2500-2506 (fits the
# cascade's cross-category exclusion and its final calibration; `exclusion` and `final` modes).
selection_set() {
    local subset name rooms frames seed prefix
    for subset in mixed:mixed:80:2500:mixed bathroom:bathroom:40:2501:bathroom bedroom:bedroom:40:2502:bedroom \
        living_room:living_room:40:2503:living bathroom-2:bathroom:60:2504:bathroom2 \
        bedroom-2:bedroom:45:2505:bedroom2 office:office:20:2506:office; do
        IFS=: read -r name rooms frames seed prefix <<< "$subset"
        [ "$rooms" = mixed ] && rooms=$all_rooms
        synth_set "$WORK/selection/$name" "$rooms" "$frames" "$seed" "$prefix"
    done
}

# selection_first: WORK/final/selection-first, the selection set's first-stage files of the shipped models as
# `detect` makes them today (the second floor searched, box voting; about 30 min on the 2-core machine),
# made when missing or made by an earlier rule (`final` and `shipped-cascade` modes).
selection_first() {
    selection_set
    if [ "$(cat "$WORK/final/selection-first/.done" 2>/dev/null)" != "$CROSS_MARK $FLOOR_MARK" ]; then
        local started=$SECONDS
        rm -rf "$WORK/final/selection-first"
        mkdir -p "$WORK/final"
        "$BIN" detect "$WORK/selection" --models assets/models --out "$WORK/final/selection-first" --min-score -3 \
            --no-overlay --no-cascade > /dev/null
        echo "$CROSS_MARK $FLOOR_MARK" > "$WORK/final/selection-first/.done"
        echo "final: selection detect $((SECONDS - started)) s" >> "$WORK/final/times.txt"
    fi
}

# cascade_set: WORK/cascade-set, the held-out frames that train the context cascade (`cascade` and
# `shipped-cascade` modes): CASCADE_BLOCKS blocks of 500 (default 4, the shipped cascade's 2 000 frames).
cascade_set() {
    local block letter seed first second index spec rooms short frames suffix tag room_arg
    # Blocks of 500 frames composed the same way (80 of the default mix, 40 bathrooms, 40 bedrooms, 40
    # living rooms, then 120, 60, 60, 60; the 200-frame set starved the second stage, and each doubling
    # since helped: README "Context cascade"), block b's eight sets seeded 1700 + 8b, in order, frames
    # prefixed by the block's letter (c, d, e, f, then g, h, i, j), directories suffixed "" and -2, -3 and
    # -4, ..., -15 and -16. A set made with more blocks holds the smaller one's frames unchanged.
    block=0
    for letter in c d e f g h i j; do
        [ "$block" -lt "$CASCADE_BLOCKS" ] || break
        seed=$((1700 + 8 * block))
        first=$([ $block = 0 ] && echo "" || echo "-$((2 * block + 1))")
        second="-$((2 * block + 2))"
        index=0
        for spec in mixed:mixed:80:"$first": bathroom:bath:40:"$first": bedroom:bed:40:"$first": \
            living_room:living:40:"$first": mixed:mixed:120:"$second":2 bathroom:bath:60:"$second":2 \
            bedroom:bed:60:"$second":2 living_room:living:60:"$second":2; do
            IFS=: read -r rooms short frames suffix tag <<< "$spec"
            room_arg=$rooms
            [ "$rooms" = mixed ] && room_arg=$all_rooms
            synth_set "$WORK/cascade-set/$rooms$suffix" "$room_arg" "$frames" $((seed + index)) "$letter$short$tag"
            index=$((index + 1))
        done
        block=$((block + 1))
    done
}

# cascade_set_frames: the number of frames in WORK/cascade-set.
cascade_set_frames() {
    find "$WORK/cascade-set" -mindepth 2 -maxdepth 2 -type d | wc -l
}

# cascade_first MODELS OUT TIMES: the cascade set's first-stage files of MODELS in OUT, detected as the
# shipped stages' files were (no box voting, one floor: FIT), the time appended to TIMES. The marker holds
# the number of frames and the rules: files of an earlier rule are detected again from scratch; a set that
# grew (more CASCADE_BLOCKS) and a run interrupted before its marker was written go on where they stopped
# (`detect --resume` detects only the frames without a file; the cascade set takes hours).
cascade_first() {
    local models=$1 out=$2 times=$3 started=$SECONDS done_marker
    local marker
    marker="$(cascade_set_frames) $FIT_MARK $CROSS_MARK"
    done_marker=$(cat "$out/.done" 2>/dev/null || true)
    [ "$done_marker" = "$marker" ] && return 0
    local resume=()
    if [ -n "$done_marker" ] && [ "${done_marker#* }" != "${marker#* }" ]; then
        rm -rf "$out"
    elif [ -d "$out" ]; then
        rm -f "$out/.done"
        resume=(--resume)
    fi
    "$BIN" detect "$WORK/cascade-set" --models "$models" --out "$out" --min-score -3 --no-overlay --no-cascade \
        "${FIT[@]}" "${resume[@]}" > /dev/null
    echo "$marker" > "$out/.done"
    echo "cascade set detected into $out: $((SECONDS - started)) s" >> "$times"
}

case "$mode" in
    shipped)
        # The README's status table ("Where it stands") and "The shipped pipeline today": the shipped models,
        # calibrations and cascade, detected on the test set (about 30 min on the 2-core machine; a rerun
        # keeps the first-stage files), rescored, and evaluated against both annotation rules of the same
        # frames; the support surfaces of the first stage; the scores as probabilities (reliability bins) of
        # the first stage and the cascade; the sample frames' best detections.
        dir="$WORK/shipped"
        mkdir -p "$dir"
        started=$SECONDS
        if [ "$(cat "$dir/first/.done" 2>/dev/null)" != "$CROSS_MARK $FLOOR_MARK" ]; then
            rm -rf "$dir/first"
            "$BIN" detect "$WORK/test" --models assets/models --out "$dir/first" --min-score -3 --no-overlay \
                --no-cascade > /dev/null
            echo "$CROSS_MARK $FLOOR_MARK" > "$dir/first/.done"
            echo "shipped detect $((SECONDS - started)) s" >> "$dir/times.txt"
        fi
        rm -rf "$dir/rescored"
        "$BIN" rescore --detections "$dir/first" --out "$dir/rescored" --cascade assets/models/cascade.json
        for rule in visible:test depth:test-depth; do
            IFS=: read -r name data <<< "$rule"
            for stage in first rescored; do
                "$BIN" eval --data "$WORK/$data" --detections "$dir/$stage" --bootstrap 1000 \
                    > "$dir/ap-ten-$name-$stage.txt"
                "$BIN" eval --data "$WORK/$data" --detections "$dir/$stage" --categories all --bootstrap 1000 \
                    > "$dir/ap-all-$name-$stage.txt"
            done
            "$BIN" eval --data "$WORK/$data" --detections "$dir/rescored" --diagnose > "$dir/diagnosis-$name.txt"
        done
        # The scores as probabilities (`eval --diagnose`'s reliability bins), all 19 categories, `visible`:
        # the first stage's calibrations and the cascade's.
        for stage in first rescored; do
            "$BIN" eval --data "$WORK/test" --detections "$dir/$stage" --categories all --diagnose \
                > "$dir/diagnosis-all-visible-$stage.txt"
        done
        "$BIN" eval --data "$WORK/test" --detections "$dir/first" --surfaces \
            --categories bed,table,desk,dresser,nightstand > "$dir/surfaces.txt"
        "$BIN" detect assets/sample --models assets/models --out "$dir/sample" > "$dir/sample.txt"
        {
            echo "The shipped pipeline on WORK/test ($(find "$WORK/test" -mindepth 2 -maxdepth 2 -type d | wc -l) frames),"
            echo "AP@0.25 with 90 % bootstrap intervals; first stage, then with the cascade."
            for name in visible depth; do
                for stage in first rescored; do
                    echo "$name, $stage: ten large $(grep '^mAP' "$dir/ap-ten-$name-$stage.txt" | tail -1 | tr -s " ")"
                    echo "$name, $stage: 19 categories $(grep '^mAP' "$dir/ap-all-$name-$stage.txt" | tail -1 | tr -s " ")"
                done
                echo "$name $(grep '^overlay precision' "$dir/diagnosis-$name.txt")"
            done
            for stage in first rescored; do
                echo "visible, $stage, 19 categories, $(sed -n '/^scores as probabilities/,$p' \
                    "$dir/diagnosis-all-visible-$stage.txt")"
            done
            echo "first stage, $(sed -n '/^support surfaces/,$p' "$dir/surfaces.txt")"
            echo "sample frames:"
            cat "$dir/sample.txt"
        } | tee "$dir/summary.txt"
        ;;
    models)
        # `train`'s defaults are the shipped models' settings, with more examples for the categories in
        # CATEGORY_ARGS; detection uses the models' own step (0.2 m; 0.1 m for the nightstand, whose
        # model is trained as the others and detects with the finer window: README, "The shipped models").
        CATEGORY_ARGS[chair]="--positives 320 --negatives 200"
        # 200 frames without a dresser instead of 60 (every usable instance is already taken):
        # chosen on the calibration set (docs/measurements.md, "More negatives for the dresser and the bookshelf").
        CATEGORY_ARGS[dresser]="--negatives 200"
        # The bookshelf on twice the training frames, every usable instance (254) and 200 frames without
        # one: chosen on a 1 500-frame selection set (docs/measurements.md, "The bookshelf on twice the frames").
        synth_set "$WORK/train-more" "$all_rooms" 1000 1001 more
        mkdir -p "$WORK/train2000"
        ln -sfn ../train "$WORK/train2000/a"
        ln -sfn ../train-more "$WORK/train2000/b"
        CATEGORY_DATA[bookshelf]="$WORK/train2000"
        CATEGORY_ARGS[bookshelf]="--positives 300 --negatives 200"
        # The toilet on the same 2 000 frames with `train`'s defaults: chosen on a 300-bathroom selection
        # set (docs/measurements.md, "The toilet on twice the frames, shipped").
        CATEGORY_DATA[toilet]="$WORK/train2000"
        # The sofa on the same 2 000 frames, every usable instance (288) and 200 frames without one:
        # chosen on the 1 500-frame selection set (docs/measurements.md, "The sofa on twice the frames, shipped").
        CATEGORY_DATA[sofa]="$WORK/train2000"
        CATEGORY_ARGS[sofa]="--positives 300 --negatives 200"
        # The table with latent support surfaces (paper §4), trained by CCCP from its cuboid model, which
        # is trained first with the same defaults: chosen on the 1 500-frame selection set
        # (docs/measurements.md, "The table's latent surfaces, shipped").
        mkdir -p "$WORK/cuboid"
        if [ ! -f "$WORK/cuboid/table.json" ]; then
            cuboid_resume=()
            [ -f "$WORK/cuboid/table.json.ckpt" ] && cuboid_resume=(--resume)
            "$BIN" train --data "$WORK/train" --category table --out "$WORK/cuboid/table.json" \
                "${cuboid_resume[@]}" "${NORMALS_ARGS[@]}" 2> "$WORK/cuboid/table.log"
        fi
        CATEGORY_ARGS[table]="--surfaces-from $WORK/cuboid/table.json"
        CATEGORY_ARGS[nightstand]="--detect-step 0.1"
        # The bathtub on the lattice of centres aligned with the walls (README, "The bathtub on the walls
        # lattice").
        CATEGORY_ARGS[bathtub]="--lattice walls"
        # The shipped layout model (assets/reproduce-layout.sh) sits beside them, so that every detections
        # file carries the frame's room, which the cascade's layout features read.
        mkdir -p "$WORK/models/models"
        cp assets/models/layout.json "$WORK/models/models/"
        train_and_eval models bed,chair,sofa,table,desk,toilet,bathtub,dresser,nightstand,bookshelf test yes
        ;;
    ablation)
        five=bed,bathtub,nightstand,chair,toilet
        # Smaller training runs (30 instances, 15 negative frames, 0.3 m training step, 2 full passes),
        # evaluated on the full 325-frame test set (bed 83, chair 183, toilet 45, nightstand 51, bathtub 30
        # boxes), so that paired differences of a few points are beyond the bootstrap's noise.
        small=(--positives 30 --negatives 15 --max-full-passes 2 --step 0.3)
        train_and_eval ablation-geom "$five" test no "${small[@]}" --groups geom --no-expand
        train_and_eval ablation-cog "$five" test no "${small[@]}" --groups cog --no-expand
        train_and_eval ablation-geom-cog "$five" test no "${small[@]}" --groups geom,cog --no-expand
        train_and_eval ablation-geom-cog-view "$five" test no "${small[@]}" --groups geom,cog,view --no-expand
        train_and_eval ablation-expanded "$five" test no "${small[@]}" --groups geom,cog,view
        # Paired bootstrap differences (same 1 000 resamples of the test frames for both rows).
        for pair in cog:geom geom-cog:cog geom-cog-view:geom-cog expanded:geom-cog-view; do
            IFS=: read -r this that <<< "$pair"
            "$BIN" eval --data "$WORK/test" --detections "$WORK/ablation-$this/detections" \
                --categories "$five" --bootstrap 1000 --versus "$WORK/ablation-$that/detections" \
                | tee "$WORK/ablation-$this-vs-$that.txt"
        done
        ;;
    cascade)
        # The context cascade (paper section 6) over the 19 models of `models` and `small` (run those
        # first): first-stage detections of the cascade set, the cascade trained on them (`--features
        # best-cross`: per category the best of v4, v5, v6 and v7 by cross-validation; `--keep nested-gain`:
        # a category's stage only where that choice gains in a nested cross-validation; on the 2 000 frames
        # about 3 h 40 min of detection and 60 min of training on the 2-core machine (3 595 s);
        # interrupted, a rerun resumes from the stage checkpoints in WORK/small/cascade.json.stages)
        # (WORK/small/cascade.json; copy it to assets/models/ to ship it), the test set's first-stage
        # detections of the 19 (from `small`) rescored, and both evaluated.
        dir="$WORK/small"
        nineteen=bed,chair,sofa,table,desk,toilet,bathtub,dresser,nightstand,bookshelf
        nineteen=$nineteen,box,door,counter,garbage_bin,pillow,lamp,tv,monitor,sink
        [ -f "$dir/detections/.done" ] || { echo "run the models and small modes first" >&2; exit 1; }
        # The layout features need the room in every detections file, and v7 the cross scores: a WORK
        # whose `small` ran without the layout model beside the detectors, or before the cross scores, gets
        # it and its test set detected again.
        if [ ! -f "$dir/models/layout.json" ] || [ "$(cat "$dir/detections/.done" 2>/dev/null)" != "$CROSS_MARK" ]; then
            [ -f "$dir/models/layout.json" ] || cp assets/models/layout.json "$dir/models/"
            "$BIN" detect "$WORK/test" --models "$dir/models" --out "$dir/detections" --min-score -3 \
                --no-overlay --no-cascade "${ONE_FLOOR[@]}" > /dev/null
            echo "$CROSS_MARK" > "$dir/detections/.done"
        fi
        cascade_set
        cascade_first "$dir/models" "$dir/cascade-detections" "$dir/times.txt"
        "$BIN" cascade --data "$WORK/cascade-set" --detections "$dir/cascade-detections" --models "$dir/models" --features best-cross \
            --keep nested-gain --out "$dir/cascade.json" | tee "$dir/cascade.txt"
        rm -rf "$dir/cascade-test-detections"
        "$BIN" rescore --detections "$dir/detections" --out "$dir/cascade-test-detections" --cascade "$dir/cascade.json"
        # AP with 90 % intervals, and the paired difference to the first stage on the same resamples.
        "$BIN" eval --data "$WORK/test" --detections "$dir/cascade-test-detections" --categories "$nineteen" \
            --bootstrap 1000 --versus "$dir/detections" | tee "$dir/cascade-ap.txt"
        "$BIN" eval --data "$WORK/test" --detections "$dir/cascade-test-detections" --categories "$nineteen" \
            --diagnose | tee "$dir/cascade-diagnosis.txt"
        "$BIN" eval --data "$WORK/test-depth" --detections "$dir/cascade-test-detections" \
            --categories "$nineteen" --bootstrap 1000 --versus "$dir/detections" | tee "$dir/cascade-ap-depth.txt"
        ;;
    final)
        # The shipped cascade's final calibration (README "The cascade's final calibration"), nothing trained:
        # the selection set detected by the shipped first stage as `shipped` detects the test set (about 30
        # min on the 2-core machine; a rerun keeps the files), and the final calibration of
        # assets/models/cascade.json fitted again on it (its stages and exclusion as they are; the file's
        # own final calibration is not read by the fit) into WORK/final/cascade.json -- the shipped file
        # (but for the data paths it names) when the shipped models and cascade are what made it; the fit's
        # report in WORK/final/final.txt.
        dir="$WORK/final"
        selection_first
        "$BIN" calibrate --cascade assets/models/cascade.json --final --data "$WORK/selection" \
            --detections "$dir/selection-first" --out "$dir/cascade.json" | tee "$dir/final.txt"
        # The files name the frames they were fitted on ("data"): compared without those lines.
        if cmp -s <(grep -v '"data": ' "$dir/cascade.json") <(grep -v '"data": ' assets/models/cascade.json); then
            echo "WORK/final/cascade.json is the shipped assets/models/cascade.json, byte for byte but for the" \
                "data paths" | tee -a "$dir/final.txt"
        else
            echo "WORK/final/cascade.json differs from assets/models/cascade.json" | tee -a "$dir/final.txt"
        fi
        ;;
    shipped-cascade)
        # The shipped cascade's stages trained again from the shipped first stage, nothing else trained: the
        # cascade set (as `cascade` makes it) detected by assets/models -- the 19 models and the layout
        # model -- as the shipped stages' files were (`--box-voting off --unseen-floor off`, the FIT options;
        # about 2.5 h on the 2-core machine; an interrupted run goes on where it stopped, `detect
        # --resume`), then `cascade --features best-cross --keep nested-gain` on them into
        # WORK/shipped-cascade/cascade.json (about 1 h; its stage checkpoints resume likewise; kept when
        # it exists and was trained on as many frames), compared stage by stage with the shipped file and,
        # on the selection set, by AP (WORK/shipped-cascade/selection-ap*.txt). With CASCADE_BLOCKS=8 the
        # same on 4 000 frames (the 2 000 first-stage files kept, 2 000 more detected): a larger set's
        # cascade against the shipped one. WORK/shipped-cascade/first is what a changed model's
        # cascade-set detections are merged into before the cascade is trained again (README "Changing a
        # shipped model": the script's `cascade` mode trains on its own models instead, whose monitor and
        # sink differ from the shipped ones).
        dir="$WORK/shipped-cascade"
        mkdir -p "$dir"
        cascade_set
        cascade_first assets/models "$dir/first" "$dir/times.txt"
        started=$SECONDS
        # A cascade trained on another number of frames (CASCADE_BLOCKS changed) is trained again.
        if [ -f "$dir/cascade.json" ] \
            && [ "$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["training"]["frames"])' \
                "$dir/cascade.json")" != "$(cascade_set_frames)" ]; then
            rm "$dir/cascade.json"
        fi
        if [ ! -f "$dir/cascade.json" ]; then
            "$BIN" cascade --data "$WORK/cascade-set" --detections "$dir/first" --models assets/models \
                --features best-cross --keep nested-gain --out "$dir/cascade.json" | tee "$dir/cascade.txt"
            echo "shipped-cascade: train $((SECONDS - started)) s" >> "$dir/times.txt"
        fi
        # The shipped file also holds the cross-category exclusion and the final calibration (fitted after
        # its stages, on the selection set: the `exclusion` and `final` modes' commands) and names the
        # directories it was trained on; everything else is compared.
        python3 - "$dir/cascade.json" assets/models/cascade.json <<'PY' | tee -a "$dir/cascade.txt"
import json, sys
def comparable(path):
    cascade = json.load(open(path))
    for key in ("exclusion", "final_calibration"):
        cascade.pop(key, None)
    training = cascade["training"]
    training.pop("data"); training.pop("detections")
    for calibration in training.get("calibrations", {}).values():
        calibration.pop("data", None)
    return cascade
trained, shipped = comparable(sys.argv[1]), comparable(sys.argv[2])
if trained == shipped:
    print("WORK/shipped-cascade/cascade.json has the shipped cascade's stages, to the last digit")
else:
    print("WORK/shipped-cascade/cascade.json differs from the shipped cascade in:",
          ", ".join(key for key in sorted(set(trained) | set(shipped)) if trained.get(key) != shipped.get(key)))
    for category in sorted(set(trained["stages"]) | set(shipped["stages"])):
        if trained["stages"].get(category) != shipped["stages"].get(category):
            print("  the stage of", category, "differs")
PY
        # Stages that differ (first-stage files changed by the code since the shipped cascade was trained,
        # e.g. the support surfaces of 2026-12-06) are judged by what they do: the selection set's shipped
        # first stage (as the `final` mode detects it; made here when missing) rescored by the shipped
        # cascade and by the retrained stages with the shipped exclusion and final calibration, compared.
        selection_first
        python3 - "$dir/cascade.json" assets/models/cascade.json "$dir/cascade-with-shipped-rules.json" <<'PY'
import json, sys
trained, shipped = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
for key in ("exclusion", "final_calibration"):
    if key in shipped:
        trained[key] = shipped[key]
json.dump(trained, open(sys.argv[3], "w"), indent=2)
PY
        for which in shipped retrained; do
            cascade=assets/models/cascade.json
            [ "$which" = retrained ] && cascade="$dir/cascade-with-shipped-rules.json"
            rm -rf "$dir/selection-$which"
            "$BIN" rescore --detections "$WORK/final/selection-first" --out "$dir/selection-$which" --cascade "$cascade"
        done
        "$BIN" eval --data "$WORK/selection" --detections "$dir/selection-retrained" --categories all --bootstrap 1000 \
            --versus "$dir/selection-shipped" | tee "$dir/selection-ap.txt"
        "$BIN" eval --data "$WORK/selection" --detections "$dir/selection-retrained" --bootstrap 1000 \
            --versus "$dir/selection-shipped" | tee "$dir/selection-ap-ten.txt"
        ;;
    exclusion)
        # The cascade's cross-category exclusion (README "Cross-category exclusion"), after `cascade`: the
        # selection set's first-stage files of the 19 (about 46 min on the 2-core machine), the exclusion's
        # IoU and weight fitted on them into WORK/small/cascade.json (its stages unchanged; a rerun fits
        # again, the fit reads only the stages), and the test set's first-stage files rescored with it and
        # evaluated against the cascade mode's rescoring, which has no exclusion.
        dir="$WORK/small"
        [ -f "$dir/cascade.json" ] && [ -d "$dir/cascade-test-detections" ] \
            || { echo "run the cascade mode first" >&2; exit 1; }
        nineteen=bed,chair,sofa,table,desk,toilet,bathtub,dresser,nightstand,bookshelf
        nineteen=$nineteen,box,door,counter,garbage_bin,pillow,lamp,tv,monitor,sink
        selection_set
        started=$SECONDS
        if [ "$(cat "$dir/selection-detections/.done" 2>/dev/null)" != "$CROSS_MARK" ]; then
            "$BIN" detect "$WORK/selection" --models "$dir/models" --out "$dir/selection-detections" \
                --min-score -3 --no-overlay --no-cascade "${ONE_FLOOR[@]}" > /dev/null
            echo "$CROSS_MARK" > "$dir/selection-detections/.done"
            echo "selection detect $((SECONDS - started)) s" >> "$dir/times.txt"
        fi
        "$BIN" calibrate --cascade "$dir/cascade.json" --exclusion --data "$WORK/selection" \
            --detections "$dir/selection-detections" --models "$dir/models" | tee "$dir/exclusion.txt"
        rm -rf "$dir/exclusion-test-detections"
        "$BIN" rescore --detections "$dir/detections" --out "$dir/exclusion-test-detections" --cascade "$dir/cascade.json"
        "$BIN" eval --data "$WORK/test" --detections "$dir/exclusion-test-detections" --categories "$nineteen" \
            --bootstrap 1000 --versus "$dir/cascade-test-detections" | tee "$dir/exclusion-ap.txt"
        "$BIN" eval --data "$WORK/test" --detections "$dir/exclusion-test-detections" --bootstrap 1000 \
            --versus "$dir/cascade-test-detections" | tee "$dir/exclusion-ap-ten.txt"
        "$BIN" eval --data "$WORK/test" --detections "$dir/exclusion-test-detections" --diagnose \
            | tee "$dir/exclusion-diagnosis.txt"
        ;;
    small)
        # The nine other categories of the paper's Table 2, after `models` (whose ten calibrated models
        # carry the support surfaces): box, door, counter and garbage bin with the floor window (train's
        # defaults; doors with the lattice of centres on the walls, `--lattice walls`; boxes 3x3x3 at
        # 0.1 m); pillows, lamps and TVs with the free window (`--support free`: every bottom from the
        # floor to 1.5 m); monitor searched on the support surfaces of its supporters' detections
        # (`--support surfaces`; `train` takes as supporters the surface categories its positives stand
        # on: desks), sink on its supporters' (counters) and on the floor (`--support floor+surfaces`:
        # pedestal sinks and basins on counters); the paper's grids
        # (3x3x3 pillows and lamps, 3x1x3 monitors and TVs; 3x3x3 sinks). The floor and free ones are
        # calibrated first, so that the counters' calibrated scores choose the surfaces the sinks are
        # searched on; then the surface two; then the test set with all nineteen models, evaluated.
        # Since 2026-11-28 the measured support surfaces find the surface under a cover (a bed's mattress
        # under its duvet), and the surface models train on those surfaces, so the monitor and sink this
        # mode trains differ from the shipped ones (equal within the noise on the test set; the shipped
        # files stay because the cascade is tied to them: docs/measurements.md, "Small objects: numbers"). Likewise since
        # 2026-12-06 a table's, desk's, dresser's or nightstand's surface is its highest face with a fifth
        # of the fullest face's points (`top_surface_height`), which moves some desks' surfaces and so the
        # monitor's training examples (README, "Surfaces measured from the points").
        dir="$WORK/small"
        large=bed,chair,sofa,table,desk,toilet,bathtub,dresser,nightstand,bookshelf
        floor=box,door,counter,garbage_bin,pillow,lamp,tv
        surfaces=monitor,sink
        [ -f "$WORK/models/models/bed.json" ] || { echo "run the models mode first" >&2; exit 1; }
        mkdir -p "$dir/models"
        for category in ${large//,/ }; do cp "$WORK/models/models/$category.json" "$dir/models/"; done
        # The room layout model beside them, so that the test detections carry the frame's room (the
        # cascade's layout features read it).
        cp assets/models/layout.json "$dir/models/"
        # Windows (README, "Small objects on support surfaces", "The free window" and "Hypotheses"): pillows,
        # lamps and monitors detect with a 0.1 m centre step (trained at 0.2 m), chosen on the calibration
        # set, as the pillows', lamps' and TVs' free window, the doors' lattice and the boxes' 3x3x3 grid
        # trained and detected at 0.1 m; TVs and sinks with 0.2 m. Pillows and lamps, trained on the free
        # window, detect on its resting boxes (`--detect-support resting`: on the floor or on a top seen
        # around them; README, "The free window"), chosen on the calibration set; TVs, which hang on walls,
        # on the whole free window.
        declare -A WINDOW=([pillow]="--support free --grid 3x3x3 --detect-step 0.1 --detect-support resting"
            [door]="--lattice walls" [box]="--grid 3x3x3 --step 0.1 --detect-step 0.1"
            [lamp]="--support free --grid 3x3x3 --detect-step 0.1 --detect-support resting"
            [monitor]="--support surfaces --grid 3x1x3 --detect-step 0.1" [tv]="--support free --grid 3x1x3"
            [sink]="--support floor+surfaces --grid 3x3x3")
        for category in ${floor//,/ } ${surfaces//,/ }; do
            [ -f "$dir/models/$category.json" ] && continue
            started=$SECONDS
            resume=()
            [ -f "$dir/models/$category.json.ckpt" ] && resume=(--resume)
            window=()
            if [ -n "${WINDOW[$category]:-}" ]; then
                read -r -a window <<< "${WINDOW[$category]}"
            fi
            "$BIN" train --data "$WORK/train" --category "$category" --out "$dir/models/$category.json" \
                "${resume[@]}" "${window[@]}" "${NORMALS_ARGS[@]}" 2> "$dir/$category.log"
            echo "small $category $((SECONDS - started)) s" >> "$dir/times.txt"
        done
        for group in floor surfaces; do
            categories=${!group}
            started=$SECONDS
            if [ "$(cat "$dir/calibration-$group/.done" 2>/dev/null)" != "$FIT_MARK" ]; then
                # --categories brings the surface categories' models along for the surface group.
                "$BIN" detect "$WORK/calibration" --models "$dir/models" --categories "$categories" \
                    --out "$dir/calibration-$group" --min-score -3 --no-overlay --no-cascade "${FIT[@]}" > /dev/null
                echo "$FIT_MARK" > "$dir/calibration-$group/.done"
            fi
            "$BIN" calibrate --data "$WORK/calibration" --detections "$dir/calibration-$group" \
                --models "$dir/models" --categories "$categories" | tee "$dir/calibration-$group.txt"
            echo "small calibrate $group $((SECONDS - started)) s" >> "$dir/times.txt"
        done
        started=$SECONDS
        if [ ! -f "$dir/detections/.done" ]; then
            "$BIN" detect "$WORK/test" --models "$dir/models" --out "$dir/detections" --min-score -3 --no-overlay \
                --no-cascade "${ONE_FLOOR[@]}" > /dev/null
            echo "$CROSS_MARK" > "$dir/detections/.done"
            echo "small detect $((SECONDS - started)) s" >> "$dir/times.txt"
        fi
        nine=$floor,$surfaces
        "$BIN" eval --data "$WORK/test" --detections "$dir/detections" --categories "$large,$nine" \
            --bootstrap 1000 | tee "$dir/ap.txt"
        "$BIN" eval --data "$WORK/test-depth" --detections "$dir/detections" --categories "$large,$nine" \
            --bootstrap 1000 | tee "$dir/ap-depth.txt"
        "$BIN" eval --data "$WORK/test" --detections "$dir/detections" --categories "$nine" --diagnose \
            --models "$dir/models" | tee "$dir/diagnosis.txt"
        ;;
    *)
        echo "usage: bash assets/reproduce-models.sh [models|ablation|small|cascade|exclusion|final|shipped]" >&2
        exit 2
        ;;
esac
