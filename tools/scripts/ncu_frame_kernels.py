#!/usr/bin/env python3
"""Kernel time per TSDF frame from an Nsight Compute CSV:
   ncu --clock-control none --cache-control none --metrics gpu__time_duration.sum --csv \
       --launch-skip 400 --launch-count 240 build_gpu/benchmark_tsdf --device cuda --integrations 12 --skip-lidar > f.csv
   tools/scripts/ncu_frame_kernels.py f.csv [FIRST]
Frames are cut at each kernel whose name contains FIRST (default: the depth image's unproject
kernel; the merged method reads the image in its first kernel, pass "tsdf_merge_rays" with ncu's
--kernel-name-base demangled), where the kernel before it does not; prints each whole frame's
kernel count and time (us), then the last whole frame's kernels one by one."""
import csv,signal,sys
signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # quiet under `| head`
rows=list(csv.reader(open(sys.argv[1])))
hdr=None; out=[]
for r in rows:
    if r and r[0]=='ID': hdr=r; continue
    if hdr and len(r)==len(hdr):
        d=dict(zip(hdr,r)); out.append((int(d['ID']),d['Kernel Name'],float(d['Metric Value'].replace(',',''))/1000))
first=sys.argv[2] if len(sys.argv)>2 else 'unproject'
starts=[k for k,(i,n,t) in enumerate(out) if first in n and (k==0 or first not in out[k-1][1])]
for a,b in zip(starts,starts[1:]):
    fr=out[a:b]; print(b-a, round(sum(t for _,_,t in fr),1))
a,b=starts[-2],starts[-1]
for i,n,t in out[a:b]:
    n=n.replace('void covox::parallel_for_kernel<','pf<')
    print(f"{t:6.1f}  {n if len(n) <= 110 else n[:60] + ' ... ' + n[-45:]}")
