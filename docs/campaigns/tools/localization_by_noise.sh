#!/bin/bash
# Localization error by estimator noise (session 15, #17): for every target of the three
# built-in worlds and seeds 0-1, render a fine-localization circle under each [estimator]
# config in CONFIG_DIR (exact.toml, position.toml, attitude.toml, gps.toml) and localize it.
# usage: localization_by_noise.sh SCARP_BIN CONFIG_DIR OUT_DIR; then localization_table.py OUT_DIR/res
set -u; BIN=$1; CFG=$2; OUT=$3; mkdir -p "$OUT/res"
for world in default library-a library-b; do
  "$BIN" world --world $world --out "$OUT/gt_$world" --log warn >/dev/null
  for target in $(python3 -c "import json,sys; print(\" \".join(str(r[\"id\"]) for r in json.load(open(sys.argv[1]))[\"rocks\"] if r[\"role\"]==\"target\"))" "$OUT/gt_$world/world.json"); do
    for seed in 0 1; do for cfg in exact gps attitude position; do
      key=$world-$target-$seed-$cfg; [ -f "$OUT/res/$key.json" ] && continue
      rm -rf "$OUT/seq"; "$BIN" render --world $world --path finecircle --frames 300 --target $target --seed $seed --config "$CFG/$cfg.toml" --out "$OUT/seq" --log warn >/dev/null || continue
      "$BIN" localize "$OUT/seq" --poses estimate --world $world --out "$OUT/lz" --json --log warn > "$OUT/res/$key.json"
    done; done; done; done
