#!/usr/bin/env python3
"""The shown-picture table (issue 91) from catgs-shown's JSON: one row a picture, pooled over the
sessions (the three real paths), PSNR and SSIM mean and 5th percentile, and the anchor's bound or
the shown frame's age; with --summary OUT, the JSON without its per-refresh arrays (what
tests/gpu/results/ keeps).

usage: scripts/shown_table.py SHOWN.json [--summary OUT.json]
"""
import json
import sys


def main():
    args = sys.argv[1:]
    if not args:
        sys.exit(__doc__)
    j = json.load(open(args[0]))
    print('| picture | refreshes | PSNR mean | PSNR p5 | SSIM mean | SSIM p5 | bound px / age ms |')
    print('|---|---|---|---|---|---|---|')
    for r in j['pooled']:
        extra = r.get('lod_bound_px_mean', r.get('age_ms_mean', 0))
        print('| %s | %d | %.2f | %.2f | %.4f | %.4f | %.1f |' % (
            r['name'], r['refreshes'], r['psnr_db_mean'], r['psnr_db_p5'], r['ssim_mean'], r['ssim_p5'], extra))
    if '--summary' in args:
        for s in j['sessions']:
            for r in s['rows']:
                r.pop('psnr_db', None)
                r.pop('ssim', None)
        json.dump(j, open(args[args.index('--summary') + 1], 'w'), indent=1)


if __name__ == '__main__':
    main()
