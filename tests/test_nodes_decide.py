"""The decide node on real Zenoh: layer set + pose in, waypoint with explanation out; avoids the other drone."""

from __future__ import annotations

import contextlib
import time

import numpy as np
import pytest

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import GridLayersMessage, column_arrays, encode_layer_set
from layerpilot.geometry import Pose
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.map import VoxelMap
from layerpilot.missionfile import Mission
from layerpilot.mission.pilot import PilotConfig
from layerpilot.nodes.decide import DecideNode, decode_aggregates
from conftest import wait_for


def layer_payload(vehicle: str) -> bytes:
    """A 40 m x 40 m patch of ground around home seen at t = 1 s, in a 256 m window."""
    m = VoxelMap(1.0)
    xs, ys = np.meshgrid(np.arange(-20, 20.0) + 0.5, np.arange(-20, 20.0) + 0.5)
    pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
    m.insert(pts, np.array([0.0, 0.0, 30.0]), stamp=1.0)
    cl = m.column_layers(-128, -128, 256, 256)
    return encode_layer_set(GridLayersMessage(1.0, vehicle, cl.geometry, column_arrays(cl)))


@pytest.fixture
def sessions():
    ep = free_endpoint()
    ss = [open_session(BusConfig(endpoint=ep)) for _ in range(2)]
    yield ss
    for s in ss:
        s.close()


def test_decides_on_arrival_and_avoids_the_other_drone(sessions, tmp_path):
    node_session, world = sessions
    # balanced's weights with the paper's metres: footprint hops (r_e 28.9 m, r_i 202 m) reach past this small map
    metres = tmp_path / "metres.toml"
    metres.write_text("r_e = 10.0\nr_i = 100.0\n[weights]\nfringe = 0.3\ntime = 0.3\ndistance = 0.3\n")
    mission = Mission(vehicles=["uav1", "uav2"], decide=PilotConfig(behavior=str(metres)))
    nodes = [DecideNode(node_session, v, mission) for v in ("uav1", "uav2")]
    got: dict[str, list[msg.Waypoint]] = {"uav1": [], "uav2": []}
    decisions: list[msg.Decision] = []
    subs = [world.declare_subscriber(Keys(v).waypoint, lambda s, v=v: got[v].append(msg.decode_waypoint(s.payload.to_bytes())))
            for v in got]
    subs.append(world.declare_subscriber("layerpilot/*/decision",
                                         lambda s: decisions.append(msg.decode_decision(s.payload.to_bytes()))))
    for n in nodes:
        n.start()
    try:
        time.sleep(0.5)
        k1, k2 = Keys("uav1"), Keys("uav2")
        before = list(world.get(k1.aggregates, timeout=5.0))  # nothing ticked yet: an error reply, not silence
        assert len(before) == 1 and "no decision tick yet" in before[0].err.payload.to_string()
        world.put(k1.layers, layer_payload("uav1"))
        world.put(k1.pose, msg.encode_state(msg.State(2.0, "uav1", Pose(np.array([0.0, 0.0, 50.0])))))
        wait_for(lambda: len(got["uav1"]) >= 1 and decisions, "uav1's first waypoint and its decision")
        w1 = got["uav1"][0]
        assert w1.seq == 1 and w1.position[2] == 50.0
        assert 10.0 <= np.hypot(*w1.position[:2]) <= 100.0  # outside r_e, inside the area of interest
        d1 = decisions[0]
        names = [t.name for t in d1.terms]
        assert {"fringe", "time", "distance", "zone", "preference", "history"} <= set(names)
        assert d1.score > 0 and d1.behavior == str(metres)
        assert_aggregates_of_the_tick(world, nodes[0], w1, d1)

        # same map, same place, same behavior: uav2 would pick uav1's cell, but must stay r_e away
        wait_for(lambda: "uav1" in nodes[1]._others, "uav2 hearing uav1's target")
        world.put(k2.layers, layer_payload("uav2"))
        world.put(k2.pose, msg.encode_state(msg.State(2.0, "uav2", Pose(np.array([0.0, 0.0, 50.0])))))
        wait_for(lambda: len(got["uav2"]) >= 1, "uav2's first waypoint")
        assert np.hypot(*(got["uav2"][0].position[:2] - w1.position[:2])) >= 10.0

        # no new decision while flying; a new one on arrival
        world.put(k1.pose, msg.encode_state(msg.State(3.0, "uav1", Pose(w1.position * [0.5, 0.5, 1]))))
        time.sleep(1.5)
        assert {w.seq for w in got["uav1"]} == {1} and len(got["uav1"]) >= 2  # the same waypoint, repeated
        world.put(k1.pose, msg.encode_state(msg.State(9.0, "uav1", Pose(w1.position + [1.0, 0, 0]))))
        wait_for(lambda: got["uav1"][-1].seq == 2, "uav1's second waypoint")
        assert nodes[0].reached == 1
        flown = np.hypot(*(0.5 * w1.position[:2])) + np.hypot(*(0.5 * w1.position[:2] + [1.0, 0]))
        assert nodes[0].distance_flown == pytest.approx(flown)

        world.put(k1.layers, b"\x08\x01garbage")
        world.put(k1.pose, b"\xff" * 10)
        wait_for(lambda: nodes[0].rejects.total == 2, "both bad messages rejected")
    finally:
        for n in nodes:
            n.stop()
        for s in subs:
            s.undeclare()


def assert_aggregates_of_the_tick(world, node: DecideNode, w: msg.Waypoint, d: msg.Decision) -> None:
    """Asked on the bus, the decide node answers A0..A3 of the tick that chose ``w``: on its window (r_i
    around the drone, not the whole 256 m grid), placed in the map frame, the chosen cell scoring ``d.score``."""
    replies = list(world.get(Keys("uav1").aggregates, timeout=5.0))
    assert len(replies) == 1 and replies[0].ok is not None
    ls = decode_aggregates(replies[0].ok.payload.to_bytes(), "uav1")
    tick, r_i = node.pilot.maker.last_tick, node.pilot.behavior.r_i
    g = ls.geometry
    assert g == tick.placement and g.resolution == 1.0
    assert g.width < 256 and g.height < 256 and abs(g.width - (2 * r_i + 3)) <= 1  # the window, one cell of slack
    assert g.origin_x == pytest.approx(-r_i - 1.5, abs=1.0) and g.origin_y == pytest.approx(-r_i - 1.5, abs=1.0)
    for name, exact in tick.aggregates().items():
        np.testing.assert_allclose(ls.layers[name], exact, rtol=1e-3, atol=1e-4)  # float16 on the wire
    np.testing.assert_allclose(ls.layers["A2"], tick.a1 * tick.p, rtol=1e-3, atol=1e-4)
    row, col = g.cell_of(*w.position[:2])
    assert ls.layers["A3"][row, col] == pytest.approx(d.score, rel=1e-3)
    assert ls.layers["A3"][row, col] >= ls.layers["A3"].max() - node.pilot.behavior.noise - 1e-3
    assert ls.stamp == d.stamp and node.aggregates_answered == 1


def wide_payload(vehicle: str, half: float, stamp: float) -> bytes:
    m = VoxelMap(1.0)
    xs, ys = np.meshgrid(np.arange(-half, half) + 0.5, np.arange(-half, half) + 0.5)
    pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
    m.insert(pts, np.array([0.0, 0.0, 30.0]), stamp=stamp)
    cl = m.column_layers(-128, -128, 256, 256)
    return encode_layer_set(GridLayersMessage(stamp, vehicle, cl.geometry, column_arrays(cl)))


def behavior_file(tmp_path, text: str) -> str:
    path = tmp_path / "behavior.toml"
    path.write_text('weights = { fringe = 1.0 }\nnoise = 0.0\n' + text)
    return str(path)


@contextlib.contextmanager
def started_node(sessions, tmp_path, behavior_text: str, key: str, decode):
    """A decide node flying a fringe behavior (plus ``behavior_text``), the messages it puts on ``key``,
    and the world's session that feeds it; it has heard the first layer set and pose when yielded."""
    node_session, world = sessions
    node = DecideNode(node_session, "uav1", Mission(decide=PilotConfig(behavior=behavior_file(tmp_path, behavior_text))))
    got: list = []
    sub = world.declare_subscriber(key, lambda s: got.append(decode(s.payload.to_bytes())))
    node.start()
    try:
        k = Keys("uav1")
        time.sleep(0.5)
        world.put(k.layers, wide_payload("uav1", 20, 1.0))
        world.put(k.pose, msg.encode_state(msg.State(1.0, "uav1", Pose(np.array([0.0, 0.0, 50.0])))))
        wait_for(lambda: len(got) >= 1, "the first decision")
        yield node, got, world
    finally:
        node.stop()
        sub.undeclare()


@pytest.mark.parametrize("retarget", [True, False])
def test_live_node_retargets_while_flying_when_the_behavior_opts_in(sessions, tmp_path, retarget):
    k = Keys("uav1")
    text = f"[retarget]\nenabled = {str(retarget).lower()}\nmin_interval = 0.0\n"
    with started_node(sessions, tmp_path, text, k.waypoint, msg.decode_waypoint) as (node, got, world):
        first = got[0].position
        world.put(k.pose, msg.encode_state(msg.State(19.0, "uav1", Pose(first * [0.5, 0.5, 1.0]))))  # halfway
        time.sleep(0.3)
        world.put(k.layers, wide_payload("uav1", 60, 20.0))  # the map has grown past the target
        if retarget:
            wait_for(lambda: got[-1].seq == 2, "a new target while flying")
            assert np.hypot(*got[-1].position[:2]) > 55.0 and node.reached == 0
        else:
            time.sleep(1.5)
            assert {w.seq for w in got} == {1}


def test_live_node_follows_the_weight_schedule(sessions, tmp_path):
    k = Keys("uav1")
    text = "[[schedule]]\nafter_coverage = 0.5\nweights = { time = 1.0 }\n"
    with started_node(sessions, tmp_path, text, k.decision, msg.decode_decision) as (node, decisions, world):
        world.put(k.layers, wide_payload("uav1", 100, 40.0))  # the whole area of interest seen
        time.sleep(0.3)
        world.put(k.pose, msg.encode_state(msg.State(50.0, "uav1", Pose(decisions[0].waypoint))))  # arrived
        wait_for(lambda: len(decisions) >= 2, "the second decision")
        weighted = [{t.name for t in d.terms if t.weight > 0} - {"zone", "preference", "history"} for d in decisions]
        assert weighted[:2] == [{"fringe"}, {"time"}]


def test_a_drone_that_drops_out_frees_its_target(sessions):
    """Its decide node repeats its waypoint every second; when that stops for claim_timeout_s (the drone's
    processes were killed, its link lost) the others stop avoiding its target."""
    node_session, world = sessions
    mission = Mission(vehicles=["uav1", "uav2"], decide=PilotConfig(claim_timeout_s=1.5))
    node = DecideNode(node_session, "uav2", mission)
    node.start()
    try:
        time.sleep(0.3)
        repeat = msg.encode_waypoint(msg.Waypoint(1.0, "uav1", 1, np.array([40.0, 10.0, 50.0])))
        for _ in range(8):  # 2.4 s of repeats: longer than the timeout, still claimed
            world.put(Keys("uav1").waypoint, repeat)
            time.sleep(0.3)
        assert np.array_equal(node._others["uav1"], [40.0, 10.0])
        wait_for(lambda: "uav1" not in node._others, "uav1's claim to expire", timeout=5.0)
        world.put(Keys("uav3").waypoint, repeat)  # not a vehicle of the mission: rejected, counted
        wait_for(lambda: node.rejects.total == 1, "the stranger's waypoint rejected")
    finally:
        node.stop()
