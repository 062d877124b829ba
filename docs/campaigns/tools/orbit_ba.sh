#!/bin/bash
# Odometry and keyframe BA on 120-frame noisy orbits of rock 1 in each built-in world:
#   orbit_ba.sh BIN OUTROOT BA_CONFIG_TOML_OR_EMPTY SEED...
# Renders each orbit once into $SEQ_DIR (default /tmp/orbit_sequences), runs
# `scarp map --poses odometry --ba` with a ROI around rock 1, and prints the keyframe ATE before
# and after BA, every frame's, the observation count, the odometry's NEES against the truth
# (median, mean), the information scale that would calibrate it, and the landmarks' RMS residual
# at the true poses.
BIN=$1; OUT=$2; CFG=$3; shift 3
declare -A C=([default]="-12.0234,8.0438,-4,4,2.5" [library-a]="-18.0234,-13.9562,0,8,2.5" [library-b]="19.9702,-18.0396,0,8,2.5")
mkdir -p $OUT
for w in default library-a library-b; do for s in "$@"; do
  seq=${SEQ_DIR:-/tmp/orbit_sequences}/$w-$s
  [ -f $seq/rgb.txt ] || $BIN render --world $w --path orbit --frames 120 --seed $s --out $seq >/dev/null 2>&1
  o=$OUT/$w-$s; rm -rf $o
  extra=""; [ -n "$CFG" ] && extra="--ba-config $CFG"
  $BIN map $seq --poses odometry --ba --world $w --roi cyl:${C[$w]} $extra --out $o >/dev/null 2>$o.err
  python3 -c "
import json; d=json.load(open('$o/map.json'))
print('$w-$s', 'kf# %d kf %.2f->%.2f all %.2f->%.2f obs %d nees med %.1f mean %.1f scale %.3f lm truth rms %.3f'%(d['keyframes'],d['ate_rmse_before_ba_m']*1e3,d['ate_rmse_after_ba_m']*1e3,d['ate_rmse_m']*1e3,d['ate_rmse_all_frames_after_ba_m']*1e3,d['ba_observations'],d['odometry_nees_median'],d['odometry_nees_mean'],d['odometry_information_scale_calibrated'],d['ba_landmark_residuals_truth']['rms_px']))"
done; done
