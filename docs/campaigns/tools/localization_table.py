# Table of localization_by_noise.sh results: estimate-frame error per case and estimator.
# usage: localization_table.py RES_DIR
import json, glob, collections, statistics as st, sys
res=collections.defaultdict(dict)
for f in sorted(glob.glob(sys.argv[1] + '/*.json')):
    key=f.split('/')[-1][:-5]
    world,rest=key.rsplit('-',3)[0],key.rsplit('-',3)[1:]
    target,seed,cfg=rest
    try: j=json.load(open(f))
    except Exception: continue
    # the one target matching the rock
    ts=[t for t in j['targets'] if t.get('gt_rock_id')==int(target)]
    conv=[t for t in ts if t['status']=='converged']
    t=(conv or ts or [None])[0]
    res[(world,target,seed)][cfg]=(t and t.get('localization_error_estimate_frame_m'), t and t['status'], len(ts), t and t.get('centroid_error_m'))
cfgs=['exact','position','attitude','gps']
print('%-22s'%'case'+''.join('%18s'%c for c in cfgs))
for k,v in sorted(res.items()):
    print('%-22s'%'-'.join(k)+''.join('%18s'%(('%.2f %s%s'%(v[c][0] or float('nan'),v[c][1][:4],'' if v[c][2]==1 else '×%d'%v[c][2])) if c in v and v[c][1] else '-') for c in cfgs))
for c in cfgs:
    e=[v[c][0] for v in res.values() if c in v and v[c][0] is not None]
    if e: print(c,'n',len(e),'median %.2f'%st.median(e),'p90 %.2f'%sorted(e)[int(0.9*(len(e)-1))],'max %.2f'%max(e),'<=0.5: %d/%d'%(sum(x<=0.5 for x in e),len(e)))
