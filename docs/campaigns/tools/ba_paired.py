"""Keyframe ATE before and after BA for every target of two campaigns flown on the same seeds.

    python3 ba_paired.py CAMPAIGN_A CAMPAIGN_B

Pairs targets by world, seed and rock id, and prints per campaign the median ATE before and
after BA, how many targets BA left worse than their odometry and the largest rise, then one row
per target (before, after A, after B; a `*` marks a target B leaves worse than its odometry).
"""
import json,glob,sys,statistics as st
def rows(c):
    out={}
    for f in sorted(glob.glob(c+'/runs/*/seed-*/mission.json')):
        d=json.load(open(f)); w=f.split('/')[-3]; s=f.split('/')[-2]
        for t in d['targets']:
            a,b=t.get('ate_before_ba_m'),t.get('ate_after_ba_m')
            if a is None or b is None: continue
            out[(w,s,t['id'])]=(a*1e3,b*1e3,t.get('fscore_2cm'),t.get('alpha_error_deg'))
    return out
A=rows(sys.argv[1]); B=rows(sys.argv[2])
keys=sorted(set(A)&set(B))
print('paired targets',len(keys),'only A',len(set(A)-set(B)),'only B',len(set(B)-set(A)))
for name,R in (('A',A),('B',B)):
    ks=[k for k in keys]
    worse=[k for k in ks if R[k][1]>R[k][0]]
    print(name,'median before %.2f after %.2f'%(st.median(R[k][0] for k in ks),st.median(R[k][1] for k in ks)),'BA worse on',len(worse),'worst rise %.2f mm'%max([R[k][1]-R[k][0] for k in ks]))
print('per target: before(A) afterA afterB | before(B) ; F2 A B')
for k in keys:
    a=A[k]; b=B[k]; flag=' *' if b[1]>b[0] else ''
    print('%-10s %-8s %2d  %6.2f %6.2f %6.2f | %6.2f  F2 %.3f %.3f%s'%(k[0],k[1],k[2],a[0],a[1],b[1],b[0],a[2] or 0,b[2] or 0,flag))
