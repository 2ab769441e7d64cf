"""What the study scores is what flies: a lock-step mission's pilot inputs, replayed into the live decide
node's step object (and into the running node over a real Zenoh session), give byte-identical decisions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import zenoh

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.geometry import Pose
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.eval.mission import run_mission
from layerpilot.missionfile import Override, load_mission
from layerpilot.nodes.decide import DecideNode, decision_message
from conftest import wait_for


def short_mission(behavior: str, state: Path, world_seed: int = 0):
    """``state``: the decide nodes' state directory (the default mission's is relative to the working directory:
    a test must not overwrite a survey saved there)."""
    return load_mission("default", [Override("--behavior", "decide.behavior", behavior),
                                    Override("--state", "decide.state", str(state)),
                                    Override("--duration", "evaluation.duration", 40.0),
                                    Override("--step", "evaluation.step_s", 0.1),
                                    Override("--world-seed", "sim.world.seed", world_seed),
                                    Override("--camera", "sim.camera", {"width": 160, "height": 120})])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    mission = short_mission("balanced", tmp_path_factory.mktemp("state"), world_seed=3)
    result = run_mission(mission, tmp_path_factory.mktemp("lockstep"), record_inputs=True)
    assert sum(i.command is not None for i in result.pilot_inputs) >= 3
    return mission, result


def record_bytes(command) -> bytes:
    return json.dumps(command.record(), sort_keys=True, default=lambda v: np.asarray(v).tolist()).encode()


def test_decide_nodes_step_object_replays_the_lockstep_decisions(recorded):
    mission, result = recorded
    with open_session(BusConfig(endpoint=free_endpoint())) as session:
        pilot = DecideNode(session, mission.vehicles[0], mission).pilot  # the live node's own step object
    for step in result.pilot_inputs:
        columns = to_column_layers(decode_layer_set(step.layer_set))  # the node's decode path
        command = pilot.step(step.position, step.time, columns)
        assert (command is None) == (step.command is None), step.time
        if command is not None:
            assert record_bytes(command) == record_bytes(step.command)


def test_running_decide_node_publishes_the_same_decision_bytes(recorded):
    mission, result = recorded
    vehicle = mission.vehicles[0]
    k = Keys(vehicle)
    ep = free_endpoint()
    node_session, world = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    node = DecideNode(node_session, vehicle, mission)
    published: list[bytes] = []
    sub = world.declare_subscriber(k.decision, lambda s: published.append(s.payload.to_bytes()))
    node.start()
    try:
        block = zenoh.CongestionControl.BLOCK  # every step matters here: none may be dropped on a busy machine
        layers = world.declare_publisher(k.layers, congestion_control=block)
        poses = world.declare_publisher(k.pose, congestion_control=block)
        wait_for(lambda: layers.matching_status.matching and poses.matching_status.matching, "the node's subscriptions")
        expected = []
        for step in result.pilot_inputs:
            before = node._columns
            layers.put(step.layer_set)  # first the layer set, then the pose that makes the pilot decide
            wait_for(lambda: node._columns is not before, "the layer set")
            poses.put(msg.encode_state(msg.State(step.time, vehicle, Pose(np.array(step.position)))))
            if step.command is not None:
                expected.append(msg.encode_decision(decision_message(step.command, vehicle, "balanced")))
                wait_for(lambda: len(published) == len(expected), f"decision {len(expected)}")
        assert published == expected
    finally:
        node.stop()
        sub.undeclare()
        world.close()
        node_session.close()
