"""The link's geofence: the shapes, the one place a mission builds it, and its enforcement over real
MAVLink (loopback, the simulated vehicle) in the flight link, the live link node and the evaluator."""

from __future__ import annotations

import json
import math
import signal
import time

import numpy as np
import pytest

from conftest import cli_process, wait_for
from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session, publish
from layerpilot.config import ConfigError
from layerpilot.link.config import LinkConfig
from layerpilot.link.frames import enu_to_ned
from layerpilot.link.geofence import Geofence, OutsideGeofence
from layerpilot.link.link import FlightLink, WaypointRefused
from layerpilot.missionfile import geofence_for
from layerpilot.missionfile import load_mission
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter

FAST = dict(arrival_hold_s=0.3, arrival_tolerance_m=0.5, command_timeout_s=1.0, ready_timeout_s=10.0)
FENCE = Geofence.circle((0.0, 0.0), 100.0, margin=20.0, alt_min=2.0, alt_max=120.0)
HOME_Z = 2.0


# --- the shapes ------------------------------------------------------------------------------

def test_circle_with_margin_and_altitudes_relative_to_home():
    FENCE.check(0.0, 0.0, 50.0, home_z=0.0)
    FENCE.check(119.9, 0.0, 50.0, home_z=0.0)          # inside the margin
    with pytest.raises(OutsideGeofence, match=r"^waypoint \(150.0, 150.0, 45.0\) is 92.1 m outside the geofence "
                                              r"\(circle of radius 100 m around \(0, 0\) \+ 20 m margin, "
                                              r"2-120 m above home\); not sent$") as info:
        FENCE.check(150.0, 150.0, 45.0, home_z=0.0)
    assert info.value.kind == "outside the area"
    with pytest.raises(OutsideGeofence, match="altitude 121.0 m above home is outside the geofence's limits "
                                              r"\[2, 120\] m") as info:
        FENCE.check(0.0, 0.0, 131.0, home_z=10.0)
    assert info.value.kind == "altitude"
    with pytest.raises(OutsideGeofence, match="altitude 1.0 m above home"):
        FENCE.check(0.0, 0.0, 11.0, home_z=10.0)
    for bad in ((math.nan, 0.0, 50.0), (0.0, math.inf, 50.0), (0.0, 0.0, -math.inf)):
        with pytest.raises(OutsideGeofence, match="is not finite; not sent"):
            FENCE.check(*bad, home_z=0.0)


def test_polygon_with_margin():
    fence = Geofence.polygon_of([(0, 0), (100, 0), (100, 100), (0, 100)], margin=10.0)
    fence.check(50.0, 50.0, 30.0, home_z=0.0)
    fence.check(107.0, 50.0, 30.0, home_z=0.0)          # 7 m beyond the east edge: within the margin
    fence.check(-7.0, -7.0, 30.0, home_z=0.0)           # 9.9 m beyond the corner
    with pytest.raises(OutsideGeofence, match=r"18.3 m outside the geofence \(polygon of 4 vertices"):
        fence.check(120.0, 120.0, 30.0, home_z=0.0)     # 28.3 m from the corner
    concave = Geofence.polygon_of([(0, 0), (100, 0), (100, 100), (50, 10), (0, 100)])
    with pytest.raises(OutsideGeofence):
        concave.check(50.0, 60.0, 30.0, home_z=0.0)     # in the notch


@pytest.mark.parametrize("build, message", [
    (lambda: Geofence.circle((0, 0), 0.0), "radius > 0"),
    (lambda: Geofence.circle((0, 0), 10.0, margin=-1.0), "margin must be >= 0"),
    (lambda: Geofence.circle((0, 0), 10.0, alt_min=50.0, alt_max=20.0), "alt_min must be below alt_max"),
    (lambda: Geofence.circle((math.nan, 0), 10.0), "finite"),
    (lambda: Geofence.polygon_of([(0, 0), (1, 1)]), "at least 3 vertices"),
    (lambda: Geofence.polygon_of([(0, 0), (1, 1), (2, 2)]), "enclosing an area"),
])
def test_a_bad_fence_is_refused(build, message):
    with pytest.raises(ConfigError, match=message):
        build()


# --- built from the mission in one place ------------------------------------------------------

def test_the_mission_fence_is_the_behaviors_area_plus_the_margin_and_the_links_altitudes(tmp_path):
    fence = geofence_for(load_mission("default"))
    assert fence == Geofence.circle((0.0, 0.0), 100.0, margin=20.0, alt_min=2.0, alt_max=120.0)
    for name in ("sitl-camera", "two-drones"):
        assert geofence_for(load_mission(name)).shape == "circle"
    behavior = tmp_path / "field.toml"
    behavior.write_text('weights = { fringe = 1.0 }\n[area]\nshape = "polygon"\n'
                        'polygon = [[-50.0, -20.0], [80.0, -20.0], [80.0, 60.0], [-50.0, 60.0]]\n')
    mission = tmp_path / "m.toml"
    mission.write_text(f'[decide]\nbehavior = "{behavior}"\nhome = [5.0, 5.0]\n'
                       "[link]\ngeofence_margin = 5.0\n[link.link]\nalt_min_m = 10.0\nalt_max_m = 60.0\n")
    fence = geofence_for(load_mission(mission))
    assert fence.shape == "polygon" and fence.polygon[1] == (80.0, -20.0)
    assert (fence.margin, fence.alt_min, fence.alt_max) == (5.0, 10.0, 60.0)
    mission.write_text('[decide]\nbehavior = "orbit"\nhome = [30.0, -10.0]\n')  # a pattern: balanced's area
    assert geofence_for(load_mission(mission)).center == (30.0, -10.0)
    mission.write_text("[link]\ngeofence_margin = -1.0\n")
    with pytest.raises(ConfigError, match=r"link.geofence_margin = -1.0 is out of range"):
        load_mission(mission)


def test_the_evaluators_link_has_the_mission_fence():
    from layerpilot.eval.mission import flight_link

    mission = load_mission("default")
    link = flight_link(mission, "tcp:127.0.0.1:9")  # nothing serves there; the link only has to exist
    try:
        assert link.geofence == geofence_for(mission)
    finally:
        link.close()


# --- enforced over MAVLink ---------------------------------------------------------------------

def start_vehicle(speed: float = 10.0) -> MavlinkVehicle:
    vehicle = Multicopter(position=(0.0, 0.0, HOME_Z), ground_z=HOME_Z)
    return MavlinkVehicle(vehicle, "tcp:127.0.0.1:0", EndpointConfig()).start(speed=speed)


def url_of(endpoint: MavlinkVehicle) -> str:
    return f"tcp:127.0.0.1:{endpoint.addresses[0][1]}"


def spy_on(endpoint: MavlinkVehicle) -> list:
    """Every SET_POSITION_TARGET_LOCAL_NED (as NED x, y, z) and COMMAND_LONG the vehicle receives from now on."""
    received: list = []
    handle = endpoint._handle

    def spy(m):
        if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            received.append(("setpoint", round(m.x, 3), round(m.y, 3), round(m.z, 3)))
        elif m.get_type() == "COMMAND_LONG":
            received.append(("command", m.command))
        handle(m)

    endpoint._handle = spy
    return received


@pytest.fixture
def vehicle():
    endpoint = start_vehicle()
    yield endpoint
    endpoint.stop()


def test_waypoints_outside_the_fence_never_reach_the_vehicle(vehicle):
    from pymavlink.dialects.v20 import ardupilotmega as mav

    with FlightLink(LinkConfig(url=url_of(vehicle), **FAST), geofence=FENCE) as link:
        link.connect(5.0)
        link.wait_ready()
        link.start_guided()
        link.arm()
        link.takeoff(20.0)
        # the link flies the autopilot's frame: its origin, the EKF origin, is home on the ground (HOME_Z in the world)
        hover = tuple(round(c, 3) for c in enu_to_ned(0.0, 0.0, 20.0))
        target = vehicle.vehicle.position_target.copy()
        received = spy_on(vehicle)
        refused = [((150.0, 150.0, 45.0), "92.1 m outside the geofence"),     # the finding: 212 m from home
                   ((1e6, 1e6, 45.0), "outside the geofence"),
                   ((0.0, 0.0, 121.0), "altitude 121.0 m above home is outside"),
                   ((0.0, 0.0, 1.0), "altitude 1.0 m above home is outside")]
        for position, message in refused:
            with pytest.raises(WaypointRefused, match=message):
                link.set_waypoint(*position)
            with pytest.raises(WaypointRefused, match=message):
                link.goto(*position, timeout=5.0)
        with pytest.raises(WaypointRefused, match="altitude 130.0 m above home"):
            link.takeoff(130.0)                                               # NAV_TAKEOFF is a target too
        assert link.refused == {"outside the area": 4, "altitude": 5} and link.refused_total == 9
        time.sleep(1.0)                                                       # 10 s of vehicle time
        setpoints = {r[1:] for r in received if r[0] == "setpoint"}
        assert setpoints == {hover}, f"something other than the hover setpoint was sent: {setpoints}"
        assert ("command", mav.MAV_CMD_NAV_TAKEOFF) not in received
        assert np.array_equal(vehicle.vehicle.position_target, target)
        assert np.linalg.norm(vehicle.pose().position - (0.0, 0.0, HOME_Z + 20.0)) < 0.6
        # inside (within the margin) is flown
        link.goto(110.0, 0.0, 30.0)
        assert np.linalg.norm(vehicle.pose().position - (110.0, 0.0, HOME_Z + 30.0)) < 0.6
        assert link.refused_total == 9
        # the worker checks every re-send: home moves 100 m down, the setpoint is now 130 m above it
        vehicle.home = vehicle.home - (0.0, 0.0, 100.0)
        wait_for(lambda: any(e.startswith("setpoint dropped") for e in link.events), "the setpoint to be dropped")
        assert link.refused["altitude"] == 6
        received.clear()
        time.sleep(0.5)
        assert not [r for r in received if r[0] == "setpoint"]


def test_link_node_refuses_and_counts_an_outside_waypoint_over_zenoh(vehicle, tmp_path):
    ep = free_endpoint()
    mission = tmp_path / "m.toml"
    mission.write_text("[link]\ntakeoff_altitude = 20.0\n[link.link]\nready_timeout_s = 10.0\n"
                       "arrival_tolerance_m = 0.5\narrival_hold_s = 0.3\n")
    received = []
    with cli_process("link", "--config", str(mission), "--endpoint", ep, "--mavlink", url_of(vehicle),
                     "--status-every", "0.2") as proc:
        first = json.loads(proc.stdout.readline())
        assert first["status"] == "connecting" and first["geofence"] == FENCE.describe()
        lines = [first]

        def flying() -> bool:
            lines.append(json.loads(proc.stdout.readline()))
            return lines[-1].get("phase") == "flying"

        wait_for(flying, "the link node to take off", timeout=60)
        assert [ln["status"] for ln in lines if "status" in ln] == ["connecting", "ready"]
        with open_session(BusConfig(endpoint=ep)) as outsider:
            received = spy_on(vehicle)
            key = Keys("uav1").waypoint
            for seq, position in enumerate([(150.0, 150.0, 45.0), (1e6, 1e6, 45.0), (0.0, 0.0, 300.0)], 1):
                publish(outsider, key, msg.encode_waypoint(msg.Waypoint(1.0, "uav1", seq, np.array(position))))

            def refused() -> bool:
                lines.append(json.loads(proc.stdout.readline()))
                return lines[-1].get("rejected") == 3

            wait_for(refused, "three refusals in the status line")
            assert lines[-1]["refused"] == {"outside the area": 2, "altitude": 1} and lines[-1]["waypoints"] == 0
            publish(outsider, key, msg.encode_waypoint(msg.Waypoint(2.0, "uav1", 9, np.array([30.0, 0.0, 32.0]))))
            # flown in the autopilot's frame (origin: home on the ground, HOME_Z in the simulated world)
            wait_for(lambda: np.linalg.norm(vehicle.pose().position - vehicle.ekf_origin - (30.0, 0.0, 32.0)) < 1.0,
                     "the inside waypoint")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    last = json.loads(out.strip().splitlines()[-1])
    assert last["status"] == "stopped" and last["rejected"] == 3 and last["waypoints"] == 1
    sent = {r[1:] for r in received if r[0] == "setpoint"}
    assert all(abs(y) < 31.0 and abs(x) < 1.0 for x, y, _ in sent), sent   # only hover and (30, 0, 32)
    assert err.count("waypoint refused (outside the area)") == 1          # logged once per kind
    assert err.count("waypoint refused (altitude)") == 1
