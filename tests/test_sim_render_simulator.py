"""The whole simulator in lock-step: a pymavlink client flies the vehicle, the camera renders from its pose."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.grid import GridGeometry
from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.sim.simulator import SimConfig, Simulator
from layerpilot.sim.world import WorldConfig


@pytest.fixture
def sim():
    config = SimConfig(world=WorldConfig(seed=2, size=160.0, trees_per_hectare=200.0, clearings=2),
                       camera=CameraConfig(width=320, height=240), frame_rate_hz=4.0,
                       urls=("tcp:127.0.0.1:0",))
    s = Simulator(config)
    client = mavutil.mavlink_connection(f"tcp:127.0.0.1:{s.endpoint.addresses[0][1]}", source_system=255,
                                        source_component=190)
    yield s, client
    client.close()
    s.close()


def _run(sim: Simulator, client, seconds: float, frames: list, messages: list) -> None:
    for _ in range(int(round(seconds / sim.config.step_s))):
        shot = sim.step()
        if shot is not None:
            frames.append(shot)
        while (msg := client.recv_match(blocking=False)) is not None:
            messages.append(msg)


def _command(sim, client, frames, messages, command: int, *params: float) -> int:
    client.mav.command_long_send(1, 1, command, 0, *(list(params) + [0.0] * (7 - len(params))))
    for _ in range(100):
        n = len(messages)
        _run(sim, client, sim.config.step_s, frames, messages)
        for msg in messages[n:]:
            if msg.get_type() == "COMMAND_ACK" and msg.command == command:
                return msg.result
    raise AssertionError(f"no COMMAND_ACK for {command}")


def test_take_off_over_mavlink_and_render_from_the_vehicle_pose(sim):
    s, client = sim
    frames: list = []
    messages: list = []
    _run(s, client, 3.0, frames, messages)  # pre-arm checks pass after 2 s
    assert any(m.get_type() == "HEARTBEAT" for m in messages)
    assert _command(s, client, frames, messages, mav.MAV_CMD_DO_SET_MODE,
                    mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4) == mav.MAV_RESULT_ACCEPTED  # GUIDED
    assert _command(s, client, frames, messages, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
    assert _command(s, client, frames, messages, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) \
        == mav.MAV_RESULT_ACCEPTED
    _run(s, client, 16.0, frames, messages)
    ground = float(s.world.terrain_height(0.0, 0.0))

    # frames come at 4 Hz of mission time, stamped with the mission clock
    stamps = np.array([t for t, _ in frames])
    assert len(frames) == s.frames == int(s.time * 4.0 + 1e-6) + 1
    assert np.allclose(np.diff(stamps), 0.25, atol=s.config.step_s + 1e-9)

    # the last frame is taken from the vehicle's pose, 30 m above home
    stamp, frame = frames[-1]
    assert frame.stamp == stamp
    pos = s.vehicle.position
    assert pos[2] == pytest.approx(ground + 30.0, abs=0.5)
    expected = camera_pose(frame.pose.position, s.vehicle.yaw, 60.0)
    assert np.allclose(frame.pose.rotation, expected.rotation, atol=1e-3)
    assert np.linalg.norm(frame.pose.position - pos) < 0.1  # at most one step of climb apart

    # every pixel's depth puts its 3D point on the world surface (between terrain and canopy top)
    K = frame.K
    v, u = np.mgrid[0:240:8, 0:320:8]
    d = frame.depth[v, u]
    assert np.isfinite(d).all()
    pc = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3) @ np.linalg.inv(K).T * d.reshape(-1, 1)
    pts = frame.pose.position + pc @ frame.pose.rotation.T
    terrain = s.world.terrain_height(pts[:, 0], pts[:, 1])
    assert np.all(pts[:, 2] >= terrain - 0.01)
    for x, y, z in pts[::8]:  # the exact column top under the point (a one-cell grid centred on it)
        assert z <= s.world.surface_height(GridGeometry(x - 0.5, y - 0.5, 1.0, 1, 1))[0, 0] + 0.01, (x, y, z)
    on_ground = np.abs(pts[:, 2] - terrain) < 0.01
    assert 0.2 < on_ground.mean() < 1.0  # sees both ground and trees
