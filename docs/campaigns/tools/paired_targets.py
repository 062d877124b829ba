#!/usr/bin/env python3
# Target by target, two runs of one world and seed: status, estimate-frame and absolute
# localization error, F@2cm, alpha error. usage: paired_targets.py RUN_A RUN_B [RUN_A2 RUN_B2 ...]
import json,sys
def load(p):
    m=json.load(open(p+'/mission.json'))
    out={}
    for t in m['targets']:
        if t.get('gt_role')!='target': continue
        out[t['gt_rock_id']]=t
    return m,out
for base,new in zip(sys.argv[1::2],sys.argv[2::2]):
    mb,b=load(base); mn,n=load(new)
    print(base,'->',new, 'sim %.0f -> %.0f'%(mb.get('sim_time_s',0),mn.get('sim_time_s',0)), 'collisions',mb.get('collisions'),mn.get('collisions'), 'minclr %.2f %.2f'%(mb.get('min_clearance_m') or -1, mn.get('min_clearance_m') or -1))
    for rid in sorted(set(b)|set(n)):
        def f(t):
            if not t: return 'absent'
            e=t.get('localization_error_estimate_frame_m'); a=t.get('localization_error_m')
            ae=t.get('alpha_error_deg')
            return '%-10s est %s abs %s F2 %s aerr %s frames_conv %s'%(t['status'], '%.2f'%e if e is not None else '-', '%.2f'%a if a is not None else '-', '%.3f'%t['fscore_2cm'] if t.get('fscore_2cm') else '-', '%+.2f'%ae if ae is not None else '-', t.get('localization_converged'))
        print('  rock',rid,'|',f(b.get(rid)),'|',f(n.get(rid)))
