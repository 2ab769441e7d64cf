"""`layerpilot link fly-plan`: a .plan uploaded over real MAVLink (TCP loopback) to the simulated ArduCopter and
flown in AUTO, and to the simulated PX4 and flown in AUTO.MISSION; a second client watches what the vehicle says (MISSION_CURRENT, MISSION_ITEM_REACHED and its
GLOBAL_POSITION_INT, read through geodesy.LocalFrame)."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.cli import main
from layerpilot.cli.link import _flown
from layerpilot.geodesy import LocalFrame
from layerpilot.link.connection import open_connection
from layerpilot.link.mission_transfer import MissionItem
from layerpilot.link.qgc_plan import Plan, plan_from_waypoints, read_plan, write_plan
from layerpilot.sim.mavlink_vehicle import SITL_DATUM, EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter

WAYPOINTS = np.array([[12.0, 0.0, 8.0], [12.0, 15.0, 8.0], [-6.0, 15.0, 11.0]])  # map frame, home on the ground at 0
ACCEPTANCE_M = 2.0
HOLD_S = 1.0


class Watcher(threading.Thread):
    """A second MAVLink client on the vehicle's TCP port, keeping every message; ``on_reached(seq, conn)``
    is called for each MISSION_ITEM_REACHED."""

    def __init__(self, url: str, on_reached=None) -> None:
        super().__init__(daemon=True)
        self.conn = open_connection(url, 254, 190)
        self.messages: list = []
        self.on_reached = on_reached
        self.stop = threading.Event()
        self.start()

    def run(self) -> None:
        while not self.stop.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.05)
            if msg is None:
                continue
            self.messages.append(msg)
            if msg.get_type() == "MISSION_ITEM_REACHED" and self.on_reached is not None:
                self.on_reached(msg.seq, self.conn)

    def close(self) -> None:
        self.stop.set()
        self.join(timeout=2.0)
        self.conn.close()

    def of(self, kind: str) -> list:
        return [m for m in self.messages if m.get_type() == kind]


@pytest.fixture
def plan_file(tmp_path):
    plan = plan_from_waypoints(WAYPOINTS, SITL_DATUM, acceptance=ACCEPTANCE_M)
    held = [MissionItem(i.lat, i.lon, i.alt, params=(HOLD_S, ACCEPTANCE_M, 0.0, math.nan)) for i in plan.items]
    return write_plan(tmp_path / "three.plan", Plan(held, plan.home))


@pytest.fixture(params=["ardupilot", "px4"])
def vehicle(request):
    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, 0.0), ground_z=0.0), "tcp:127.0.0.1:0",
                              EndpointConfig(flavour=request.param)).start(speed=10.0 if request.param == "ardupilot"
                                                                           else 2.0)  # PX4's OFFBOARD: >= 2 Hz
                                                                           # of setpoints on its clock
    yield endpoint, f"tcp:127.0.0.1:{endpoint.addresses[0][1]}"
    endpoint.stop()


def test_the_vehicle_flies_the_plan_in_auto_and_reaches_each_waypoint_in_order(vehicle, plan_file, capsys):
    endpoint, url = vehicle
    px4 = endpoint.config.flavour == "px4"
    first = 0 if px4 else 1  # ArduPilot's item 0 is home; PX4's mission starts at 0
    watcher = Watcher(url)
    try:
        assert main(["link", "--mavlink", url, "--timeout", "60", "fly-plan", str(plan_file)]) == 0
    finally:
        watcher.close()
    out = capsys.readouterr().out
    assert "fly-plan: 3 mission items accepted by system 1" in out
    assert out.index("mission: flying to item 1 of 3") < out.index("mission: reached item 1 of 3") \
        < out.index("mission: flying to item 2 of 3") < out.index("mission: reached item 3 of 3") \
        < out.index("fly-plan: done")
    items = [first, first + 1, first + 2]
    assert [m.seq for m in watcher.of("MISSION_ITEM_REACHED")] == items
    current = [m.seq for m in watcher.of("MISSION_CURRENT")]
    flown = [s for i, s in enumerate(current) if i == 0 or s != current[i - 1]]
    assert flown[-3:] == items
    last = watcher.of("MISSION_CURRENT")[-1]
    assert (last.total, last.mission_state) == (3, mav.MISSION_STATE_COMPLETE)
    assert last.mission_mode == 1 or px4  # ArduCopter still in AUTO; PX4 may have left for AUTO.LOITER already
    if not px4:  # ArduCopter's words
        texts = [m.text for m in watcher.of("STATUSTEXT")]
        assert [t for t in texts if t.startswith(("Mission:", "Reached"))] == [
            "Mission: 1 WP", "Reached command #1", "Mission: 2 WP", "Reached command #2", "Mission: 3 WP",
            "Reached command #3"]
    assert "pilot took over" not in out
    # where the vehicle said it was when it reported each item reached: the plan's lat/lon through LocalFrame
    lat, lon, alt = (np.array(v) for v in zip(*[(i.lat, i.lon, i.alt) for i in read_plan(plan_file).items]))
    expected = np.column_stack(SITL_DATUM.from_geodetic(lat, lon, SITL_DATUM.alt + alt))  # home: on the datum
    for k, seq in enumerate(items):
        index = next(j for j, m in enumerate(watcher.messages)
                     if m.get_type() == "MISSION_ITEM_REACHED" and m.seq == seq)
        fix = next(m for m in reversed(watcher.messages[:index]) if m.get_type() == "GLOBAL_POSITION_INT")
        here = np.array(SITL_DATUM.from_geodetic(fix.lat * 1e-7, fix.lon * 1e-7, fix.alt * 1e-3), float)
        assert np.linalg.norm(here - expected[k]) <= ACCEPTANCE_M, (seq, here, expected[k])
        assert np.allclose(expected[k], WAYPOINTS[k], atol=0.011)  # the plan is the map's waypoints
    # the mission's end: ArduCopter stays in AUTO, PX4 switches to AUTO.LOITER; both hold at the last waypoint
    assert endpoint.mode == ("LOITER" if px4 else "AUTO") and endpoint.armed
    assert np.linalg.norm(endpoint.pose().position - WAYPOINTS[-1]) <= ACCEPTANCE_M


def test_a_pilot_taking_over_ends_the_flight_at_once_with_one_line(vehicle, plan_file, capsys):
    endpoint, url = vehicle
    px4 = endpoint.config.flavour == "px4"
    first = 0 if px4 else 1
    loiter = (4, 3) if px4 else (5, 0)  # DO_SET_MODE: PX4's main and sub mode, ArduCopter's custom mode

    def take_over(seq: int, conn) -> None:
        if seq == first:
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                       *loiter, 0, 0, 0, 0)

    watcher = Watcher(url, take_over)
    try:
        assert main(["link", "--mavlink", url, "--timeout", "60", "fly-plan", str(plan_file)]) == 1
    finally:
        watcher.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["layerpilot link fly-plan: error: flying the mission: pilot took over: mode LOITER; "
                   f"paused until {'MISSION' if px4 else 'AUTO'} is handed back"]
    assert endpoint.mode == "LOITER" and [m.seq for m in watcher.of("MISSION_ITEM_REACHED")] == [first]


def test_fly_plan_refuses_an_empty_plan_before_connecting(tmp_path, capsys):
    empty = write_plan(tmp_path / "empty.plan", Plan([], (SITL_DATUM.lat, SITL_DATUM.lon, SITL_DATUM.alt)))
    assert main(["link", "--mavlink", "tcp:127.0.0.1:5760", "fly-plan", str(empty)]) == 2
    assert "the plan has no mission items to fly" in capsys.readouterr().err


def test_a_waypoint_outside_the_geofence_is_refused_before_anything_is_uploaded(vehicle, tmp_path, capsys):
    endpoint, url = vehicle
    far = plan_from_waypoints(np.array([[12.0, 0.0, 8.0], [300.0, 0.0, 8.0]]), SITL_DATUM)  # fence: 100 m + 20 m
    path = write_plan(tmp_path / "far.plan", far)
    assert main(["link", "--mavlink", url, "--timeout", "20", "fly-plan", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("layerpilot link fly-plan: error: item 2 of the plan: ")
    assert "180.0 m outside the geofence" in err[0] and err[0].endswith("(nothing uploaded)")
    assert endpoint.mission.items == [] and not endpoint.armed


def ending(kind: str) -> list[MissionItem]:
    """A waypoint, a DO_CHANGE_SPEED (lat/lon 0, as QGC writes it) and a final LAND at another place at
    altitude 0 (as QGC writes it), or a final RTL at lat/lon 0."""
    wp = plan_from_waypoints(np.array([[12.0, 0.0, 8.0], [0.0, 15.0, 8.0]]), SITL_DATUM).items
    speed = MissionItem(0.0, 0.0, 0.0, command=mav.MAV_CMD_DO_CHANGE_SPEED, params=(1.0, 5.0, -1.0, 0.0))
    last = MissionItem(wp[1].lat, wp[1].lon, 0.0, command=mav.MAV_CMD_NAV_LAND, params=(0.0, 0.0, 0.0, math.nan)) \
        if kind == "land" else MissionItem(0.0, 0.0, 0.0, command=mav.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    return [wp[0], speed, last]


@pytest.mark.parametrize("kind, landed_at", [("land", (0.0, 15.0)), ("rtl", (0.0, 0.0))])
def test_a_plan_ending_in_land_or_rtl_is_flown_to_the_ground_and_succeeds(vehicle, tmp_path, capsys, kind, landed_at):
    """Items without a place (lat/lon 0: an RTL, a DO_ item) are not fenced as a point 5,337 km away; a LAND
    at altitude 0 is not under the fence's 2 m floor; the LAND flies to its point before it comes down; the
    disarm on the ground at the end is the mission done (exit 0)."""
    endpoint, url = vehicle
    path = write_plan(tmp_path / f"{kind}.plan", Plan(ending(kind), (SITL_DATUM.lat, SITL_DATUM.lon, SITL_DATUM.alt)))
    watcher = Watcher(url)
    try:
        assert main(["link", "--mavlink", url, "--timeout", "60", "fly-plan", str(path)]) == 0, \
            capsys.readouterr().err
    finally:
        watcher.close()
    out = capsys.readouterr().out
    assert "fly-plan: 3 mission items accepted by system 1" in out and "fly-plan: done" in out
    assert f"mission: item 3 of 3 ({kind.upper()}) ended on the ground, disarmed" in out
    first = 0 if endpoint.config.flavour == "px4" else 1
    assert [m.seq for m in watcher.of("MISSION_ITEM_REACHED")] == [first, first + 1]  # the waypoint, the DO item
    assert not endpoint.armed and endpoint.pose().position[2] == pytest.approx(0.0, abs=0.05)
    assert np.linalg.norm(endpoint.pose().position[:2] - landed_at) < 0.5, endpoint.pose().position
    # the flight's default bound (60 s + 3 s per metre) goes over where the items fly: 12 m out, then 19.2 m
    # to the LAND's point (or 12 m home) and 8 m down, not to lat/lon 0
    flown = _flown(read_plan(path), LocalFrame(*read_plan(path).home), 0.0)
    assert [(number, np.round(point, 1).tolist()) for number, _, point in flown] == [
        (1, [12.0, 0.0, 8.0]), (3, [*landed_at, 0.0])]
