"""A fleet's separation in the link: a waypoint too near another drone is refused, counted and never sent,
in the flight link over real MAVLink (loopback, the simulated vehicle) and in the live link node over Zenoh."""

from __future__ import annotations

import json
import signal
import time

import numpy as np
import pytest

from conftest import cli_process, wait_for
from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session, publish
from layerpilot.config import RangeError
from layerpilot.geometry import Pose
from layerpilot.link.config import LinkConfig
from layerpilot.link.geofence import OutsideGeofence
from layerpilot.link.link import FlightLink, WaypointRefused
from layerpilot.link.separation import Separation
from test_link_geofence import FAST, FENCE, spy_on, url_of, vehicle  # noqa: F401  (the fixture)


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_waypoint_near_another_drones_position_or_target_is_refused_until_it_is_stale():
    clock = Clock()
    sep = Separation(10.0, stale_after=5.0, clock=clock)
    sep.check(0.0, 0.0)  # nobody heard: anything goes
    sep.heard("uav2", position=(30.0, 0.0))
    sep.check(40.0, 0.0)  # exactly 10 m: kept
    with pytest.raises(OutsideGeofence, match=r"^waypoint \(35.0, 0.0\) is 5.0 m from uav2's position, under "
                                              r"the 10 m separation; not sent$") as info:
        sep.check(35.0, 0.0)
    assert info.value.kind == "separation"
    sep.heard("uav2", target=(100.0, 100.0))  # the position heard before stays
    with pytest.raises(OutsideGeofence, match="uav2's target"):
        sep.check(103.0, 104.0)
    with pytest.raises(OutsideGeofence, match="uav2's position"):
        sep.check(31.0, 1.0)
    clock.now = 5.5  # silent for longer than stale_after: a drone that dropped out blocks nothing
    sep.check(31.0, 1.0)
    Separation(0.0).check(0.0, 0.0)  # 0: off
    with pytest.raises(RangeError, match="separation"):
        Separation(-1.0)


def test_the_flight_link_refuses_a_waypoint_near_another_drone_and_sends_nothing_of_it(vehicle):  # noqa: F811
    sep = Separation(10.0)
    with FlightLink(LinkConfig(url=url_of(vehicle), **FAST), geofence=FENCE, separation=sep) as link:
        link.connect(5.0)
        link.wait_ready()
        link.start_guided()
        link.arm()
        link.takeoff(20.0)
        target = vehicle.vehicle.position_target.copy()
        received = spy_on(vehicle)
        sep.heard("uav2", position=(30.0, 0.0), target=(60.0, 40.0))
        for position, what in (((33.0, 4.0, 25.0), "uav2's position"), ((62.0, 38.0, 25.0), "uav2's target")):
            with pytest.raises(WaypointRefused, match=what):
                link.set_waypoint(*position)
        with pytest.raises(WaypointRefused, match="under the 10 m separation"):
            link.goto(28.0, 0.0, 25.0, timeout=5.0)
        assert link.refused == {"separation": 3}
        time.sleep(0.5)
        assert np.array_equal(vehicle.vehicle.position_target, target)  # still the hover point
        hover = {r[1:] for r in received if r[0] == "setpoint"}
        assert len(hover) == 1, hover
        link.goto(-30.0, 0.0, 25.0)  # away from uav2: flown
        assert np.linalg.norm(vehicle.pose().position - vehicle.ekf_origin - (-30.0, 0.0, 25.0)) < 0.6
        link.set_waypoint(29.0, 1.0, 25.0, separate=False)  # a return home is never refused for separation
        assert link.refused == {"separation": 3}


def test_the_link_node_hears_the_other_drones_on_the_bus_and_refuses_until_the_way_is_clear(vehicle, tmp_path):  # noqa: F811
    ep = free_endpoint()
    mission = tmp_path / "m.toml"
    mission.write_text('vehicles = ["uav1", "uav2"]\n[link]\ntakeoff_altitude = 20.0\nseparation = 10.0\n'
                       "[link.link]\nready_timeout_s = 10.0\narrival_tolerance_m = 0.5\narrival_hold_s = 0.3\n")
    with cli_process("link", "--config", str(mission), "--endpoint", ep, "--mavlink", url_of(vehicle),
                     "--status-every", "0.2") as proc:
        lines = [json.loads(proc.stdout.readline())]

        def line(check) -> bool:
            lines.append(json.loads(proc.stdout.readline()))
            return check(lines[-1])

        wait_for(lambda: line(lambda s: s.get("phase") == "flying"), "the link node to take off", timeout=60)
        with open_session(BusConfig(endpoint=ep)) as other:
            def uav2_at(x: float, y: float) -> None:
                publish(other, Keys("uav2").pose, msg.encode_state(msg.State(1.0, "uav2", Pose.from_euler(
                    0.0, 0.0, 0.0, np.array([x, y, 20.0])))))

            uav2_at(30.0, 0.0)
            time.sleep(0.5)  # heard
            waypoint = msg.encode_waypoint(msg.Waypoint(2.0, "uav1", 1, np.array([33.0, 0.0, 22.0])))
            publish(other, Keys("uav1").waypoint, waypoint)
            wait_for(lambda: line(lambda s: s.get("refused") == {"separation": 1}), "the separation refusal")
            assert lines[-1]["waypoints"] == 0
            uav2_at(-60.0, 50.0)  # uav2 moved on; decide repeats its waypoint (the same seq), now flown
            time.sleep(0.5)  # heard before the repeat
            deadline = time.monotonic() + 20.0
            while np.linalg.norm(vehicle.pose().position - vehicle.ekf_origin - (33.0, 0.0, 22.0)) > 1.0:
                assert time.monotonic() < deadline, "the repeated waypoint was not flown"
                publish(other, Keys("uav1").waypoint, waypoint)
                uav2_at(-60.0, 50.0)
                time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    last = json.loads(out.strip().splitlines()[-1])
    assert last["waypoints"] == 1 and last["refused"] == {"separation": 1}, last
    assert err.count("waypoint refused (separation)") == 1  # logged once per kind
