#!/usr/bin/env python3
"""How the α_min intervals of flown campaigns would do with another `interval_margin_deg`.

`fragility::scan::analyze_closed_scan` adds its interval's sources in quadrature, and every
target's `fragility.json` keeps them (`alpha_interval.sources`, 95% half-widths below and above
α_min, `margin` among them). So the interval for another margin m follows from the flown scans
alone: each side becomes sqrt(Σ sources² − margin² + m²). Scans repeated across folders (the
same run flown identically in two arms) count once.

For the shipped margin and each margin given, prints how often the truth falls inside, the
median width and the misses (truth outside: the run, the rock, the signed error and the side
the interval missed by).

With --reanalysed, the scans are those of `reanalyse_fragility.py`'s result files instead (the
same meshes analysed by another build), so a change to the analysis and a margin are judged
together.

usage: margin_sweep.py CAMPAIGN_DIR... [--margins 1.5,1.25,1.0]
       margin_sweep.py --reanalysed RESULT.json... [--margins 1.5,1.25,1.0]
"""
import glob
import json
import math
import os
import statistics
import sys


def scans(dirs):
    """One row per distinct analysed scan of a true target with a known truth."""
    seen, out = set(), []
    for d in dirs:
        for mission_path in sorted(glob.glob(os.path.join(d, '**', 'mission.json'), recursive=True)):
            run_dir = os.path.dirname(mission_path)
            mission = json.load(open(mission_path))
            run = os.path.relpath(run_dir, d)
            for t in mission.get('targets', []):
                if t.get('gt_role') != 'target' or t.get('alpha_min_deg') is None:
                    continue
                if t.get('alpha_min_gt_deg') is None:
                    continue
                path = os.path.join(run_dir, 'targets', str(t['id']), 'fragility.json')
                if not os.path.exists(path):
                    continue
                frag = json.load(open(path))
                sources = (frag.get('alpha_interval') or {}).get('sources')
                if not sources:
                    continue
                key = (mission.get('world'), mission.get('seed'), t['gt_rock_id'],
                       round(t['alpha_min_deg'], 6))
                if key in seen:
                    continue
                seen.add(key)
                out.append({
                    'label': f"{mission.get('world')} {mission.get('seed')} rock {t['gt_rock_id']}",
                    'alpha': t['alpha_min_deg'],
                    'truth': t['alpha_min_gt_deg'],
                    'low': t['alpha_min_low_deg'],
                    'high': t['alpha_min_high_deg'],
                    'sources': sources,
                })
    return out


def reanalysed_scans(paths):
    """One row per distinct analysed mesh of `reanalyse_fragility.py` result files; runs are
    named by their `runs/WORLD/seed-N` folder, so a run flown identically in two arms (the same
    α) counts once."""
    seen, out = set(), []
    for path in paths:
        for r in json.load(open(path)):
            if 'alpha' not in r:
                continue
            run = r['run'].split('/runs/')[-1]
            key = (run, r['rock'], round(r['alpha'], 6))
            if key in seen:
                continue
            seen.add(key)
            out.append({'label': f"{run} rock {r['rock']}", 'alpha': r['alpha'], 'truth': r['gt'],
                        'low': r['low'], 'high': r['high'], 'sources': r['sources']})
    return out


def interval(scan, margin):
    """The scan's interval with the margin source set to `margin` degrees (None: as shipped)."""
    if margin is None:
        return scan['low'], scan['high']
    below = above = 0.0
    for s in scan['sources']:
        b, a = s['below_deg'], s['above_deg']
        if s['name'] == 'margin':
            b = a = margin
        below += b * b
        above += a * a
    return max(scan['alpha'] - math.sqrt(below), 0.0), scan['alpha'] + math.sqrt(above)


def report(rows, margin):
    inside, widths, misses = 0, [], []
    for r in rows:
        low, high = interval(r, margin)
        widths.append(high - low)
        if low <= r['truth'] <= high:
            inside += 1
        else:
            side = 'above' if r['truth'] > high else 'below'
            gap = r['truth'] - high if side == 'above' else low - r['truth']
            misses.append(f"{r['label']} ({r['alpha'] - r['truth']:+.2f}°, truth {gap:.2f}° {side})")
    name = 'shipped' if margin is None else f'margin {margin:.2f}°'
    n = len(rows)
    print(f"{name:>15}: inside {inside}/{n} ({100 * inside / max(n, 1):.0f}%), "
          f"median width {statistics.median(widths):.2f}°; misses: {', '.join(misses) or 'none'}")


def main(argv):
    margins = [1.5, 1.25, 1.0, 0.75]
    dirs = []
    reanalysed = False
    it = iter(argv)
    for a in it:
        if a == '--margins':
            margins = [float(x) for x in next(it).split(',')]
        elif a == '--reanalysed':
            reanalysed = True
        else:
            dirs.append(a)
    if not dirs:
        print(__doc__)
        return 2
    rows = reanalysed_scans(dirs) if reanalysed else scans(dirs)
    errors = [r['alpha'] - r['truth'] for r in rows]
    print(f"{len(rows)} distinct analysed scans; signed error median {statistics.median(errors):+.2f}°, "
          f"within 2° {sum(abs(e) <= 2 for e in errors)}")
    report(rows, None)
    for m in margins:
        report(rows, m)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
