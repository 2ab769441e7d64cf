"""Camera-only mission: `layerpilot up` flies an outside autopilot over MAVLink (PX4 conventions, home on
flat ground at z = 0, the way PX4/ArduPilot SITL reports it) while layerpilot's world is only its camera."""

from __future__ import annotations

import threading
import time

import numpy as np

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.bus.session import free_endpoint
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter
from layerpilot.sim.world import World, WorldConfig
from conftest import SMALL_MISSION_NODES, balanced_behavior, start_up, stop_up, operator_session

K = Keys("uav1")


def test_mission_flies_an_outside_autopilot_with_layerpilots_world_as_camera(tmp_path):
    # the stand-in for SITL: its own process clock, flat ground at 0, serving MAVLink on a free port
    # its clock runs 3x real time, so the link's 5 Hz (wall) setpoint stream is 1.7 Hz of its time: PX4's
    # "stream faster than 2 Hz before OFFBOARD" becomes 2 / 3 Hz here, or OFFBOARD is refused at random
    sitl = MavlinkVehicle(Multicopter(), "tcp:127.0.0.1:0",
                          EndpointConfig(flavour="px4", offboard_min_rate_hz=2.0 / 3.0)).start(speed=3.0)
    ep = free_endpoint()
    # balanced without retargeting: every waypoint is flown to the end, so arrival can be checked
    behavior = balanced_behavior(tmp_path, "no-retarget.toml", tail="\n[retarget]\nenabled = false\n")
    mission = tmp_path / "mission.toml"
    mission.write_text(f"""
vehicles = ["uav1"]
camera_only = true
[map_server]
resolution = 1.0
layers_rate = 2.0
window = [-128.0, -128.0, 256, 256]
snapshot = ""
""" + SMALL_MISSION_NODES.replace('behavior = "balanced"', f'behavior = "{behavior}"') + f"""
[link.link]
url = "tcp:127.0.0.1:{sitl.addresses[0][1]}"
""")
    up, lines = start_up(mission, ep, tmp_path / "logs")
    client = operator_session(ep, tmp_path / "logs")
    frames: list[msg.FrameMessage] = []
    waypoints: list[msg.Waypoint] = []
    layer_sets: list[bytes] = []
    subs = [client.declare_subscriber(K.camera, lambda s: frames.append(msg.decode_frame(s.payload.to_bytes()))),
            client.declare_subscriber(K.waypoint,
                                      lambda s: waypoints.append(msg.decode_waypoint(s.payload.to_bytes()))),
            client.declare_subscriber(K.layers, lambda s: layer_sets.append(s.payload.to_bytes()))]
    track_xy: list[np.ndarray] = []
    done = threading.Event()

    def sample_track() -> None:
        while not done.wait(0.02):
            track_xy.append(sitl.pose().position[:2].copy())

    threading.Thread(target=sample_track, daemon=True).start()
    try:
        end = time.monotonic() + 120
        while len({w.seq for w in waypoints}) < 4:
            assert up.poll() is None, "up exited:\n" + "".join(lines[-30:])
            assert time.monotonic() < end, "timed out waiting for 4 waypoints:\n" + "".join(lines[-30:])
            time.sleep(0.2)
        assert sitl.mode == "OFFBOARD" and sitl.armed
        # the outside autopilot flew to the waypoints (decide moves on only after arrival)
        track = np.array(track_xy)
        for seq in (1, 2, 3):
            w = next(w for w in waypoints if w.seq == seq)
            assert np.min(np.hypot(*(track - w.position[:2]).T)) < 3.0, seq
        # frames are stamped with the autopilot's clock and taken from where it says it is
        last = frames[-1].frame
        assert abs(last.stamp - sitl.time) < 5.0
        assert np.hypot(*(last.pose.position[:2] - sitl.pose().position[:2])) < 30.0
        # the map lives in the autopilot's frame: the world's terrain shifted by its height at home
        # (-5.7 m for the default world), never below it, and on it in the clearings
        cl = to_column_layers(decode_layer_set(layer_sets[-1]))
        assert cl.observed.sum() > 2000
        forest = World(WorldConfig())
        xs, ys = cl.geometry.cell_centers()
        terrain = forest.terrain_height(xs[cl.observed], ys[cl.observed]) - forest.terrain_height(0.0, 0.0)
        above = cl.elevation[cl.observed] - terrain  # the top of a ground voxel is 0-1 m above the terrain
        assert np.quantile(above, 0.01) > -1.5 and np.mean((above > -1.0) & (above < 2.0)) > 0.1
    finally:
        done.set()
        for s in subs:
            s.undeclare()
        client.close()
        stop_up(up)
        sitl.stop()
    assert up.returncode == 0, "".join(lines[-20:])
