#!/usr/bin/env python3
# Moves a COLMAP text model by a fixed similarity (scale 0.37, a rotation of 2.1 rad about
# (0.3, -0.8, 0.5), a translation (41, -7.5, 12.25)), or moves a binary PLY mesh written by
# omnisculpt back by its inverse, to measure `surface --colmap` in another world frame
# (docs/figures.md F18). Pure Python.
#   python3 scripts/colmap_similarity.py model IN_MODEL OUT_MODEL
#   python3 scripts/colmap_similarity.py ply IN.ply OUT.ply
import sys, struct, math, os, shutil
def axis_angle(ax, a):
    n = math.sqrt(sum(c * c for c in ax)); x, y, z = (c / n for c in ax)
    c, s_, C = math.cos(a), math.sin(a), 1 - math.cos(a)
    return [[c + x*x*C, x*y*C - z*s_, x*z*C + y*s_], [y*x*C + z*s_, c + y*y*C, y*z*C - x*s_], [z*x*C - y*s_, z*y*C + x*s_, c + z*z*C]]
def mul(A, B): return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
def tr(A): return [[A[j][i] for j in range(3)] for i in range(3)]
def app(A, x): return [sum(A[i][k] * x[k] for k in range(3)) for i in range(3)]
def q2m(w, x, y, z):
    return [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)], [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)], [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]
def m2q(m):
    t = m[0][0] + m[1][1] + m[2][2]
    if t > 0:
        S = math.sqrt(t + 1.0) * 2; return (0.25 * S, (m[2][1] - m[1][2]) / S, (m[0][2] - m[2][0]) / S, (m[1][0] - m[0][1]) / S)
    i = max(range(3), key=lambda k: m[k][k]); j, k = (i + 1) % 3, (i + 2) % 3
    S = math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k]) * 2
    q = [0, 0, 0, 0]; q[0] = (m[k][j] - m[j][k]) / S; q[1 + i] = 0.25 * S; q[1 + j] = (m[j][i] + m[i][j]) / S; q[1 + k] = (m[k][i] + m[i][k]) / S
    return tuple(q)
s = 0.37; R = axis_angle([0.3, -0.8, 0.5], 2.1); T = [41.0, -7.5, 12.25]
def fwd(x): y = app(R, x); return [s * y[i] + T[i] for i in range(3)]
def inv(x): return [c / s for c in app(tr(R), [x[i] - T[i] for i in range(3)])]
mode, src, dst = sys.argv[1:4]
if mode == 'model':
    os.makedirs(dst, exist_ok=True); shutil.copy(src + '/cameras.txt', dst + '/cameras.txt')
    out, data = [], []
    for l in open(src + '/images.txt').read().split('\n'):
        (out if l.startswith('#') else data).append(l)
    k = 0
    while k < len(data):
        h = data[k].split()
        if not h: k += 1; continue
        Rcw = q2m(*map(float, h[1:5])); t = list(map(float, h[5:8]))
        C = [-c for c in app(tr(Rcw), t)]
        Rcw2 = mul(Rcw, tr(R)); C2 = fwd(C); t2 = [-c for c in app(Rcw2, C2)]
        q = m2q(Rcw2)
        out.append(' '.join([h[0]] + [repr(v) for v in q] + [repr(v) for v in t2] + h[8:]))
        out.append(data[k + 1] if k + 1 < len(data) else ''); k += 2
    open(dst + '/images.txt', 'w').write('\n'.join(out) + '\n')
    pts = []
    for l in open(src + '/points3D.txt'):
        if l.startswith('#') or not l.strip(): pts.append(l.rstrip('\n')); continue
        f = l.split(); x = fwd(list(map(float, f[1:4])))
        pts.append(' '.join([f[0]] + [repr(v) for v in x] + f[4:]))
    open(dst + '/points3D.txt', 'w').write('\n'.join(pts) + '\n')
else:
    b = open(src, 'rb').read(); e = b.index(b'end_header\n') + len(b'end_header\n')
    nv = int(b[:e].decode().split('element vertex ')[1].split()[0]); body = bytearray(b[e:])
    for v in range(nv):
        struct.pack_into('<3f', body, v * 15, *inv(list(struct.unpack_from('<3f', body, v * 15))))
    open(dst, 'wb').write(b[:e] + bytes(body))
