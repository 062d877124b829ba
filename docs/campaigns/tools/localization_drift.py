# Estimate-frame localization error of each flown target of a campaign, against the
# estimator error averaged over the frames that updated it (as mission.json) and over the
# fine-localization stretch alone, with the estimate drift sd/range over that stretch.
# usage: localization_drift.py CAMPAIGN_DIR
import json, glob, math, sys
A=[];B=[]
def read(p):
    out=[]
    for l in open(p):
        if l.startswith('#'): continue
        f=l.split(); out.append((float(f[0]),[float(x) for x in f[1:4]]))
    return out
for mj in sorted(glob.glob(sys.argv[1]+'/runs/*/seed-*/mission.json')):
    d=mj[:-12]
    j=json.load(open(mj)); w=json.load(open(d+'world_gt/world.json')); rocks={r['id']:r for r in w['rocks']}
    est=read(d+'trajectory.txt'); gt=read(d+'groundtruth.txt')
    modes=j['modes']
    for i,m in enumerate(modes):
        if m['mode']!='fine_localize': continue
        t0=m['time_s']; t1=modes[i+1]['time_s'] if i+1<len(modes) else 1e9
        tid=m['target']; tg=[t for t in j['targets'] if t['id']==tid]
        if not tg or tg[0].get('gt_rock_id') is None: continue
        tg=tg[0]
        dr=[[e[1][k]-g[1][k] for k in range(3)] for e,g in zip(est,gt) if t0<=e[0]<t1]
        if not dr: continue
        mean=[sum(x[k] for x in dr)/len(dr) for k in range(3)]
        sd=[math.sqrt(sum((x[k]-mean[k])**2 for x in dr)/len(dr)) for k in range(3)]
        rg=[max(x[k] for x in dr)-min(x[k] for x in dr) for k in range(3)]
        e=tg.get('estimator_error_at_localization_m')
        c=tg['center']; g=rocks[tg['gt_rock_id']]['centroid']
        res=[c[k]-g[k]-(e[k] if e else 0) for k in range(3)]
        res2=[c[k]-g[k]-mean[k] for k in range(3)]
        A.append(math.sqrt(sum(x*x for x in res))); B.append(math.sqrt(sum(x*x for x in res2)))
        print('fine-mean ref: %.2f | '%B[-1], end='')
        print('%-18s t%-3d rock %d fine %.0f s: drift sd xy %.2f %.2f range xy %.2f %.2f | est_err(loc) %s | residual xy %.2f z %+.2f' % (d.split('/runs/')[1], tid, tg['gt_rock_id'], t1-t0, sd[0], sd[1], rg[0], rg[1], [round(x,2) for x in e] if e else None, math.hypot(res[0],res[1]), res[2]))

print('n',len(A),'<=0.5 with loc-frames mean:',sum(a<=0.5 for a in A),' with fine-circle mean:',sum(b<=0.5 for b in B))
