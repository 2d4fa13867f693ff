#!/usr/bin/env bash
# Mesh quality: solves badly triangulated variants of the same scenes and compares each
# with the well-meshed original, per original triangle.
#
#     cargo build --release && docs/mesh_quality.sh [OUT_DIR]
#
# For the seed room (../shared/meshes/room_radiosity_small.obj --emit-above 3.65 --albedo
# 0.75; skipped with a message when absent) and the shipped Cornell box
# (scenes/cornell_box.obj), it writes every variant (`antiradiance scene variant KIND ...`:
# fan, random, jitter, translate by 1e3 and 1e5, twins, tjunction, huge-tiny), solves the
# original and each variant with default options (`antiradiance solve ... --report R.json
# --triangles T.csv`), maps each variant's result back to the original triangles through its
# map (docs/mesh_quality.py) and prints one markdown table on stdout: input triangles, time
# (the report's time_seconds.total), links (stats.links), links per input triangle, time and
# links as ratios to the original, peak memory (peak_memory_bytes) and the difference from the
# original (the design note's error measure, area-weighted relative L1 over the original's
# non-emissive triangles). Progress goes to stderr.
#
# Each solve runs under `timeout`; one that times out, fails or runs out of its memory limit
# gives a row saying so ("timed out", "failed: <error line>") and the script goes on.
#
# Environment:
#   ANTIRADIANCE  the binary (default target/release/antiradiance)
#   TIMEOUT       seconds per solve (default 300)
#   MEMORY_MB     address-space limit per solve in MB, `ulimit -v` (default 6000; 0: none)
#   ROOM          the seed room (default ../shared/meshes/room_radiosity_small.obj)
#   SCENES        which scenes, in order (default "room cornell")
#   VARIANTS      which variants (default "fan random jitter translate:1e3 translate:1e5 twins
#                 tjunction huge-tiny"; KIND:AMOUNT sets --amount)
# Uses only the binary, bash, coreutils' timeout and python3's standard library.
set -u
cd "$(dirname "$0")/.."

BIN=${ANTIRADIANCE:-target/release/antiradiance}
TIMEOUT=${TIMEOUT:-300}
MEMORY_MB=${MEMORY_MB:-6000}
ROOM=${ROOM:-../shared/meshes/room_radiosity_small.obj}
SCENES=${SCENES:-room cornell}
VARIANTS=${VARIANTS:-fan random jitter translate:1e3 translate:1e5 twins tjunction huge-tiny}
OUT=${1:-mesh_quality}
TABULATE=docs/mesh_quality.py

if [ ! -x "$BIN" ]; then
    echo "error: $BIN: not found; build it first (cargo build --release)" >&2
    exit 1
fi
mkdir -p "$OUT" || exit 1
RUNS="$OUT/runs.tsv"
: > "$RUNS"

# solve NAME OBJ SCENE_OPTIONS...: solves OBJ into $OUT/NAME.json and $OUT/NAME.csv under the
# time and memory limits; prints the status ("ok", "timed out (> N s)", "failed: ...").
solve() {
    local name=$1 obj=$2
    shift 2
    local report="$OUT/$name.json" triangles="$OUT/$name.csv" err="$OUT/$name.stderr"
    rm -f "$report" "$triangles"
    (
        if [ "$MEMORY_MB" != 0 ]; then ulimit -v $((MEMORY_MB * 1024)); fi
        exec env -u RUST_BACKTRACE timeout "$TIMEOUT" "$BIN" solve "$obj" "$@" --quiet --report "$report" --triangles "$triangles"
    ) 2> "$err"
    local rc=$?
    if [ $rc -eq 0 ]; then
        echo "ok"
    elif [ $rc -eq 124 ]; then
        echo "timed out (> $TIMEOUT s)"
    else
        local line
        line=$(grep -m1 -E '^error:|memory allocation' "$err" || tail -n1 "$err")
        line=${line#error: }
        if [ -z "$line" ]; then line="exit code $rc"; fi
        if grep -q 'memory allocation' "$err"; then line="$line (limit $MEMORY_MB MB)"; fi
        echo "failed: ${line//|/\\|}"
    fi
}

for scene in $SCENES; do
    case $scene in
        room)
            mesh=$ROOM
            options=(--emit-above 3.65 --albedo 0.75)
            variant_options=(--albedo 0.75)
            ;;
        cornell)
            mesh=scenes/cornell_box.obj
            options=()
            variant_options=()
            ;;
        *)
            echo "error: unknown scene '$scene' (room, cornell)" >&2
            exit 1
            ;;
    esac
    if [ ! -f "$mesh" ]; then
        echo "skipping $scene: $mesh is absent" >&2
        continue
    fi
    echo "$scene: original" >&2
    status=$(solve "$scene-original" "$mesh" "${options[@]}")
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$scene" original "$status" "$mesh" \
        "$OUT/$scene-original.json" "$OUT/$scene-original.csv" - >> "$RUNS"
    for spec in $VARIANTS; do
        kind=${spec%%:*}
        amount=
        [ "$spec" != "$kind" ] && amount=${spec#*:}
        label=$kind${amount:+ $amount}
        name="$scene-$kind${amount:+-$amount}"
        obj="$OUT/$name.obj"
        echo "$scene: $label" >&2
        if ! env -u RUST_BACKTRACE "$BIN" scene variant "$kind" "$mesh" --out "$obj" ${amount:+--amount "$amount"} \
            "${options[@]}" --quiet 2> "$OUT/$name.variant.stderr"; then
            line=$(grep -m1 '^error:' "$OUT/$name.variant.stderr" || tail -n1 "$OUT/$name.variant.stderr")
            printf '%s\t%s\t%s\t%s\t-\t-\t-\n' "$scene" "$label" "failed: variant: ${line#error: }" "$obj" >> "$RUNS"
            continue
        fi
        # The variant carries the emitter rule's emitters as materials: no rule when solving.
        solve_options=("${variant_options[@]}")
        status=$(solve "$name" "$obj" "${solve_options[@]}")
        printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$scene" "$label" "$status" "$obj" \
            "$OUT/$name.json" "$OUT/$name.csv" "$OUT/$name.map.csv" >> "$RUNS"
    done
done

python3 "$TABULATE" table "$RUNS"
