"""The next flight: planned over a map's gaps, written as a QGroundControl .plan, uploaded over MAVLink
to the simulated vehicle and read back (`layerpilot plan next`, `layerpilot link upload`)."""

from __future__ import annotations

import json
import math
import socket

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import wait_for
from layerpilot.cli import main
from layerpilot.decide import area_geometry, load_behavior
from layerpilot.decide.next_flight import plan_next_flight
from layerpilot.geodesy import LocalFrame
from layerpilot.link.connection import open_connection
from layerpilot.link.mission_transfer import MissionItem, MissionTransferError, upload_mission
from layerpilot.link.qgc_plan import read_plan
from layerpilot.map import VoxelMap
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter

ORIGIN = (47.397742, 8.545594, 488.0)  # the simulated vehicle's home (its default geodetic origin)
FRAME = LocalFrame(*ORIGIN)


def same_item(a: MissionItem, b: MissionItem) -> bool:
    """Equal after the wire's rounding (1e-7 degrees, float32 altitude and params; NaN equals NaN)."""
    def close(u: float, v: float, tol: float) -> bool:
        return (math.isnan(u) and math.isnan(v)) or abs(u - v) <= tol
    return ((a.command, a.frame, a.autocontinue) == (b.command, b.frame, b.autocontinue)
            and close(a.lat, b.lat, 1.5e-7) and close(a.lon, b.lon, 1.5e-7) and close(a.alt, b.alt, 1e-4)
            and all(close(u, v, 1e-5) for u, v in zip(a.params, b.params)))


def half_seen_map() -> VoxelMap:
    """Flat ground seen on the western half (x < 0) of the exploration preset's area (radius 100 m)."""
    m = VoxelMap(2.0)
    for cx in (-90, -30):
        for cy in (-90, -30, 30, 90):
            xs, ys = np.meshgrid(np.arange(cx - 30, cx + 30, 1.0) + 0.5, np.arange(cy - 30, cy + 30, 1.0) + 0.5)
            pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
            m.insert(pts, np.array([cx, cy, 50.0]), stamp=10.0)
    return m


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    run = tmp_path_factory.mktemp("run")
    half_seen_map().save(run / "map.ot")
    args = ["plan", "next", str(run), "--behavior", "exploration", "--origin", *map(str, ORIGIN), "--footprint", "15"]
    assert main(args) == 0
    return run / "next.plan"


def test_the_waypoints_lie_over_the_unobserved_half(planned):
    doc = json.loads(planned.read_text())
    params = np.array([item["params"][4:] for item in doc["mission"]["items"]], float)
    x, y, _ = FRAME.from_geodetic(params[:, 0], params[:, 1], 0.0)
    assert 30 <= len(x) <= 100
    assert (x > -15).all()  # every footprint reaches into the gap
    assert np.mean(x > 0) > 0.95 and np.all(np.hypot(x, y) < 100 + 15)
    # and they cover it: 95 % of the unobserved half lies within 15 m of a waypoint
    gx, gy = np.meshgrid(np.arange(1, 100, 2.0), np.arange(-99, 100, 2.0))
    gap = np.hypot(gx, gy) < 99
    near = np.min(np.hypot(gx[gap][:, None] - x, gy[gap][:, None] - y), axis=1) <= 15
    assert near.mean() >= 0.95


def test_stale_columns_are_gaps_and_a_time_only_behavior_stops_when_it_covers_none():
    m = half_seen_map()
    behavior = load_behavior("exploration")
    columns = m.column_layers_for(area_geometry(behavior.area, (0, 0), 2.0))
    fresh = plan_next_flight(columns, behavior, footprint=15)
    stale = plan_next_flight(columns, behavior, footprint=15, now=1000.0, stale_after=60.0)  # all seen at t = 10
    assert fresh.gaps.sum() / columns.observed.size == pytest.approx(0.27, abs=0.02)  # half the circle's cells
    assert stale.gaps.sum() == 2 * fresh.gaps.sum()  # the whole circle
    assert len(stale.waypoints) == 100 and stale.coverage > 0.85  # up to the cap: twice the area to cover
    assert (stale.waypoints[:, 0] < 0).sum() > 10  # the stale western half is flown too
    time_only = plan_next_flight(columns, load_behavior("time"), footprint=15, max_idle=5)
    assert time_only.decisions > len(time_only.waypoints)  # its choices over seen cells were not kept
    assert (fresh.stopped, stale.stopped, time_only.stopped) == ("coverage", "max_waypoints", "max_idle")
    assert fresh.coverage >= 0.95 and len(fresh.waypoints) < 100


def test_plan_next_says_when_it_stopped_at_the_waypoint_cap(tmp_path, capsys):
    half_seen_map().save(tmp_path / "map.ot")
    assert main(["plan", "next", str(tmp_path), "--behavior", "exploration", "--origin", *map(str, ORIGIN),
                 "--footprint", "15", "--max-waypoints", "3"]) == 0
    out = capsys.readouterr().out
    assert "plan: 3 waypoints" in out
    assert "stopped: --max-waypoints 3 reached before the target coverage (95%)" in out


def test_the_plan_file_is_what_qgroundcontrol_reads(planned):
    doc = json.loads(planned.read_text())
    assert (doc["fileType"], doc["version"], doc["mission"]["version"]) == ("Plan", 1, 2)
    assert doc["mission"]["firmwareType"] == 3 and doc["mission"]["vehicleType"] == 2
    assert doc["mission"]["plannedHomePosition"] == pytest.approx(list(ORIGIN))
    assert doc["geoFence"] == {"version": 2, "circles": [], "polygons": []}
    assert doc["rallyPoints"] == {"version": 2, "points": []}
    for i, item in enumerate(doc["mission"]["items"], 1):
        assert (item["type"], item["command"], item["frame"], item["doJumpId"]) == ("SimpleItem", 16, 3, i)
        assert item["autoContinue"] is True
        hold, acceptance, pass_radius, yaw, lat, lon, alt = item["params"]
        assert (hold, acceptance, pass_radius, yaw) == (0.0, 2.0, 0.0, None)
        assert alt == item["Altitude"] == 50.0  # the behavior's altitude above home
        assert abs(lat - ORIGIN[0]) < 0.002 and abs(lon - ORIGIN[1]) < 0.002  # within ~150 m of home
    assert read_plan(planned).items[0].lat == doc["mission"]["items"][0]["params"][4]


def start_vehicle(flavour: str = "ardupilot") -> tuple[MavlinkVehicle, str]:
    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, 0.0), ground_z=0.0), "tcp:127.0.0.1:0",
                              EndpointConfig(flavour=flavour)).start(speed=10.0)
    return endpoint, f"tcp:127.0.0.1:{endpoint.addresses[0][1]}"


@pytest.fixture
def vehicle():
    endpoint, url = start_vehicle()
    yield endpoint, url
    endpoint.stop()


def gcs(url: str):
    conn = open_connection(url, 255, 190)
    heartbeat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
    assert heartbeat is not None
    return conn, (heartbeat.get_srcSystem(), heartbeat.get_srcComponent())


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_upload_then_download_gives_the_same_items(planned, flavour, tmp_path, capsys):
    endpoint, url = start_vehicle(flavour)
    try:
        assert main(["link", "--mavlink", url, "--timeout", "10", "upload", str(planned)]) == 0
        plan = read_plan(planned)
        assert f"upload: {len(plan.items)} mission items accepted by system 1" in capsys.readouterr().out
        # what the vehicle stores: ArduPilot keeps home as item 0, PX4 the plan's items alone
        stored = endpoint.mission.items
        assert len(stored) == len(plan.items) + (flavour == "ardupilot")
        assert main(["link", "--mavlink", url, "--timeout", "10", "download", str(tmp_path / "back.plan")]) == 0
    finally:
        endpoint.stop()
    back = read_plan(tmp_path / "back.plan")
    assert back.firmware == flavour and len(back.items) == len(plan.items)
    assert all(same_item(a, b) for a, b in zip(plan.items, back.items))
    assert back.home == pytest.approx(ORIGIN, abs=2e-7)  # ArduPilot: its item 0; PX4: its HOME_POSITION
    assert math.isnan(back.items[0].params[3]) and back.items[-1].alt == 50.0


def test_a_vehicle_that_stops_answering_fails_the_upload_with_a_clear_error(vehicle):
    endpoint, url = vehicle
    conn, target = gcs(url)
    try:
        endpoint.pause_output()
        with pytest.raises(MissionTransferError, match=r"upload: no MISSION_REQUEST_INT for item 0 from system 1 "
                                                       r"after 3 tries of 0.2 s \(is the vehicle connected"):
            upload_mission(conn, [MissionItem(47.4, 8.5, 30.0)], target, timeout=0.2, retries=2)
        wait_for(lambda: endpoint.messages_received >= 3, "the vehicle to receive the three MISSION_COUNTs")
    finally:
        conn.close()
    assert endpoint.mission.items == []


def test_the_vehicle_refuses_what_it_cannot_fly(vehicle):
    _, url = vehicle
    conn, target = gcs(url)
    try:
        items = [MissionItem(47.4, 8.5, 30.0), MissionItem(47.4, 8.5, 30.0, command=mav.MAV_CMD_DO_SET_SERVO)]
        with pytest.raises(MissionTransferError, match="refused the mission: MAV_MISSION_UNSUPPORTED .at item 1"):
            upload_mission(conn, items, target, timeout=1.0)
    finally:
        conn.close()


def test_a_broken_plan_file_is_a_clear_error(tmp_path, capsys):
    bad = tmp_path / "bad.plan"
    bad.write_text(json.dumps({"fileType": "Plan", "mission": {"plannedHomePosition": [1, 2, 3],
                                                               "items": [{"type": "ComplexItem"}]}}))
    assert main(["link", "--mavlink", "tcp:127.0.0.1:5760", "upload", str(bad)]) == 2
    assert "only SimpleItem is supported" in capsys.readouterr().err


def test_no_autopilot_on_the_link_is_a_one_line_error(planned, capsys):
    with socket.socket() as silent:  # accepts connections (the kernel's backlog) and never says anything
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        url = f"tcp:127.0.0.1:{silent.getsockname()[1]}"
        assert main(["link", "--mavlink", url, "--timeout", "0.3", "upload", str(planned)]) == 1
    assert capsys.readouterr().err == f"layerpilot link upload: error: no autopilot HEARTBEAT on {url} within 0.3 s\n"
