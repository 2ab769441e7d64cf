"""The live view asks the bus only for what it shows: no cloud of a vehicle crosses to it."""

from __future__ import annotations

import rerun as rr

from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.missionfile import Mission
from layerpilot.viz.live import LiveView
from layerpilot.viz.scene import MissionScene
from conftest import wait_for


def test_live_view_subscribes_to_what_it_shows_and_not_to_clouds() -> None:
    endpoint = free_endpoint()
    view_session = open_session(BusConfig(endpoint=endpoint))
    robot = open_session(BusConfig(mode="client", endpoint=endpoint))  # another process's side of the link
    view = LiveView(view_session, Mission(), MissionScene(rr.RecordingStream("test-topics")), "uav1")
    k = Keys("uav1")
    publishers = {t: robot.declare_publisher(k.topic(t)) for t in ("cloud", "pose", "camera", "layers", "decision")}
    publishers["health"] = robot.declare_publisher(k.health("map-server"))
    try:
        view.start()
        wait_for(lambda: all(p.matching_status.matching for t, p in publishers.items() if t != "cloud"),
                 "the view's subscribers reaching the other session")
        assert not publishers["cloud"].matching_status.matching  # a cloud put now goes nowhere
    finally:
        view.stop()
        for p in publishers.values():
            p.undeclare()
        robot.close()
        view_session.close()


def test_live_view_draws_the_other_drones_of_a_fleet_and_rejects_a_pose_on_the_wrong_key(tmp_path) -> None:
    import numpy as np
    from rerun.chunk import RrdReader

    from layerpilot.bus import messages as msg
    from layerpilot.geometry import Pose

    endpoint = free_endpoint()
    view_session = open_session(BusConfig(endpoint=endpoint))
    robot = open_session(BusConfig(mode="client", endpoint=endpoint))
    stream = rr.RecordingStream("test-fleet")
    stream.save(tmp_path / "view.rrd")
    view = LiveView(view_session, Mission(vehicles=["uav1", "uav2"]), MissionScene(stream), "uav1", period=0.05)
    k = Keys("uav2")
    pose, decision = robot.declare_publisher(k.topic("pose")), robot.declare_publisher(k.topic("decision"))
    try:
        view.start()
        wait_for(lambda: pose.matching_status.matching and decision.matching_status.matching,
                 "the view's fleet subscribers reaching the other session")
        pose.put(msg.encode_state(msg.State(3.0, "uav3", Pose.from_euler(0, 0, 0, [9.0, 9.0, 40.0]))))  # wrong key
        wait_for(lambda: view.rejects.total == 1, "the pose on another drone's key rejected")
        pose.put(msg.encode_state(msg.State(3.0, "uav2", Pose.from_euler(0, 0, 0, [15.0, -4.0, 60.0]))))
        decision.put(msg.encode_decision(msg.Decision(3.0, "uav2", 1, np.array([80.0, 20.0, 60.0]), 0.5, ())))
        wait_for(lambda: view.heard["fleet/pose"] == 1 and view.heard["fleet/decision"] == 1
                 and view.logged["fleet/uav2"] >= 1, "uav2's pose and target in the scene")
    finally:
        view.stop()
        pose.undeclare()
        decision.undeclare()
        robot.close()
        view_session.close()
    stream.flush()
    positions = {}
    for chunk in RrdReader(tmp_path / "view.rrd").stream():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith(":positions"):
                values = [x for x in batch.column(name).to_pylist() if x]
                if values:
                    positions[chunk.entity_path] = values[-1][0]
    assert np.allclose(positions["/world/fleet/uav2"], [15.0, -4.0, 60.0])
    assert np.allclose(positions["/world/fleet/uav2/target"], [80.0, 20.0, 60.0])
    assert "/world/fleet/uav3" not in positions
