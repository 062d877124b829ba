#!/bin/bash
# Flies the mission's mapping rings around one rock with the true poses, and analyses the scan:
# `scarp plan` (the mission's cylinder, its rings and camera path) -> `scarp render` (sensor noise
# on) -> `scarp map --poses groundtruth` (the mission's 1 cm voxels, 5 m depth, cylinder ROI plus
# its margins) -> `scarp fragility --scan`. The sequence is deleted once mapped (about 0.8 GB).
#
# usage: rings_experiment.sh BIN WORLD ROCK_ID CONFIG OUT_DIR [SEED [OFFSET_M [RADIUS_SCALE]]]
#   CONFIG: a mission TOML (e.g. `map_camera_rate_hz = 5.0` to render a quarter of the frames);
#   OFFSET_M, RADIUS_SCALE: move the cylinder's axis OFFSET_M in a direction drawn from SEED and
#   scale its radius, as a localization error would (default 0 and 1: the truth's cylinder).
# Then: `cargo run --release --example contact_diagnosis -- --mesh OUT_DIR/map/mesh.ply WORLD ROCK_ID LABEL`
set -e
BIN=$1; W=$2; R=$3; C=$4; D=$5; SEED=${6:-0}; OFFSET=${7:-0}; SCALE=${8:-1}
mkdir -p "$D"
"$BIN" --log warn plan --world "$W" --target "$R" --config "$C" --out "$D/plan0" > "$D/plan.log" 2>&1
if [ "$OFFSET" != 0 ] || [ "$SCALE" != 1 ]; then
  read -r TGT RAD HGT < <(python3 - "$D/plan0/flight.json" "$SEED" "$OFFSET" "$SCALE" <<'PY'
import json, math, random, sys
c = json.load(open(sys.argv[1]))['cylinder']
a = random.Random(int(sys.argv[2])).uniform(0, 2 * math.pi); off = float(sys.argv[3])
print('%f,%f,%f' % (c['center_x_m'] + off * math.cos(a), c['center_y_m'] + off * math.sin(a), c['z_bottom_m']),
      c['radius_m'] * float(sys.argv[4]), c['z_top_m'] - c['z_bottom_m'])
PY
)
  "$BIN" --log warn plan --world "$W" --target="$TGT" --radius "$RAD" --height "$HGT" --config "$C" --out "$D/plan" >> "$D/plan.log" 2>&1
else
  mv "$D/plan0" "$D/plan"
fi
"$BIN" --log warn render --world "$W" --path "$D/plan/camera_trajectory.txt" --seed "$SEED" --out "$D/seq" > "$D/render.log" 2>&1
ROI=$(python3 -c "
import json; c = json.load(open('$D/plan/flight.json'))['cylinder']
print('cyl:%f,%f,%f,%f,%f' % (c['center_x_m'], c['center_y_m'], c['z_bottom_m'] - 2, c['z_top_m'] + 2, c['radius_m'] + 1))")
"$BIN" --log warn map "$D/seq" --poses groundtruth --voxel 0.01 --max-depth 5 --roi "$ROI" --out "$D/map" > "$D/map.log" 2>&1
rm -rf "$D/seq"
"$BIN" --log warn fragility "$D/map/mesh.ply" --scan --json > "$D/frag.json" 2> "$D/frag.err" || true
