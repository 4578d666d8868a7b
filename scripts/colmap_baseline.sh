#!/usr/bin/env bash
# COLMAP 3.8 (the Debian package `colmap`, no CUDA) on frames of a drive: the offline peer the
# SfM's poses are measured against (docs/figures.md F33, F76). One thread throughout, so that a
# run leaves the other core to the machine; 12 to 22 minutes for 60 frames of six 384x512
# cameras.
#
# usage: scripts/colmap_baseline.sh DRIVE FIRST COUNT OUT
#
# Images of frames FIRST .. FIRST+COUNT-1 (indices in the drive's frame order), linked into
# OUT/images as f<frame>_c<camera>.png or .jpg (the names scripts/sfm_vs_colmap.py reads);
# each camera's pinhole intrinsics from rig.json, fixed in the adjustment (COLMAP's pixel
# centres are +0.5 from ours). The image pairs matched: each camera with itself 1, 2, 3 and 5
# frames on, and with every camera whose field of view may overlap its own (optical axes closer
# than the sum of their half horizontal fields of view) 1 and 2 frames on. The model is written
# as text in OUT/model; compare with
#   python3 scripts/sfm_vs_colmap.py DRIVE OUT/model OURS/poses.tum
# Only pinhole rigs; OUT must not exist.
set -euo pipefail
if [ $# -ne 4 ]; then
  echo "usage: scripts/colmap_baseline.sh DRIVE FIRST COUNT OUT" >&2
  exit 2
fi
drive="$1" first="$2" count="$3" out="$4"
refuse() {
  echo "colmap_baseline.sh: $1" >&2
  exit 2
}
[[ "$first" =~ ^[0-9]+$ && "$count" =~ ^[0-9]+$ ]] ||
  refuse "FIRST and COUNT: expected frame counts, got '$first' '$count'"
command -v colmap > /dev/null || refuse "colmap not found (apt-get install colmap)"
[ -f "$drive/rig.json" ] || refuse "$drive/rig.json: not found"
[ -e "$out" ] && refuse "$out: exists (give a new folder)"
mkdir -p "$out/images" "$out/sparse" "$out/model"

# Links, per-camera image lists and intrinsics, and the pair list (OUT removed again when the
# drive does not suit: it was made here).
if ! python3 - "$drive" "$first" "$count" "$out" <<'PY'; then
import json, math, os, sys


def fail(message):
    print(f'colmap_baseline.sh: {message}', file=sys.stderr)
    sys.exit(2)


drive, first, count, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
rig = json.load(open(os.path.join(drive, 'rig.json')))
cameras = rig['cameras']
for c in cameras:
    if c.get('model') != 'pinhole':
        fail(f"{drive}/rig.json: camera {c['name']} is {c.get('model')}, only pinhole cameras "
             f"are set up")
first_folder = os.path.join(drive, 'images', cameras[0]['name'])
if not os.path.isdir(first_folder):
    fail(f'{first_folder}: not a folder of images')
frames = sorted(os.path.splitext(n)[0] for n in os.listdir(first_folder)
                if n.endswith(('.png', '.jpg', '.jpeg')))
if first < 0 or count < 2 or first + count > len(frames):
    fail(f'frames {first}..{first + count - 1} outside the drive\'s {len(frames)} frames')
frames = frames[first:first + count]

names = {}  # (frame index, camera) -> the link's name, with its source's extension


def name(f, c):
    return names[(f, c)]


for c, cam in enumerate(cameras):
    folder = os.path.join(drive, 'images', cam['name'])
    with open(os.path.join(out, f'list_c{c}.txt'), 'w') as lst:
        for f, frame in enumerate(frames):
            source = next((os.path.join(folder, frame + e) for e in ('.png', '.jpg', '.jpeg')
                           if os.path.exists(os.path.join(folder, frame + e))), None)
            if source is None:
                fail(f'{folder}: no image {frame}.png or .jpg')
            names[(f, c)] = f'f{frame}_c{c}{os.path.splitext(source)[1]}'
            os.symlink(os.path.abspath(source), os.path.join(out, 'images', name(f, c)))
            lst.write(name(f, c) + '\n')
    fx, fy, cx, cy = cam['params'][:4]
    with open(os.path.join(out, f'params_c{c}.txt'), 'w') as p:
        p.write(f'{fx},{fy},{cx + 0.5},{cy + 0.5}\n')

def axis(cam):  # the optical axis in the rig: the third row of R_cam_from_rig
    w, x, y, z = cam['cam_from_rig']['q_wxyz']
    return (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))

def half_fov(cam):
    return math.atan(0.5 * cam['width'] / cam['params'][0])

pairs = []
for c in range(len(cameras)):
    for d in (1, 2, 3, 5):
        pairs += [(name(f, c), name(f + d, c)) for f in range(count - d)]
for i, a in enumerate(cameras):
    for j, b in enumerate(cameras):
        if i == j:
            continue
        angle = math.acos(max(-1.0, min(1.0, sum(p * q for p, q in zip(axis(a), axis(b))))))
        if angle < half_fov(a) + half_fov(b):
            for d in (1, 2):
                pairs += [(name(f, i), name(f + d, j)) for f in range(count - d)]
with open(os.path.join(out, 'pairs.txt'), 'w') as p:
    p.writelines(f'{x} {y}\n' for x, y in pairs)
print(f'colmap_baseline.sh: {len(cameras)} cameras, {count} frames, {len(pairs)} pairs')
PY
  rm -rf "$out"
  exit 2
fi

log="$out/colmap.log"
start=$(date +%s)
for list in "$out"/list_c*.txt; do
  c="${list##*list_c}"; c="${c%.txt}"
  colmap feature_extractor --database_path "$out/database.db" --image_path "$out/images" \
    --image_list_path "$list" --ImageReader.single_camera 1 --ImageReader.camera_model PINHOLE \
    --ImageReader.camera_params "$(cat "$out/params_c$c.txt")" \
    --SiftExtraction.num_threads 1 --SiftExtraction.use_gpu 0 >> "$log" 2>&1
done
extracted=$(date +%s)
colmap matches_importer --database_path "$out/database.db" --match_list_path "$out/pairs.txt" \
  --match_type pairs --SiftMatching.num_threads 1 --SiftMatching.use_gpu 0 >> "$log" 2>&1
matched=$(date +%s)
colmap mapper --database_path "$out/database.db" --image_path "$out/images" \
  --output_path "$out/sparse" --Mapper.ba_refine_focal_length 0 \
  --Mapper.ba_refine_principal_point 0 --Mapper.ba_refine_extra_params 0 \
  --Mapper.num_threads 1 >> "$log" 2>&1
mapped=$(date +%s)
if [ ! -d "$out/sparse/0" ]; then
  echo "colmap_baseline.sh: COLMAP made no model (see $log)" >&2
  exit 1
fi
colmap model_converter --input_path "$out/sparse/0" --output_path "$out/model" \
  --output_type TXT >> "$log" 2>&1
echo "colmap_baseline.sh: features $((extracted - start)) s, matching $((matched - extracted)) s," \
  "mapping $((mapped - matched)) s; the model in $out/model"
