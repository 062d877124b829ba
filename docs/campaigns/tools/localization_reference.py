#!/usr/bin/env python3
# Per target, the localized centre C_e against the true centroid moved by the estimator error
# (estimate - truth, camera position) under four references: the mission's metric, the mean over
# the fine-localization circle, the error at its end, and the mean over its last 30 s; plus the
# drift range within the circle. usage: localization_reference.py RUN_DIR...
import json,sys,bisect,math
def traj(p):
    T=[];P=[]
    for l in open(p):
        if l.startswith('#') or not l.strip(): continue
        v=list(map(float,l.split())); T.append(v[0]); P.append(v[1:4])
    return T,P
rows=[]
for r in sys.argv[1:]:
    m=json.load(open(r+'/mission.json')); w=json.load(open(r+'/world_gt/world.json'))
    rocks={x['id']:x for x in w['rocks']}
    Te,Pe=traj(r+'/trajectory.txt'); Tg,Pg=traj(r+'/groundtruth.txt')
    assert len(Te)==len(Tg)
    modes=m['modes']
    for t in m['targets']:
        if t.get('gt_role')!='target' or t.get('localization_error_estimate_frame_m') is None: continue
        segs=[(modes[i]['time_s'], modes[i+1]['time_s'] if i+1<len(modes) else 1e9) for i in range(len(modes)) if modes[i]['mode']=='fine_localize' and modes[i]['target']==t['id']]
        if not segs: continue
        a,b=segs[-1]
        idx=[i for i,tt in enumerate(Te) if a<=tt<b]
        if not idx: continue
        E=[[Pe[i][k]-Pg[i][k] for k in range(3)] for i in idx]
        mean=[sum(e[k] for e in E)/len(E) for k in range(3)]
        end=E[-1]
        c=rocks[t['gt_rock_id']]['centroid']; ce=t['center']
        d=lambda ref: math.dist(ce,[c[k]+ref[k] for k in range(3)])
        rng=max(math.dist(E[i],E[j]) for i in range(0,len(E),5) for j in range(0,len(E),5))
        last30=[e for e,i in zip(E,idx) if Te[i]>=Te[idx[-1]]-30]
        m30=[sum(e[k] for e in last30)/len(last30) for k in range(3)]
        rows.append((r.split('/runs/')[0]+' '+r.split('/runs/')[1], t['gt_rock_id'], t['localization_error_estimate_frame_m'], d(mean), d(end), d(m30), rng, b-a if b<1e8 else -1, d([0,0,0])))
print('%-40s %4s %7s %7s %7s %7s %7s %6s %6s'%('run','rock','metric','fine_mn','at_end','last30','drift','dur_s','abs'))
for x in rows: print('%-40s %4d %7.2f %7.2f %7.2f %7.2f %7.2f %6.0f %6.2f'%x)
import statistics as st
for k,name in [(2,'metric'),(3,'fine mean'),(4,'at end'),(5,'last 30 s')]:
    v=[x[k] for x in rows]; print(name, 'median %.2f'%st.median(v), '<=0.5: %d/%d'%(sum(1 for y in v if y<=0.5),len(v)), 'worst %.2f'%max(v))
