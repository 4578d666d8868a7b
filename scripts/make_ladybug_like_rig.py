#!/usr/bin/env python3
"""Writes data/rigs/ladybug-like.json, the default rig of the synthetic drives.

Where the numbers come from (see data/README.md): a Point Grey Ladybug 2 head has five side
cameras in a ring, every 72 degrees, and one looking up; its 1024x768 sensors lie on their
side, so the side images are portrait, and the paper (Litvinov & Lhuillier, BMVC 2013) halves
them, giving 384x512. The camera centres sit a few centimetres from the head axis (about 4 cm),
the top camera a few centimetres above the ring. A horizontal field of view of 80 degrees per
side camera (5 x 80 = 400 > 360) makes neighbours overlap by about 8 degrees, as on the real
head. The images are taken as rectified, hence pinhole.

Rig frame: x forward (camera 0's viewing direction), y left, z up; origin on the head axis at
the height of the ring. Camera frame (OpenCV): x right, y down, z forward.
"""
import json
import math
import os

from rig_geometry import clean, quat_wxyz_from_matrix

WIDTH, HEIGHT = 384, 512
HFOV_DEG = 80.0
RING_RADIUS_M = 0.04
TOP_HEIGHT_M = 0.06
FOCAL = (WIDTH / 2.0) / math.tan(math.radians(HFOV_DEG / 2.0))


def camera(name, x_axis, y_axis, z_axis, centre):
    # rig_from_cam has the camera axes (in the rig frame) as columns; cam_from_rig is its
    # transpose, with t = -R^T c.
    r = [x_axis, y_axis, z_axis]  # rows of cam_from_rig rotation
    t = [-sum(r[i][k] * centre[k] for k in range(3)) for i in range(3)]
    return {
        "name": name, "width": WIDTH, "height": HEIGHT, "model": "pinhole",
        "params": [round(FOCAL, 6), round(FOCAL, 6), (WIDTH - 1) / 2.0, (HEIGHT - 1) / 2.0],
        "cam_from_rig": {"q_wxyz": clean(quat_wxyz_from_matrix(r)), "t": clean(t)},
    }


cameras = []
for k in range(5):
    yaw = math.radians(72.0 * k)
    forward = [math.cos(yaw), math.sin(yaw), 0.0]
    right = [math.sin(yaw), -math.cos(yaw), 0.0]
    down = [0.0, 0.0, -1.0]
    centre = [RING_RADIUS_M * forward[0], RING_RADIUS_M * forward[1], 0.0]
    cameras.append(camera(f"cam{k}", right, down, forward, centre))
# Top camera: looks up; its image "down" direction points forward.
cameras.append(camera("cam5", [0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0],
                      [0.0, 0.0, TOP_HEIGHT_M]))

rig = {"name": "ladybug-like", "central": False, "cameras": cameras}
out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "rigs",
                   "ladybug-like.json")
with open(out, "w") as f:
    json.dump(rig, f, indent=2)
    f.write("\n")
print(out)
