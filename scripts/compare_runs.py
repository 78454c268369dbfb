#!/usr/bin/env python3
"""Compares two runs of the same checks side by side (scripts/gpu_before_after.sh).

  compare_runs.py tests BEFORE.md AFTER.md   GPU test tables: rows matched by (test, scene, view,
                                             pipeline); PSNR, errors and render lists must agree
  compare_runs.py bench DIR                  catgs-bench JSON {before,after}_SCENE_PATH.json in DIR:
                                             mean and p99 frame times, per-frame render lists and
                                             snapshots (snap_{before,after}_SCENE_PATH/*.png),
                                             then the mean stage times before -> after
Prints markdown tables. Every file may be gzipped (name ending in .gz: BEFORE.md.gz, before_*.json.gz).
"""
import filecmp, glob, gzip, json, os, sys


def open_text(path):
    """A result file, plain or gzipped (name ending in .gz)."""
    return gzip.open(path, 'rt') if path.endswith('.gz') else open(path)


def table_rows(path):
    rows = {}
    for line in open_text(path):
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) < 11 or cells[0] in ('test', '---') or cells[0].startswith('-'):
            continue
        rows[tuple(cells[:4])] = cells
    return rows


def tests(before, after):
    b, a = table_rows(before), table_rows(after)
    same = differ = 0
    print('| test | scene | view | pipeline | before (PSNR, max err, 8-bit, lists, result) | after | same |')
    print('|---|---|---|---|---|---|---|')
    for key in sorted(set(b) | set(a)):
        vb = b.get(key, ['-'] * 11)[4:10]
        va = a.get(key, ['-'] * 11)[4:10]
        ok = vb == va
        same += ok
        differ += not ok
        if not ok:
            print('| %s | %s | %s |' % (' | '.join(key), ' / '.join(vb), ' / '.join(va)) + (' yes |' if ok else ' **no** |'))
    print('\n%d rows identical (PSNR, errors, render lists, result), %d differ or exist on one side only' % (same, differ))


def bench(d):
    print('| scene, path | pipeline | before ms (p99) | after ms (p99) | after / before | pre-processing + keys ms, before -> after | lists | snapshot |')
    print('|---|---|---|---|---|---|---|---|')
    stage_rows = []
    for fb in sorted(glob.glob(os.path.join(d, 'before_*.json')) + glob.glob(os.path.join(d, 'before_*.json.gz')),
                     key=lambda f: f.removesuffix('.gz')):
        tag = os.path.basename(fb).removesuffix('.gz')[len('before_'):-len('.json')]
        fa = os.path.join(d, 'after_%s.json' % tag)
        fa = fa if os.path.exists(fa) else fa + '.gz'
        if not os.path.exists(fa):
            print('| %s | (no after run) |' % tag)
            continue
        jb, ja = json.load(open_text(fb)), json.load(open_text(fa))
        pa = {p['pipeline']: p for p in ja['pipelines']}
        for p in jb['pipelines']:
            name = p['pipeline']
            q = pa.get(name)
            if q is None:
                continue
            mb, ma = p['frame_ms']['mean'], q['frame_ms']['mean']
            lists = ('-' if 'per_frame_render_list' not in p or 'per_frame_render_list' not in q  # stripped
                     else 'same' if p['per_frame_render_list'] == q['per_frame_render_list'] else '**differ**')
            snaps = [f for f in glob.glob(os.path.join(d, 'snap_before_%s' % tag, '*%s.png' % name))]
            snap = '-'
            for sb in snaps:
                sa = os.path.join(d, 'snap_after_%s' % tag, os.path.basename(sb))
                snap = 'same' if os.path.exists(sa) and filecmp.cmp(sb, sa, shallow=False) else '**differ**'
            def front(r):  # the per-Gaussian stages, where chunk culling shows
                st = r.get('stages_ms_mean', {})
                return st.get('preprocess', 0.0) + st.get('keys', 0.0)
            print('| %s | %s | %.3f (%.3f) | %.3f (%.3f) | %.3f | %.3f -> %.3f | %s | %s |' % (
                tag, name, mb, p['frame_ms']['p99'], ma, q['frame_ms']['p99'], ma / mb, front(p), front(q), lists,
                snap))
            stage_rows.append((tag, name, p.get('stages_ms_mean', {}), q.get('stages_ms_mean', {})))
    stages = ('preprocess', 'keys', 'sort', 'tile_ranges', 'rasterize')
    print('\n| scene, path | pipeline | ' + ' | '.join('%s ms' % s for s in stages) + ' |')
    print('|---|---|' + '---|' * len(stages))
    for tag, name, sb, sa in stage_rows:
        print('| %s | %s | ' % (tag, name) + ' | '.join(
            '%.3f -> %.3f' % (sb.get(s, 0.0), sa.get(s, 0.0)) for s in stages) + ' |')


if __name__ == '__main__':
    if len(sys.argv) >= 4 and sys.argv[1] == 'tests':
        tests(sys.argv[2], sys.argv[3])
    elif len(sys.argv) >= 3 and sys.argv[1] == 'bench':
        bench(sys.argv[2])
    else:
        sys.exit(__doc__)
