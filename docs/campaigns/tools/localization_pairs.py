#!/usr/bin/env python3
# Paired by run and true rock: C_e's estimate-frame error (norm, vertical) in each arm; targets
# the mission named duplicates are listed apart.
# usage: localization_pairs.py ARM_A ARM_B [...]
import glob, json, os, sys
arms = sys.argv[1:]
rows = {}
for k, a in enumerate(arms):
    for mj in glob.glob(a + '/runs/*/seed-*/mission.json'):
        run = mj.split('/runs/')[1].rsplit('/', 1)[0]
        for t in json.load(open(mj))['targets']:
            if t.get('gt_rock_id') is None or t.get('localization_offset_estimate_frame_m') is None:
                continue
            if t['status'] == 'duplicate':
                print(f'{a} {run}: target {t["id"]} is a duplicate of rock {t["gt_rock_id"]}')
                continue
            o = t['localization_offset_estimate_frame_m']
            rows.setdefault((run, t['gt_rock_id']), [None] * len(arms))[k] = (
                t['localization_error_estimate_frame_m'], o[2], t['status'])
print('| run | rock | ' + ' | '.join(arms) + ' |')
print('|---|---|' + '---|' * len(arms))
for (run, rock), v in sorted(rows.items()):
    cells = ['%.2f (%+.2f) %s' % (x[0], x[1], '' if x[2] == 'mapped' else x[2]) if x else '–' for x in v]
    print(f'| {run} | {rock} | ' + ' | '.join(cells) + ' |')
