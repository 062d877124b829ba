#!/bin/bash
# Writes the READINGS / INTERVAL / UNSEEN / FEATURES / REFUSED lines of
# `examples/contact_diagnosis.rs` for scans, for `interval_calibration.py`:
# - a folder holding `map/mesh.ply` and named WORLD-ROCK (a `rings_experiment.sh` output) is read
#   with `--mesh`, labelled gt_<parent>_<folder>;
# - any other folder is read as a campaign (`runs/WORLD/seed-S/...`), labelled camp_<folder>_...
#
# usage: [BIN=contact_diagnosis] collect_readings.sh FRAGILITY_TOML OUT FOLDER...   (FRAGILITY_TOML may be "")
# e.g.   collect_readings.sh "" r.txt exp/v0/* camp/scarp_lib23
#        interval_calibration.py r.txt
set -e
T=$1; O=$2; shift 2
BIN=${BIN:-target/release/examples/contact_diagnosis}   # or the BIN of the environment
: > "$O"
for d in "$@"; do
  d=${d%/}
  if [ -f "$d/map/mesh.ply" ]; then
    t=$(basename "$d"); w=${t%-*}; r=${t##*-}
    "$BIN" --mesh "$d/map/mesh.ply" "$w" "$r" "gt_$(basename "$(dirname "$d")")_$t" $T >> "$O"
  else
    "$BIN" "$d" "$T" 2>/dev/null | grep "^READINGS\|^FEATURES\|^UNSEEN\|^INTERVAL" |
      sed "s/^\(READINGS\|FEATURES\|UNSEEN\|INTERVAL\) /\1 camp_$(basename "$d")_/" >> "$O"
  fi
done
