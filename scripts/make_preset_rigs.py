#!/usr/bin/env python3
"""Writes the rig presets of the synthetic drives besides the default ladybug-like head:
data/rigs/pinhole.json, data/rigs/car.json and data/rigs/fisheye5.json (data/README.md says
where their numbers come from). They imitate the rigs users bring:

* pinhole: one forward phone-like camera, 1024x768, 65 degrees of horizontal field of view.
* car: six large pinhole cameras (1920x1200, 70 degrees horizontal) around a car roof, every
  60 degrees of heading (front, front_left, rear_left, rear, rear_right, front_right), so that
  neighbours overlap by about 10 degrees; centres 1.0 to 1.5 m from the rig origin.
* fisheye5: five equidistant (Kannala-Brandt) fisheyes of 720x540 as on an Alphasense head:
  a forward stereo pair 10 cm apart, one left, one right, one up.

Rig frame: x forward, y left, z up. Camera frame (OpenCV): x right, y down, z forward.
"""
import json
import math
import os

from rig_geometry import clean, quat_wxyz_from_matrix


def camera(name, width, height, model, params, x_axis, y_axis, z_axis, centre):
    # rig_from_cam has the camera axes (in the rig frame) as columns; cam_from_rig is its
    # transpose, with t = -R^T c.
    r = [x_axis, y_axis, z_axis]  # rows of the cam_from_rig rotation
    t = [-sum(r[i][k] * centre[k] for k in range(3)) for i in range(3)]
    return {
        "name": name, "width": width, "height": height, "model": model,
        "params": [round(p, 6) for p in params],
        "cam_from_rig": {"q_wxyz": clean(quat_wxyz_from_matrix(r)), "t": clean(t)},
    }


def level_axes(yaw_deg):
    """Axes (right, down, forward) of a level camera looking along heading yaw (0 = forward)."""
    yaw = math.radians(yaw_deg)
    forward = [math.cos(yaw), math.sin(yaw), 0.0]
    right = [math.sin(yaw), -math.cos(yaw), 0.0]
    down = [0.0, 0.0, -1.0]
    return right, down, forward


def pinhole_params(width, height, hfov_deg):
    focal = (width / 2.0) / math.tan(math.radians(hfov_deg / 2.0))
    return [focal, focal, (width - 1) / 2.0, (height - 1) / 2.0]


def pinhole_rig():
    width, height, hfov = 1024, 768, 65.0
    cam = camera("phone", width, height, "pinhole", pinhole_params(width, height, hfov),
                 *level_axes(0.0), [0.0, 0.0, 0.0])
    return {"name": "pinhole", "central": True, "cameras": [cam]}


def car_rig():
    width, height, hfov = 1920, 1200, 70.0
    params = pinhole_params(width, height, hfov)
    # (name, heading in degrees, centre x, centre y): around a roof, 1.0-1.5 m from the origin.
    mounts = [
        ("front", 0.0, 1.40, 0.0),
        ("front_left", 60.0, 0.75, 0.80),
        ("rear_left", 120.0, -0.55, 0.85),
        ("rear", 180.0, -1.20, 0.0),
        ("rear_right", -120.0, -0.55, -0.85),
        ("front_right", -60.0, 0.75, -0.80),
    ]
    cameras = [camera(name, width, height, "pinhole", params, *level_axes(yaw), [x, y, 0.0])
               for name, yaw, x, y in mounts]
    return {"name": "car", "central": False, "cameras": cameras}


def fisheye5_rig():
    width, height = 720, 540
    # Equidistant fisheye, Alphasense-like: about 120 degrees across the width.
    params = [350.0, 350.0, (width - 1) / 2.0, (height - 1) / 2.0, -0.04, 0.004, -0.002, 0.0004]
    baseline = 0.10
    cameras = [
        camera("cam0", width, height, "fisheye", params, *level_axes(0.0),
               [0.0, baseline / 2.0, 0.0]),  # stereo left
        camera("cam1", width, height, "fisheye", params, *level_axes(0.0),
               [0.0, -baseline / 2.0, 0.0]),  # stereo right
        camera("cam2", width, height, "fisheye", params, *level_axes(90.0),
               [-0.03, 0.06, 0.0]),  # left
        camera("cam3", width, height, "fisheye", params, *level_axes(-90.0),
               [-0.03, -0.06, 0.0]),  # right
        # Up: the image "up" direction points forward (image down = rig -x, right = rig +y).
        camera("cam4", width, height, "fisheye", params, [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0],
               [0.0, 0.0, 1.0], [-0.03, 0.0, 0.04]),
    ]
    return {"name": "fisheye5", "central": False, "cameras": cameras}


folder = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "rigs")
for name, rig in [("pinhole", pinhole_rig()), ("car", car_rig()), ("fisheye5", fisheye5_rig())]:
    out = os.path.normpath(os.path.join(folder, name + ".json"))
    with open(out, "w") as f:
        json.dump(rig, f, indent=2)
        f.write("\n")
    print(out)
