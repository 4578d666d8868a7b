#!/usr/bin/env python3
# The SfM's poses against a COLMAP model of the same drive, on the frames both posed
# (docs/figures.md F33). Pure Python.
#   python3 scripts/sfm_vs_colmap.py DRIVE COLMAP_TEXT_MODEL|- [OURS_POSES.tum ...] [--rate 15]
# The COLMAP model holds one image per camera and frame, named f<frame>_c<camera>.png (frame
# the drive's six-digit frame name, camera the index in rig.json). A frame is posed by COLMAP
# when at least one of its images is registered; its rig centre is the mean over those images of
# the camera centre moved by the camera's offset (the offsets in COLMAP's units from a first
# similarity of the camera centres to the truth). Each trajectory's rig centres on the common
# frames are registered to the truth (gt/poses.tum) by a similarity (Horn) and the RMS of the
# residuals is printed in cm and in % of the drive's length (the truth's path over all frames).
import json, math, os, re, sys


def qmat(w, x, y, z):
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


def mv(A, x): return [sum(A[i][k] * x[k] for k in range(3)) for i in range(3)]
def tr(A): return [[A[j][i] for j in range(3)] for i in range(3)]
def add(a, b): return [a[i] + b[i] for i in range(3)]
def sub(a, b): return [a[i] - b[i] for i in range(3)]
def scl(s, a): return [s * c for c in a]
def dot(a, b): return sum(a[i] * b[i] for i in range(3))


def read_tum(path, rate):
    poses = {}
    for line in open(path):
        f = line.split()
        if not f or f[0].startswith('#'): continue
        t, x, y, z, qx, qy, qz, qw = map(float, f[:8])
        poses[int(round(t * rate))] = (qmat(qw, qx, qy, qz), [x, y, z])
    return poses


def jacobi_max_eigenvector(N):
    A = [row[:] for row in N]; n = 4
    V = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    for _ in range(100):
        off = sum(A[i][j] ** 2 for i in range(n) for j in range(n) if i != j)
        if off < 1e-30: break
        for p in range(n):
            for q in range(p + 1, n):
                if abs(A[p][q]) < 1e-300: continue
                theta = (A[q][q] - A[p][p]) / (2 * A[p][q])
                t = (1 if theta >= 0 else -1) / (abs(theta) + math.sqrt(theta * theta + 1))
                c = 1 / math.sqrt(t * t + 1); s = t * c
                for k in range(n):
                    akp, akq = A[k][p], A[k][q]
                    A[k][p], A[k][q] = c * akp - s * akq, s * akp + c * akq
                for k in range(n):
                    apk, aqk = A[p][k], A[q][k]
                    A[p][k], A[q][k] = c * apk - s * aqk, s * apk + c * aqk
                for k in range(n):
                    vkp, vkq = V[k][p], V[k][q]
                    V[k][p], V[k][q] = c * vkp - s * vkq, s * vkp + c * vkq
    i = max(range(n), key=lambda k: A[k][k])
    return [V[k][i] for k in range(n)]


def similarity(src, dst):
    """s, R, t minimising sum |s R src + t - dst|^2 (Horn's quaternion method)."""
    n = len(src)
    ms = scl(1.0 / n, [sum(p[i] for p in src) for i in range(3)])
    md = scl(1.0 / n, [sum(p[i] for p in dst) for i in range(3)])
    a = [sub(p, ms) for p in src]; b = [sub(p, md) for p in dst]
    S = [[sum(a[k][i] * b[k][j] for k in range(n)) for j in range(3)] for i in range(3)]
    Sxx, Sxy, Sxz = S[0]; Syx, Syy, Syz = S[1]; Szx, Szy, Szz = S[2]
    N = [[Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx],
         [Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz],
         [Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy],
         [Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz]]
    q = jacobi_max_eigenvector(N)
    R = qmat(*q)
    s = sum(dot(b[k], mv(R, a[k])) for k in range(n)) / sum(dot(p, p) for p in a)
    t = sub(md, scl(s, mv(R, ms)))
    return s, R, t


def ate(src, dst):
    s, R, t = similarity(src, dst)
    e = [sub(add(scl(s, mv(R, p)), t), q) for p, q in zip(src, dst)]
    return math.sqrt(sum(dot(d, d) for d in e) / len(e)), s


def main():
    args = sys.argv[1:]; rate = 15.0
    if '--rate' in args:
        i = args.index('--rate'); rate = float(args[i + 1]); del args[i:i + 2]
    drive, model, ours = args[0], args[1], args[2:]
    rig = json.load(open(os.path.join(drive, 'rig.json')))
    cam_from_rig = []
    for c in rig['cameras']:
        q = c['cam_from_rig']['q_wxyz']; cam_from_rig.append((qmat(*q), c['cam_from_rig']['t']))
    gt = read_tum(os.path.join(drive, 'gt', 'poses.tum'), rate)
    frames = sorted(gt)
    length = sum(math.sqrt(dot(sub(gt[frames[i + 1]][1], gt[frames[i]][1]),
                               sub(gt[frames[i + 1]][1], gt[frames[i]][1])))
                 for i in range(len(frames) - 1))
    images = []  # (frame, camera, R_world_from_cam, centre)
    if model == '-':  # no COLMAP model: each trajectory against the truth on all its frames
        print(f'drive {drive}: {len(frames)} frames, length {length:.2f} m')
        for p in ours:
            t = read_tum(p, rate); fs = [f for f in sorted(t) if f in gt]
            rms, _ = ate([t[f][1] for f in fs], [gt[f][1] for f in fs])
            print(f'{p}: {len(fs)} frames; ATE {100 * rms:.2f} cm, {100 * rms / length:.4f} %')
        return
    lines = [l for l in open(os.path.join(model, 'images.txt')) if not l.startswith('#')]
    for k in range(0, len(lines), 2):
        h = lines[k].split()
        if len(h) < 10: continue
        m = re.match(r'f(\d+)_c(\d+)\.', h[9])
        R_cw = qmat(*map(float, h[1:5])); t_cw = list(map(float, h[5:8]))
        R_wc = tr(R_cw); images.append((int(m.group(1)), int(m.group(2)), R_wc,
                                        scl(-1.0, mv(R_wc, t_cw))))
    images = [im for im in images if im[0] in gt]
    # Truth camera centre: world_from_rig * (cam centre in rig) = R_wr * (-R_cr^T t_cr) + t_wr.
    def gt_cam_centre(f, c):
        R_cr, t_cr = cam_from_rig[c]; R_wr, t_wr = gt[f]
        return add(mv(R_wr, scl(-1.0, mv(tr(R_cr), t_cr))), t_wr)
    cam_rms, s = ate([im[3] for im in images], [gt_cam_centre(im[0], im[1]) for im in images])
    # Rig origin in the world = world_from_cam * (rig origin in the camera) = R_wc t_cr + C.
    by_frame = {}
    for f, c, R_wc, C in images:
        by_frame.setdefault(f, []).append(add(C, scl(1.0 / s, mv(R_wc, cam_from_rig[c][1]))))
    colmap = {f: scl(1.0 / len(v), [sum(p[i] for p in v) for i in range(3)])
              for f, v in by_frame.items()}
    print(f'drive {drive}: {len(frames)} frames, length {length:.2f} m')
    print(f'colmap: {len(images)} images of {len(by_frame)} frames registered; camera-centre RMS '
          f'{100 * cam_rms:.2f} cm over its images')
    if len(by_frame) >= 3:
        fs = sorted(by_frame)
        rms, _ = ate([colmap[f] for f in fs], [gt[f][1] for f in fs])
        print(f'colmap: ATE on its {len(fs)} frames {100 * rms:.2f} cm, '
              f'{100 * rms / length:.4f} % of the length')
    for p in ours:
        t = read_tum(p, rate)
        common = sorted(f for f in colmap if f in t)
        if len(common) < 3:
            print(f'{p}: {len(t)} frames posed, {len(common)} in common'); continue
        g = [gt[f][1] for f in common]
        ours_rms, _ = ate([t[f][1] for f in common], g)
        colmap_rms, _ = ate([colmap[f] for f in common], g)
        print(f'{p}: {len(t)} frames posed, {len(common)} common with colmap: ATE ours '
              f'{100 * ours_rms:.2f} cm ({100 * ours_rms / length:.4f} %), colmap '
              f'{100 * colmap_rms:.2f} cm ({100 * colmap_rms / length:.4f} %), ratio '
              f'{ours_rms / max(colmap_rms, 1e-12):.2f}')

if __name__ == '__main__':
    main()
