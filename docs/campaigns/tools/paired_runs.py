# Paired comparison of two campaigns flown with two configs on the same runs.
# usage: paired_runs.py DIR_A[,DIR_A2...] DIR_B[,DIR_B2...]
import json, glob, sys
def runs(path):
    out={}
    for mj in sorted(glob.glob(path+'/runs/*/seed-*/mission.json')):
        j=json.load(open(mj)); run=mj.split('/runs/')[1][:-13].rstrip('/')
        flown=[t for t in j['targets'] if t.get('gt_role')=='target' and t['status'] in ('mapped','incomplete')]
        mapped=[t for t in flown if t['status']=='mapped']
        f2=[t['fscore_2cm'] for t in flown if t.get('fscore_2cm') is not None]
        aerr=[t['alpha_error_deg'] for t in mapped if t.get('alpha_error_deg') is not None]
        inside=sum(1 for t in mapped if t.get('alpha_min_low_deg') is not None and t['alpha_min_low_deg']<=t['alpha_min_gt_deg']<=t['alpha_min_high_deg'])
        loc=[t['localization_error_estimate_frame_m'] for t in flown if t.get('localization_error_estimate_frame_m') is not None]
        ntrue=len([r for r in json.load(open(mj.replace('mission.json','world_gt/world.json')))['rocks'] if r['role']=='target'])
        out[run]=dict(sim=j['sim_time_s'],mapped=len(mapped),ntrue=ntrue,col=j['collisions'],clr=j['min_clearance_m'],
            within2=sum(abs(a)<=2 for a in aerr), over3=sum(a>3 for a in aerr), inside=inside, nint=len(aerr),
            f2min=min(f2) if f2 else None, loc05=sum(l<=0.5 for l in loc), nloc=len(loc), end=j['end_reason'])
    return out
P={}; S={}
for d in sys.argv[1].split(','): P.update(runs(d))
for d in sys.argv[2].split(','): S.update(runs(d))
print('| run | preset | sim s | mapped | collisions | min clearance m | \\|α err\\| ≤ 2° | over +3° | truth in interval | worst F@2cm | loc ≤ 0.5 m (estimate frame) |')
print('|---|---|---|---|---|---|---|---|---|---|---|')
tot={'paper':[0]*8,'scarp':[0]*8}
for run in sorted(set(P)&set(S)):
    for name,R in (('paper',P),('scarp',S)):
        r=R[run]
        print('| %s | %s | %.0f | %d/%d | %d | %.2f | %d/%d | %d | %d/%d | %s | %d/%d |'%(run,name,r['sim'],r['mapped'],r['ntrue'],r['col'],r['clr'],r['within2'],r['ntrue'],r['over3'],r['inside'],r['nint'],'%.3f'%r['f2min'] if r['f2min'] else '-',r['loc05'],r['nloc']))
        t=tot[name]; 
        for i,k in enumerate(['mapped','ntrue','col','within2','over3','inside','nint','loc05']): t[i]+=r[k]
for name,t in tot.items():
    print(name,'mapped %d/%d collisions %d within2 %d over3 %d inside %d/%d loc05 %d'%tuple(t))
