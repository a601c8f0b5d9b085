"""Builds the pyrender adapter's inputs on one platform (argv[1]) and saves them (argv[2]).

Run in a fresh process: PyOpenGL binds its platform at import time.
"""

import sys

import numpy as np

from rtp.capture.scenes import procedural
from rtp.plugins.pyrender import Adapter, SceneFrame, import_pyrender, to_pyrender_scene
from rtp.scene import Camera

platform, out = sys.argv[1], sys.argv[2]
pyrender = import_pyrender(platform)
scene = procedural(3)
sp = scene.spawn_points[0]
W, H = 160, 96
prev = Camera(sp.position, yaw=sp.yaw, pitch=-5.0)
cur = Camera((sp.position[0] + 0.3, sp.position[1], sp.position[2] - 0.2), yaw=sp.yaw + 5.0, pitch=-3.0)
ps = to_pyrender_scene(scene)
cam = pyrender.PerspectiveCamera(yfov=np.radians(cur.fov_y), aspectRatio=W / H, znear=cur.near, zfar=cur.far)
channels = ("reprojected.r", "seen", "albedo.r", "normal.z", "depth")
# The previous displayed frame is the same fixed image on both platforms, so that only the
# adapter's own work (G-buffers, reprojection) is compared, not pyrender's lit image.
yy, xx = np.mgrid[0:H, 0:W]
colour = np.stack([xx / W, yy / H, (xx + yy) % 7 / 7.0], axis=2).astype(np.float32)
with Adapter(channels, W, H, platform=platform) as a:
    x = a.inputs(SceneFrame(ps, np.linalg.inv(cur.view()), np.linalg.inv(prev.view()), colour, camera=cam))
np.save(out, x)
