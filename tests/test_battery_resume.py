"""Issue 14, item 5: the simulated battery drains as ArduCopter reports it and its failsafe RTLs; the
pilot turns home when the way home plus the reserve needs the charge left (in time, with real
numbers); a lock-step mission with a small battery ends with that return; the survey's state is
saved and a fresh pilot continues it (path history, schedule phase, counts; the map from the
snapshot) on one mission clock (cells of the first flight as old as they are, after_time phases
counting on); the link node RTLs on the pilot's battery return and reports the autopilot's own
battery failsafe as such, stamping its poses on the mission clock; `up --resume` needs a saved survey."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import wait_for
from test_link_flight import url_of
from test_link_reboot import flying_link_node
from layerpilot.bus.keys import Keys
from layerpilot.cli import main as cli_main
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.bus.messages import (MissionState, State, decode_mission_state, decode_state, encode_mission_state,
                                     encode_state)
from layerpilot.bus.session import BusConfig, free_endpoint, open_session, publish
from layerpilot.eval.mission import run_mission
from layerpilot.geometry import Pose
from layerpilot.link.connection import open_connection
from layerpilot.map import VoxelMap
from layerpilot.mission import resume as survey
from layerpilot.layers import compute_layers
from layerpilot.mission.build import build_pilot
from layerpilot.mission.clock import MissionClock
from layerpilot.missionfile import Override, load_mission
from layerpilot.mission.energy import RETURN_PHASE
from layerpilot.mission.map_service import MapService
from layerpilot.decide.behavior import load_behavior
from layerpilot.mission.pilot import Pilot, PilotConfig
from layerpilot.nodes.decide import DecideNode
from layerpilot.nodes.up import node_commands, up
from layerpilot.sim.battery import BatteryConfig
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter


def start_vehicle(battery: BatteryConfig, speed: float = 10.0) -> MavlinkVehicle:
    return MavlinkVehicle(Multicopter(position=(0.0, 0.0, 2.0), ground_z=2.0), "tcp:127.0.0.1:0",
                          EndpointConfig(battery=battery)).start(speed=speed)


def test_the_pilot_turns_home_in_time_to_land_with_the_reserve():
    """500 m from home at 50 m: 100 s back at 5 m/s + 50 s down = 150 s. A 5000 mAh pack at 15 A
    drains 1/1200 per s, so those 150 s take 12.5 %: with a 25 % reserve the pilot turns at 37.5 %
    or less, when the autopilot first reports 37 %, and lands with 24.5 %, above ArduCopter's
    BATT_LOW_MAH failsafe (750 mAh, 15 %) that the simulator copies."""
    cfg = PilotConfig(behavior="lawnmower", battery_reserve=0.25, return_speed=5.0)
    pilot = Pilot(cfg, load_behavior("lawnmower"), pattern=np.array([[300.0, 400.0, 50.0, 0.0]]))
    where, turned = (300.0, 400.0, 50.0), None
    for t in range(0, 1201):
        charge = round(100 * (1.0 - t / 1200.0)) / 100  # SYS_STATUS battery_remaining, whole percent
        command = pilot.step(where, float(t), None, battery=charge)
        if command is not None and command.reason == "battery":
            turned = (t, charge, command)
            break
    assert turned is not None
    t, charge, command = turned
    assert charge == 0.37 and t == 751  # the first reading of 37 % (37.4 % rounded), not one second later
    assert command.position == (0.0, 0.0, 50.0) and command.record()["scripted"] is False
    # measured from whole percents: 63 % in 751 s = 5.03 %/min (5.00 true), 12.6 % for the way home
    assert pilot.energy.why == "battery 37% <= reserve 25% + 12.6% for 150 s home (drain 5.03 %/min)"
    landing = charge - 150.0 / 1200.0
    assert landing == pytest.approx(0.245) and landing > BatteryConfig().low_mah / BatteryConfig().capacity_mah
    assert pilot.step(where, t + 1.0, None, battery=charge) is None  # the return is the flight's last command


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """A lock-step mission whose 500 mAh pack (2 min of flight) sends the pilot home after ~30 s."""
    mission = load_mission("default", [Override("--duration", "evaluation.duration", 90.0),
                                       Override("--step", "evaluation.step_s", 0.1),
                                       Override("--camera", "sim.camera", {"width": 160, "height": 120}),
                                       Override("--battery", "sim.battery",
                                                {"capacity_mah": 500.0, "low_mah": 50.0})])
    out = tmp_path_factory.mktemp("battery")
    return mission, out, run_mission(mission, out, record_inputs=True)


def test_a_lockstep_mission_with_a_small_battery_ends_with_a_battery_return(flown):
    mission, out, result = flown
    records = [json.loads(line) for line in (out / "decisions.jsonl").read_text().splitlines()]
    last = records[-1]
    assert last["reason"] == "battery" and last["waypoint"] == [0.0, 0.0, 50.0]
    assert all(r["reason"] != "battery" for r in records[:-1]) and len(records) >= 5
    ended = json.loads((out / "metrics.json").read_text())["settings"]["ended"]
    found = re.fullmatch(r"battery: battery (\d+)% <= reserve 25% \+ ([\d.]+)% for (\d+) s home "
                         r"\(drain ([\d.]+) %/min\); home at t = ([\d.]+) s", ended)
    assert found, ended
    charge, home_s, drain, home_at = (float(found[k]) for k in (1, 3, 4, 5))
    # 500 mAh at 15 A is 2 min: 50 %/min, measured once 30 s have passed, when the return came
    assert drain == pytest.approx(50.0, abs=2.0) and 30.0 <= last["time"] <= 31.0
    assert 55 <= home_s <= 75  # 50 s down from 50 m, the rest back at 5 m/s
    landing = charge / 100 - home_s / 120.0
    # The drain is first known at 30 s and the return came at that reading; by then the default
    # behavior's footprint hops at survey speed are far enough out that the pack lands a little under
    # the 25 % reserve (the rule itself, with the drain known: test_the_pilot_turns_home_in_time_to_land_with_the_reserve).
    assert landing > 50.0 / 500.0  # before the autopilot's own failsafe (low_mah = 50) would trigger
    assert last["time"] < home_at < 60.0  # the mission ended at home, not at its 90 s duration


def test_the_survey_is_saved_and_a_fresh_pilot_continues_it(flown, tmp_path):
    mission, out, result = flown
    state = json.loads((out / "survey.json").read_text())
    # the pilot that flew, rebuilt by replaying its inputs (as the replay test does): what resume must equal
    flew = build_pilot(mission.core)
    for step in result.pilot_inputs:
        flew.step(step.position, step.time, to_column_layers(decode_layer_set(step.layer_set)))
    resumed = build_pilot(mission.core)
    survey.load(resumed, out / "survey.json")
    assert resumed.seq == flew.seq + 1 == state["seq"]  # + the battery return
    assert resumed.reached == state["reached"] >= 3 and len(resumed.ticks) == len(flew.ticks) >= 4
    assert np.array_equal(resumed.maker.history.values, flew.maker.history.values)  # H to the bit
    assert resumed.maker.schedule.phase == flew.maker.schedule.phase
    h = resumed.maker.history.values
    assert h.min() == 0.0 and (h < 1.0).sum() > 100  # it knows where the drone has been
    # the map comes back from the snapshot the map server reloads at start
    cfg = replace(mission.map_server, snapshot=str(tmp_path / "map.ot"))
    MapService(cfg, VoxelMap.load(out / "map.ot")).snapshot()
    service = MapService.start(cfg)
    assert service.map.stats()["leaves"] == VoxelMap.load(out / "map.ot").stats()["leaves"] > 1000
    # the new flight's stamps go on from the saved mission time (the autopilot's clock starts at 0 again)
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "uav1.json").write_text(json.dumps(state))
    clock = survey.clock_after(tmp_path / "state", ["uav1", "uav2"])  # uav2 saved nothing: uav1's time
    assert clock.start == state["time"] > 30.0 and clock(0.5) == state["time"] + 0.5
    # a cloud of the new flight, 0.5 s after its autopilot booted, sees something 45 m up, 60 m north-east
    patch = np.array([(60.0 + dx, 60.0 + dy, 45.0) for dx in np.arange(-3, 3, 0.5) for dy in np.arange(-3, 3, 0.5)])
    service.insert(patch, np.array([60.0, 60.0, 80.0]), None, stamp=clock(0.5))
    columns = service.columns()
    now = clock(1.0)
    time_layer = compute_layers(columns, resumed.layer_context(columns, (0.0, 0.0, 50.0), now), ["time"]).layers["time"]
    seen = columns.observed
    fresh = seen & (np.abs(columns.last_seen - clock(0.5)) < 1e-3)  # the map keeps times in float32
    first = seen & (columns.last_seen == columns.last_seen[seen].min())  # the cells the first flight saw first
    assert fresh.sum() >= 30 and first.any() and (now - columns.last_seen[seen] > 0.499).all()  # none in the future
    assert (time_layer[fresh] == 0.0).all() and (time_layer[first] == 1.0).all()  # just seen; seen longest ago
    # on the vehicle's clock (restarted at 0) the patch, stamped 0.5, would be older than the whole first flight
    assert (columns.last_seen[seen & ~fresh] > 0.5 + 1e-3).all()
    # the pilot continues: a fresh battery (a swap), at home, a new decision numbered after the saved ones
    command = resumed.step((0.0, 0.0, 50.0), now, columns, battery=1.0)
    assert command is not None and command.reason == "resume" and command.seq == state["seq"] + 1
    assert command.time == now and command.decision.history > 0.0  # not a cell it has just been over


def test_an_after_time_phase_counts_on_the_mission_clock_after_a_resume(flown, tmp_path):
    """A phase after 60 mission s: a survey saved at 50 s reaches it 10 s into the resumed flight, on the
    mission clock; on the restarted autopilot's clock it would wait until 60 s of the new flight."""
    _, out, _ = flown
    behavior = tmp_path / "patrol-after-a-minute.toml"
    behavior.write_text(Path("config/behaviors/explore-then-patrol.toml").read_text().replace(
        "after_coverage = 0.85", "after_time = 60.0"))
    mission = load_mission("default", [Override("--behavior", "decide.behavior", str(behavior)),
                                       Override("--state", "decide.state", str(tmp_path / "state"))])
    survey.save(build_pilot(mission.core), survey.state_file(tmp_path / "state", "uav1"), 50.0, 45.0)
    clock = survey.clock_after(tmp_path / "state", mission.vehicles)
    service = MapService(mission.map_server, VoxelMap.load(out / "map.ot"))
    phases = {}
    for name, stamp in (("mission clock", clock(10.0)), ("vehicle clock", 10.0)):
        pilot = build_pilot(mission.core)
        survey.load(pilot, survey.state_file(tmp_path / "state", "uav1"))
        command = pilot.step((0.0, 0.0, 50.0), stamp, service.columns(), battery=1.0)
        phases[name] = (pilot.maker.schedule.phase, command.decision.weights)
    assert phases == {"mission clock": (1, {"time": 1.0}), "vehicle clock": (0, {"fringe": 1.0})}


def test_resume_keeps_the_schedule_phase_and_refuses_what_it_cannot_use(tmp_path):
    mission = load_mission("default", [Override("--behavior", "decide.behavior", "explore-then-patrol")])
    pilot = build_pilot(mission.core)
    pilot.maker.schedule.phase = 1  # past "explore until 85 % observed"
    survey.save(pilot, tmp_path / "uav1.json", 100.0, 100.0)
    fresh = build_pilot(mission.core)
    assert survey.load(fresh, tmp_path / "uav1.json")["flown_s"] == 100.0 and fresh.maker.schedule.phase == 1
    with pytest.raises(ValueError, match="saved by behavior 'explore-then-patrol', the mission flies 'view-side'"):
        survey.load(build_pilot(load_mission("default").core), tmp_path / "uav1.json")
    (tmp_path / "bad.json").write_text('{"version": 1, "behav')
    with pytest.raises(ValueError, match="bad.json: damaged mission state"):
        survey.load(build_pilot(mission.core), tmp_path / "bad.json")
    with pytest.raises(ValueError, match="none.json: no saved mission state to resume"):
        survey.load(build_pilot(mission.core), tmp_path / "none.json")


def test_up_resume_without_a_saved_survey_says_so(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text(f'[decide]\nstate = "{tmp_path / "state"}"\n')
    with pytest.raises(ValueError, match="--resume: no saved survey state for uav1 in decide.state"):
        up(str(m), resume=True, log_dir=tmp_path / "logs")
    assert not (tmp_path / "logs").exists()  # nothing was started
    assert cli_main(["up", "--mission", str(m), "--resume", "--log-dir", str(tmp_path / "logs")]) == 2


def test_up_resume_starts_the_sim_and_link_nodes_on_the_saved_mission_clock(tmp_path):
    """What `up --resume` gives its nodes: the clock start read once from the saved states (the newest of
    the vehicles'), and one mission id for every decide node (so that a restarted one continues)."""
    mission = load_mission("default", [Override("--state", "decide.state", str(tmp_path / "state"))])
    for vehicle, time in (("uav1", 38.5), ("uav2", 41.25)):
        survey.save(build_pilot(mission.core), survey.state_file(tmp_path / "state", vehicle), time, time - 5.0)
    start = survey.clock_after(tmp_path / "state", ["uav1", "uav2"]).start
    nodes = {n.name: n.argv for n in node_commands(tmp_path / "m.toml", ["uav1", "uav2"], None, resume=True,
                                                    clock_start=start, mission_id="run7")}
    assert start == 41.25
    for v in ("uav1", "uav2"):
        assert nodes[f"sim/{v}"][-2:] == nodes[f"link/{v}"][-2:] == ["--clock-start", "41.25"]
        assert nodes[f"decide/{v}"][-3:] == ["--mission-id", "run7", "--resume"]
    (tmp_path / "state" / "uav2.json").write_text('{"time": "soon"}')
    with pytest.raises(ValueError, match="uav2.json: damaged mission state: ValueError"):
        survey.clock_after(tmp_path / "state", ["uav1", "uav2"])
    for bad in ("NaN", "-3.0"):  # the clock's own check, naming the file
        (tmp_path / "state" / "uav2.json").write_text(f'{{"time": {bad}}}')
        with pytest.raises(ValueError, match=r"uav2\.json: damaged mission state: ValueError: mission clock start: "
                                             r"expected finite seconds >= 0, got (nan|-3\.0)"):
            survey.clock_after(tmp_path / "state", ["uav1", "uav2"])


def test_up_sets_a_saved_survey_aside_before_any_node_starts(tmp_path, capsys):
    """`up` without --resume moves the saved survey to uav1.json.bak itself, so its warning is true even for a
    run that ends before the decide node starts."""
    m = tmp_path / "m.toml"
    m.write_text(f'[decide]\nstate = "{tmp_path / "state"}"\n')
    path = survey.state_file(tmp_path / "state", "uav1")
    survey.save(build_pilot(load_mission(str(m)).core), path, 38.5, 33.5, "run1")
    saved = path.read_text()
    assert cli_main(["up", "--mission", str(m), "--duration", "0.2", "--log-dir", str(tmp_path / "logs")]) == 0
    assert (tmp_path / "state" / "uav1.json.bak").read_text() == saved
    assert "the surveys saved in decide.state for uav1 are kept as <vehicle>.json.bak" in capsys.readouterr().out


def test_a_new_survey_keeps_another_runs_saved_state_as_bak(tmp_path, caplog):
    """A decide node of a new run (no --resume) does not overwrite the survey another run saved: it keeps it as
    uav1.json.bak and says so once; a node restarted within the same run continues its predecessor's state."""
    mission = load_mission("default", [Override("--state", "decide.state", str(tmp_path / "state"))])
    path = survey.state_file(tmp_path / "state", "uav1")
    survey.save(build_pilot(mission.core), path, 38.5, 33.5, "run1")
    saved, bak = path.read_text(), tmp_path / "state" / "uav1.json.bak"
    with open_session(BusConfig(endpoint=free_endpoint())) as session:
        assert DecideNode(session, "uav1", mission, mission_id="run1").continued  # a restart: nothing set aside
        assert path.read_text() == saved and not bak.exists()
        DecideNode(session, "uav1", mission, mission_id="run2")
    assert bak.read_text() == saved and not path.exists()
    warnings = [r.getMessage() for r in caplog.records if "kept as" in r.getMessage()]
    assert warnings == [f"a new survey (no --resume): the one saved by run run1 is kept as {bak} (rename it back "
                        "and run `up --resume` to continue it)"]


def test_the_simulated_battery_fails_safe_as_arducopter_and_the_link_node_reports_it_as_such():
    """200 mAh at 15 A: 48 s of flight; BATT_LOW_MAH 100 -> the autopilot's own RTL 24 s after arming (2.4 s
    at 10x; no idle draw: what the ground wait costs depends on the machine's load). The link node was
    given a mission clock started at 500 s (a resumed survey's saved time): its poses say 500 s + the
    autopilot's time_boot_ms."""
    vehicle = start_vehicle(BatteryConfig(capacity_mah=200.0, low_mah=100.0, idle_current_a=0.0))
    gcs = open_connection(url_of(vehicle), 255, 190)
    gcs.mav.command_long_send(1, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, mav.MAVLINK_MSG_ID_BATTERY_STATUS, 1e6,
                              0, 0, 0, 0, 0)  # a ground station asks for it: ArduCopter streams nothing unasked
    stamps: list[tuple[float, float]] = []  # (pose stamp, the vehicle's uptime when it arrived)
    try:
        with flying_link_node(vehicle, MissionClock(500.0), end_action="loiter") as (node, session):
            flying = vehicle.uptime  # the node flies: every pose from now on is later on the autopilot's clock
            sub = session.declare_subscriber(Keys("uav1").pose, lambda s: stamps.append(
                (decode_state(s.payload.to_bytes()).stamp, vehicle.uptime)))
            wait_for(lambda: node.phase.startswith("returning home"), "the autopilot's failsafe", timeout=20)
            sub.undeclare()
            vehicle.pause_output()  # what was sent so far, and no more
            link = node.link
            assert vehicle.mode == "RTL" and "Battery 1 is low 15.00V used 100 mAh" in link.state.texts  # ArduCopter's
            # the autopilot's own failsafe, not a pilot: the text came just before the mode change
            found = re.fullmatch(r"returning home: autopilot failsafe: battery \(Battery 1 is low 15\.00V used "
                                 r"100 mAh, (\d+)% left\): RTL", node.phase)
            # the charge at the mode's heartbeat: below the failsafe's 50 %, above what it has now (it drains on)
            assert found and int(found[1]) <= 50, node.phase
            assert link.upsets[-1] == ("failsafe", link.failsafe) and link.failsafe in link.events
            assert not any("took over" in e for e in link.events) and node.end == ""
        assert vehicle.mode == "RTL"  # the mission's end (end_action loiter) leaves the autopilot's return alone
        assert len(stamps) > 5 and all(500.0 < stamp <= 500.0 + uptime for stamp, uptime in stamps)
        assert all(b[0] >= a[0] for a, b in zip(stamps, stamps[1:]))  # the autopilot's clock only goes on
        assert stamps[-1][0] > 500.0 + flying  # ... up to the failsafe: the stamps follow the flight
        statuses = []  # every BATTERY_STATUS the ground station got; the newest counts
        while (m := gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=0.5)) is not None:
            statuses.append(m)
        status = statuses[-1]
        assert statuses[0].current_battery == 0 and status.current_battery == 1500  # disarmed, then 15 A armed
        assert int(found[1]) >= status.battery_remaining
        assert 100 <= status.current_consumed < 200  # mAh: past BATT_LOW_MAH, still drawing while it returns
        assert status.battery_remaining == pytest.approx(100 * (1 - status.current_consumed / 200), abs=1)
        assert status.voltages[0] == pytest.approx(1000 * (13.2 + 3.6 * status.battery_remaining / 100), abs=40)
    finally:
        gcs.close()
        vehicle.stop()


def test_link_node_commands_rtl_when_the_pilot_turns_home_for_the_battery():
    vehicle = start_vehicle(BatteryConfig())
    try:
        with flying_link_node(vehicle, end_action="loiter") as (node, session):
            publish(session, Keys("uav1").state, encode_mission_state(MissionState(
                10.0, "uav1", RETURN_PHASE, 7, 6, 300.0, np.array([0.0, 0.0, 50.0]))))
            wait_for(lambda: node.phase.startswith("returning home"), "the node to turn home", timeout=10)
            assert node.phase == ("returning home for the battery: RTL acknowledged (COMMAND_ACK accepted, "
                                  "mode RTL)") and vehicle.mode == "RTL"
        assert vehicle.mode == "RTL"  # the mission's end (end_action loiter) leaves the return alone
    finally:
        vehicle.stop()


def test_an_unacknowledged_battery_rtl_is_tried_again_and_the_mission_end_still_follows():
    """The autopilot refuses RTL (ArduPilot: FAILED): no return, so the node keeps flying, tries again at each
    wake, and its end still commands the end action: the vehicle is never left in GUIDED unsupervised."""
    vehicle = start_vehicle(BatteryConfig())
    answer, refused = vehicle._command, []
    vehicle._command = lambda msg: (refused.append(msg.command), mav.MAV_RESULT_FAILED)[1] \
        if msg.command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH else answer(msg)
    try:
        with flying_link_node(vehicle, end_action="loiter") as (node, session):
            publish(session, Keys("uav1").state, encode_mission_state(MissionState(
                10.0, "uav1", RETURN_PHASE, 7, 6, 300.0, np.array([0.0, 0.0, 50.0]))))
            wait_for(lambda: len(refused) >= 3, "the RTL to be tried again", timeout=20)
            assert node.phase == "flying" and vehicle.mode == "GUIDED" and node.rtl_refusals >= 2
            assert node.end.startswith("RTL rejected")
        assert vehicle.mode == "LOITER" and node.end.startswith("LOITER acknowledged"), node.end
    finally:
        vehicle.stop()


def test_guided_handed_back_after_the_autopilots_battery_return_is_flown_and_ended_again():
    """After the autopilot's own RTL a pilot hands GUIDED back: the node flies it again, and its end commands
    the end action (without, the vehicle would hover in GUIDED with nothing supervising it)."""
    vehicle = start_vehicle(BatteryConfig(capacity_mah=200.0, low_mah=100.0, idle_current_a=0.0))
    gcs = None
    try:
        with flying_link_node(vehicle, end_action="loiter") as (node, session):
            wait_for(lambda: node.phase.startswith("returning home: autopilot failsafe"), "the failsafe", timeout=20)
            gcs = open_connection(url_of(vehicle), 255, 190)  # the pilot's ground station
            gcs.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                      4, 0, 0, 0, 0, 0)  # GUIDED
            wait_for(lambda: node.phase == "flying", "the node to fly again", timeout=10)
            assert vehicle.mode == "GUIDED" and vehicle.armed
        assert vehicle.mode == "LOITER" and node.end.startswith("LOITER acknowledged"), node.end
    finally:
        if gcs is not None:
            gcs.close()
        vehicle.stop()


def test_decide_node_turns_home_on_the_charge_its_pose_carries_and_saves_the_survey(tmp_path):
    """The live driver: poses with the link's charge reach the node's pilot, armed ones only (the ground
    would dilute the drain: 70 % in 110 s); 70 % in 100 s is 0.7 %/s, and 150 s home (500 m at 5 m/s,
    50 m down) need 105 % + the reserve: home at once."""
    mission = load_mission("default", [Override("--state", "decide.state", str(tmp_path / "state"))])
    ep = free_endpoint()
    k = Keys("uav1")
    heard: list[MissionState] = []
    with open_session(BusConfig(endpoint=ep)) as node_session, open_session(BusConfig(endpoint=ep)) as world:
        node = DecideNode(node_session, "uav1", mission)
        sub = world.declare_subscriber(k.state, lambda s: heard.append(decode_mission_state(s.payload.to_bytes())))
        node.start()
        poses = world.declare_publisher(k.pose)
        try:  # a pose put before the node's subscription matches is lost: wait for it
            wait_for(lambda: poses.matching_status.matching, "the node's pose subscription", timeout=10)
            for stamp, charge, armed in ((0.0, 1.0, False), (10.0, 1.0, True), (110.0, 0.3, True)):
                pose = Pose.from_euler(0.0, 0.0, 0.0, np.array([300.0, 400.0, 50.0]))
                poses.put(encode_state(State(stamp, "uav1", pose, armed=armed, battery=charge)))
                wait_for(lambda: node._first_stamp is not None and (  # the flight's first pose, stepped
                    node.pilot.energy._last is not None and node.pilot.energy._last[0] == stamp or not armed),
                    "the pose to reach the pilot", timeout=10)
            wait_for(lambda: any(s.phase == RETURN_PHASE for s in heard), "the battery return", timeout=10)
        finally:
            poses.undeclare()
            sub.undeclare()
            node.stop()
    assert np.allclose(heard[-1].target, (0.0, 0.0, 50.0)) and "home (drain 42.00 %/min)" in node.pilot.energy.why
    saved = json.loads((tmp_path / "state" / "uav1.json").read_text())
    assert saved["ending"] == "battery" and saved["seq"] == 1 and saved["flown_s"] == pytest.approx(110.0)
