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
