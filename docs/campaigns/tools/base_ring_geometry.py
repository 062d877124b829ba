#!/usr/bin/env python3
# For each true target with mapping keyframes: how far the lowest keyframe camera flew above the
# true contact (and at what horizontal distance), beside the fragility outcome (base seen in
# fewer than 80% of directions, unseen surface, ok). usage: base_ring_geometry.py CAMPAIGN_DIR...
import json,sys,glob,os,math
rows=[]
for d in sys.argv[1:]:
  for r in glob.glob(d+'/runs/*/seed-*'):
    if not os.path.exists(r+"/mission.json"): continue
    m=json.load(open(r+"/mission.json"))
    w=json.load(open(r+'/world_gt/world.json'))
    rocks={x['id']:x for x in w['rocks']}
    for t in m['targets']:
        if t.get('gt_role')!='target': continue
        kf=r+'/targets/%d/keyframes_groundtruth.txt'%t['id']
        if not os.path.exists(kf): continue
        rock=rocks[t['gt_rock_id']]; c=rock['contact']
        if not c: continue
        poly=c['polygon_xy_m']; cx=sum(p[0] for p in poly)/len(poly); cy=sum(p[1] for p in poly)/len(poly)
        hs=[];ds=[]
        for line in open(kf):
            if line.startswith('#') or not line.strip(): continue
            v=list(map(float,line.split()))
            hs.append(v[3]-c['height_m']); ds.append(math.hypot(v[1]-cx,v[2]-cy))
        err=t.get('error') or ''
        kind='base<80%' if 'directions' in err else ('unseen' if 'no camera saw' in err else ('ok' if t['status']=='mapped' else 'other'))
        n=err.split('in only ')[1].split(' of')[0] if 'in only' in err else ''
        low=[ (h,dd) for h,dd in zip(hs,ds)]
        low.sort()
        print(f"{r.split('/runs/')[1]:18s} rock {t['gt_rock_id']} {rock['shape'][:28]:28s} {kind:9s} {n:3s} base_ring={t.get('base_ring_flown')!s:5s} lowest cam-contact dz {low[0][0]:+.2f} at d {low[0][1]:.2f}; 10th pct dz {sorted(hs)[len(hs)//10]:+.2f}; kfs {len(hs)}")
