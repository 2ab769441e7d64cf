"""Camera-only simulation: frames rendered from the pose another autopilot reports, rate-limited by mission time."""

from __future__ import annotations

import threading
import time

import numpy as np

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.depth.source import GroundTruthDepth
from layerpilot.geometry import Pose
from layerpilot.nodes.sim import CameraOnlyNode
from layerpilot.camera import CameraConfig
from layerpilot.sim.simulator import SimConfig
from layerpilot.sim.world import World, WorldConfig

K = Keys("uav1")


def test_camera_only_renders_from_reported_pose():
    ep = free_endpoint()
    node_session, world = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    node = CameraOnlyNode(node_session, "uav1", SimConfig(camera=CameraConfig(width=64, height=48), frame_rate_hz=2.0))
    frames: list[msg.FrameMessage] = []
    sub = world.declare_subscriber(K.camera, lambda s: frames.append(msg.decode_frame(s.payload.to_bytes())))
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    try:
        time.sleep(0.5)
        yaw = np.radians(30.0)
        for i in range(5):  # 10 Hz of poses over 0.4 s: at 2 frames per second only t = 0.0 qualifies...
            world.put(K.pose, msg.encode_state(msg.State(i * 0.1, "uav1", Pose.from_euler(0, 0, yaw, (5.0, 6.0, 40.0)))))
            time.sleep(0.1)
        world.put(K.pose, msg.encode_state(msg.State(0.6, "uav1", Pose.from_euler(0, 0, yaw, (5.0, 6.0, 40.0)))))
        end = time.monotonic() + 20
        while len(frames) < 2 and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(0.3)
        assert [m.frame.stamp for m in frames] == [0.0, 0.6]  # ...and then t = 0.6
        assert [m.seq for m in frames] == [1, 2] and frames[0].vehicle == "uav1"
        f = frames[0].frame
        assert f.image.shape == (48, 64, 3) and f.depth is not None
        np.testing.assert_allclose(f.pose.position, [5, 6, 40])
        forward = f.optical_axis  # the camera looks 30 deg left of east, pitched down
        assert abs(np.degrees(np.arctan2(forward[1], forward[0])) - 30.0) < 1e-6 and forward[2] < 0
        assert np.isfinite(f.depth).mean() > 0.9  # sees the forest, not the sky
        # The autopilot's frame has home on the ground; layerpilot's world is lifted to match, so what the
        # camera sees, back in the published (autopilot) frame, lies on the world's terrain shifted by
        # its height at home: never below it, and the ground pixels on it.
        forest = World(WorldConfig())
        lift = float(forest.terrain_height(0.0, 0.0))
        pts = GroundTruthDepth().push(f).points.astype(np.float64)
        above = pts[:, 2] - (forest.terrain_height(pts[:, 0], pts[:, 1]) - lift)
        assert lift < -1.0 and np.quantile(above, 0.01) > -0.3  # would be 5.7 m below without the lift
        assert np.mean(np.abs(above) < 0.3) > 0.05  # clearings: the terrain itself
    finally:
        stop.set()
        runner.join()
        sub.undeclare()
        world.close()
        node_session.close()

