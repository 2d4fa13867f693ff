#!/usr/bin/env bash
# Re-measures the tables of docs/performance.md and docs/accuracy.md (and, through
# docs/mesh_quality.sh, docs/mesh_quality.md). It takes long (hours with the growth series and
# the benches) and is not run by CI; the figures land in OUT_DIR (default figures/) as the
# reports, CSVs and logs the tables quote, one file per command, so a table row can be checked
# against the file of its command.
#
#     cargo build --release && docs/figures.sh [OUT_DIR]
#
# Environment:
#   ANTIRADIANCE  the binary (default target/release/antiradiance)
#   MESHES        the folder of the seed meshes (default ../shared/meshes); rows that need a
#                 mesh that is not there are skipped with a message
#   RUNS          runs per timed command (default 5; the tables quote min / median / max)
#   PARTS         which parts, in order (default "room accuracy growth fields memory bench
#                 relight mesh_quality")
# Uses only the binary, cargo, bash and coreutils.
set -euo pipefail
cd "$(dirname "$0")/.."
B=${ANTIRADIANCE:-target/release/antiradiance}
MESHES=${MESHES:-../shared/meshes}
RUNS=${RUNS:-5}
PARTS=${PARTS:-room accuracy growth fields memory bench relight mesh_quality}
OUT=${1:-figures}
mkdir -p "$OUT"
ROOM=$MESHES/room_radiosity_small.obj
ROOM_OPTS=(--emit-above 3.65 --albedo 0.75)
say() { echo "figures.sh: $*" >&2; }
have() { [ -f "$1" ] || { say "skipped: $1 is absent"; return 1; }; }

# performance.md, "The seed room": every preset, RUNS runs each (one for accurate).
room() {
  have "$ROOM" || return 0
  for preset in default fast accurate; do
    local runs=$RUNS
    [ "$preset" = accurate ] && runs=1
    for i in $(seq 1 "$runs"); do
      "$B" solve "$ROOM" "${ROOM_OPTS[@]}" --preset "$preset" --quiet \
        --report "$OUT/room_${preset}_$i.json" --triangles "$OUT/room_${preset}_$i.csv"
    done
  done
  for i in $(seq 1 "$RUNS"); do
    "$B" solve "$ROOM" "${ROOM_OPTS[@]}" --no-direct-light --quiet --report "$OUT/room_nodl_$i.json"
  done
  "$B" solve "$ROOM" "${ROOM_OPTS[@]}" --solver dense --no-direct-light --quiet \
    --report "$OUT/room_dense.json" --triangles "$OUT/room_dense.csv"
}

# accuracy.md, "Summary": the references, then each row's solve against them (the error is the
# report's; `compare` prints it too).
accuracy() {
  "$B" reference scenes/cornell_box.obj --max-edge 60 --spp 512 --quiet --triangles "$OUT/cornell_ref.csv"
  "$B" sweep scenes/cornell_box.obj --reference "$OUT/cornell_ref.csv" --repeat 5 --time-axis cpu \
    --csv "$OUT/sweep_cornell.csv" --svg "$OUT/sweep_cornell.svg"
  "$B" sweep scenes/cornell_box.obj --max-edge 60 --reference "$OUT/cornell_ref.csv" --repeat 2 \
    --time-axis cpu --csv "$OUT/sweep_cornell_me60.csv" --svg "$OUT/sweep_cornell_me60.svg"
  if have "$ROOM"; then
    "$B" reference "$ROOM" "${ROOM_OPTS[@]}" --spp 256 --quiet --triangles "$OUT/room_ref.csv"
    "$B" sweep "$ROOM" "${ROOM_OPTS[@]}" --reference "$OUT/room_ref.csv" --time-axis cpu \
      --csv "$OUT/sweep_room.csv" --svg "$OUT/sweep_room.svg"
    "$B" sweep "$ROOM" "${ROOM_OPTS[@]}" --reference "$OUT/room_ref.csv" --time-axis cpu \
      --preset fast,default,accurate --epsilon preset --bins preset \
      --csv "$OUT/sweep_presets.csv" --svg "$OUT/sweep_presets.svg"
  fi
  if have "$MESHES/bear.obj"; then
    "$B" scene in-room "$MESHES/bear.obj" --out "$OUT/bear_room.obj"
    "$B" reference "$OUT/bear_room.obj" --max-edge 1 --spp 512 --quiet --triangles "$OUT/bear_room_ref.csv"
    "$B" sweep "$OUT/bear_room.obj" --reference "$OUT/bear_room_ref.csv" --epsilon preset --bins preset \
      --direct-light on,off --csv "$OUT/sweep_bear_room.csv"
  fi
  cargo test --release --test sweep -- --nocapture > "$OUT/occluder.log" 2>&1
}

# performance.md, "Growth": the subdivided Cornell box from 1k to 4M triangles, the bear in a
# room subdivided, and the error at 66k and 258k against two path-traced references each.
growth() {
  local sizes="1000 4000 16000 64000 256000 1000000 4000000"
  for n in $sizes; do
    "$B" scene cornell-box --triangles "$n" --out "$OUT/cb_$n.obj"
    "$B" solve "$OUT/cb_$n.obj" --quiet --report "$OUT/growth_$n.json" --triangles "$OUT/growth_$n.csv"
  done
  python3 docs/growth.py $(for n in $sizes; do echo "$OUT/growth_$n.json"; done)
  if have "$MESHES/bear.obj"; then
    "$B" scene in-room "$MESHES/bear.obj" --out "$OUT/bear_room.obj"
    "$B" solve "$OUT/bear_room.obj" --quiet --report "$OUT/bear_none.json"
    for l in 1 0.5 0.25 0.125; do
      "$B" solve "$OUT/bear_room.obj" --max-edge "$l" --quiet --report "$OUT/bear_$l.json"
    done
    python3 docs/growth.py "$OUT"/bear_none.json "$OUT"/bear_1.json "$OUT"/bear_0.5.json \
      "$OUT"/bear_0.25.json "$OUT"/bear_0.125.json
  fi
  for n in 64000:1024 256000:256; do
    local size=${n%%:*} spp=${n##*:}
    for seed in 11 12; do
      "$B" reference "$OUT/cb_$size.obj" --spp "$spp" --seed "$seed" --quiet \
        --triangles "$OUT/ref_${size}_$seed.csv" --report "$OUT/ref_${size}_$seed.json"
    done
    python3 docs/rms_error.py "$OUT/growth_$size.csv" "$OUT/ref_${size}_11.csv" \
      "$OUT/ref_${size}_12.csv" --spp "$spp"
  done
}

# performance.md, "Memory budget": the office mesh at the default limit, 2G and 1G.
memory() {
  "$B" scene office --out "$OUT/office.obj"
  "$B" solve "$OUT/office.obj" --quiet --report "$OUT/office_default.json" || true
  "$B" solve "$OUT/office.obj" --memory-limit 2G --quiet --report "$OUT/office_2g.json" || true
  "$B" solve "$OUT/office.obj" --memory-limit 1G --quiet --report "$OUT/office_1g.json" \
    2> "$OUT/office_1g.log" || true
}

# performance.md, criterion tables.
bench() {
  cargo bench --bench solvers > "$OUT/bench_solvers.log" 2>&1
}

# performance.md, "Relighting".
relight() {
  have "$ROOM" || return 0
  local point=(--albedo 0.75 --light point:2,2,1:20,20,20)
  # The table: each mode twice, to the tolerance and with a 100 ms budget per frame.
  for i in 1 2; do
    for budget in "" 100; do
      local b=() tag=$i
      [ -n "$budget" ] && b=(--frame-budget "$budget") && tag=budget_$i
      "$B" relight "$ROOM" "${ROOM_OPTS[@]}" --frames 30 "${b[@]}" --errors --out "$OUT/f" --quiet --report "$OUT/relight_sweep_$tag.json"
      "$B" relight "$ROOM" "${point[@]}" --move-light 0:-3,2.5,-2 --frames 30 "${b[@]}" --errors --out "$OUT/f" --quiet --report "$OUT/relight_move_$tag.json"
      "$B" relight "$ROOM" "${point[@]}" --scale-light 0:0.25 --frames 30 "${b[@]}" --errors --out "$OUT/f" --quiet --report "$OUT/relight_dim_$tag.json"
    done
  done
  "$B" relight "$ROOM" "${ROOM_OPTS[@]}" --frames 40 --hold 10 --frame-budget 100 --errors --out "$OUT/f" --quiet --report "$OUT/relight_sweep_prog.json"
  "$B" relight "$ROOM" "${point[@]}" --move-light 0:-3,2.5,-2 --frames 40 --hold 10 --frame-budget 100 --errors --out "$OUT/f" --quiet --report "$OUT/relight_move_prog.json"
  "$B" relight "$ROOM" "${point[@]}" --scale-light 0:0.25 --frames 40 --hold 10 --frame-budget 100 --errors --out "$OUT/f" --quiet --report "$OUT/relight_dim_prog.json"
  cargo bench --bench relight > "$OUT/bench_relight.log" 2>&1
}

# performance.md, "Receiver fields": each scene with fields (the default) and without
# (--field-ratio 0, the per-element gather), alternated, RUNS runs each.
fields() {
  "$B" scene cornell-box --triangles 256000 --out "$OUT/fields_cb256k.obj" --quiet
  "$B" scene classroom --out "$OUT/fields_classroom.obj" --quiet
  local scenes=("$OUT/fields_cb256k.obj" "$OUT/fields_classroom.obj")
  if have "$ROOM"; then scenes=("$ROOM" "${scenes[@]}"); fi
  for scene in "${scenes[@]}"; do
    local name opts=()
    name=$(basename "$scene" .obj)
    [ "$scene" = "$ROOM" ] && opts=("${ROOM_OPTS[@]}")
    for i in $(seq "$RUNS"); do
      for ratio in 0.3 0; do
        "$B" solve "$scene" "${opts[@]}" --field-ratio "$ratio" --quiet \
          --report "$OUT/fields_${name}_${ratio}_$i.json" --triangles "$OUT/fields_${name}_${ratio}_$i.csv"
      done
    done
  done
  "$B" scene cornell-box --triangles 1000000 --out "$OUT/fields_cb1m.obj" --quiet
  "$B" solve "$OUT/fields_cb1m.obj" --quiet --report "$OUT/fields_cb1m.json"
}

# docs/mesh_quality.md.
mesh_quality() {
  ANTIRADIANCE=$B docs/mesh_quality.sh "$OUT/mesh_quality" > "$OUT/mesh_quality.md"
}

for part in $PARTS; do
  say "$part"
  "$part"
done
say "done: $OUT"
