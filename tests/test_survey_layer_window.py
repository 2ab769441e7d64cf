"""A 1 km survey on the bus: layer sets in full only around the drone, the same decisions as from the whole area."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.bus import layerset as wire
from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.eval.mission import run_mission
from layerpilot.geometry import Pose
from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.map.columns import ColumnLayers, observed_range
from layerpilot.mission.build import build_pilot
from layerpilot.missionfile import Mission, Override, load_mission
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.mission.pilot import PilotConfig
from layerpilot.nodes.map_server import MapServer
from conftest import wait_for

K = Keys("uav1")
AREA = (-520.0, -520.0, 1040, 1040)  # the map server's window over a 1 km area of interest (+20 m)
DRONE = (150.0, 80.0, 50.0)


@pytest.fixture(scope="module")
def survey_behavior(tmp_path_factory) -> str:
    """The balanced behavior over a circle of 500 m: a square-kilometre area of interest.

    With the paper's hops in metres (r_i 100 m), so the window's size below is known.
    """
    path = tmp_path_factory.mktemp("behavior") / "km.toml"
    path.write_text('r_e = 10.0\nr_i = 100.0\nweights = { fringe = 0.3, time = 0.3, distance = 0.3 }\n'
                    '[area]\nshape = "circle"\nradius = 500.0\n')
    return str(path)


def _patch(service, cx: float, cy: float, half: float, stamp: float, height) -> None:
    """Ground squares 2 * half wide around (cx, cy), seen from 10 m above each 30 m tile's centre."""
    for x0 in np.arange(cx - half, cx + half, 30.0):
        for y0 in np.arange(cy - half, cy + half, 30.0):
            xs, ys = np.meshgrid(np.arange(x0 + 0.5, min(x0 + 30, cx + half)),
                                 np.arange(y0 + 0.5, min(y0 + 30, cy + half)))
            pts = np.stack([xs.ravel(), ys.ravel(), height(xs.ravel(), ys.ravel())], 1).astype(np.float32)
            origin = np.array([xs.mean(), ys.mean(), float(pts[:, 2].max()) + 10.0])
            service.insert(pts, origin, None, stamp, 100.0)


@pytest.fixture(scope="module")
def server(survey_behavior):
    """A map server on Zenoh holding three patches of a 1 km area: one around the drone, and far away
    the area's highest and oldest columns and its lowest and newest ones."""
    ep = free_endpoint()
    server_session, client = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    mission = Mission(map_server=MapServiceConfig(layers_rate=10.0, window=AREA, snapshot=""),
                      decide=PilotConfig(behavior=survey_behavior))
    node = MapServer(server_session, mission)
    _patch(node.service, 150.0, 60.0, 60.0, 10.0, lambda x, y: 3.0 * np.sin(x / 7.0) + 2.0 * np.cos(y / 5.0))
    _patch(node.service, -400.0, -400.0, 15.0, 1.0, lambda x, y: np.full_like(x, 60.0))
    _patch(node.service, 400.0, 300.0, 15.0, 30.0, lambda x, y: np.full_like(x, -20.0))
    node.start()
    published: list[bytes] = []
    sub = client.declare_subscriber(K.layers, lambda s: published.append(s.payload.to_bytes()))
    poses = client.declare_publisher(K.pose)
    yield mission, node, client, poses, published
    sub.undeclare()
    node.stop()
    client.close()
    server_session.close()


def _set_around(server, x: float, y: float) -> wire.GridLayersMessage:
    """The first layer set the server publishes after hearing the drone at (x, y)."""
    mission, node, client, poses, published = server
    poses.put(msg.encode_state(msg.State(0.0, "uav1", Pose(np.array([x, y, DRONE[2]])))))
    g = node.service.geometry
    row, col = g.cell_of(x, y)

    def centred() -> bool:
        win = published and wire.decode_layer_set(published[-1]).window
        return bool(win) and abs((win.row0 + win.row1) / 2 - row) <= 1 and abs((win.col0 + win.col1) / 2 - col) <= 1

    wait_for(centred, f"a layer set centred on ({x}, {y})")
    data = published[-1]
    assert len(data) < wire.MAX_BYTES
    return wire.decode_layer_set(data)


def test_the_map_server_publishes_the_drones_neighbourhood_and_the_pilot_decides_as_from_the_whole_area(server):
    mission, node, client, poses, published = server
    ls = _set_around(server, *DRONE[:2])
    near = wire.to_column_layers(ls)
    whole = wire.to_column_layers(wire.decode_layer_set(node.layer_set("uav1", *AREA)))  # asked for: all in full
    assert ls.geometry == whole.geometry and ls.geometry.shape == (1040, 1040)
    assert ls.window.shape == (263, 263) and ls.layers["elevation"].shape == (263, 263)  # r_i 100 m + 30 m margin
    assert np.array_equal(near.observed, whole.observed)  # the whole area's coverage and frontier
    assert near.window is not None and whole.window is None
    # the far patches hold the extremes: the window's own ranges would scale the layers differently
    for name in ("elevation", "last_seen"):
        assert near.value_range(name) == whole.value_range(name)
        assert observed_range(getattr(near, name), near.observed) != whole.value_range(name)
    assert whole.value_range("last_seen") == (1.0, 30.0)

    pilots = [build_pilot(mission.core), build_pilot(mission.core)]
    position, t = np.array(DRONE), 40.0
    for tick in range(2):
        commands = [pilots[0].step(position, t, whole), pilots[1].step(position, t, near)]
        a, b = (c.decision for c in commands)
        assert commands[0].position == commands[1].position and a.cell == b.cell
        assert (a.score, a.contributions, a.coverage, a.fallback) == (b.score, b.contributions, b.coverage, b.fallback)
        assert a.fallback is None and a.contributions["time"] > 0
        position, t = np.array(commands[0].position), t + 20.0
        near = wire.to_column_layers(_set_around(server, *position[:2]))  # the next tick's neighbourhood
        assert near.window.contains(pilots[1].maker.window(near.geometry, position))


def test_a_pilot_waits_for_a_set_around_it(server):
    mission, node, *_ = server
    far = wire.to_column_layers(wire.decode_layer_set(node.layer_set("uav1")))  # around the last pose heard
    pilot = build_pilot(mission.core)
    assert pilot.step((-300.0, 200.0, 50.0), 1.0, far) is None and pilot.evaluations == 0
    assert pilot.step(DRONE, 1.0, wire.to_column_layers(_set_around(server, *DRONE[:2]))) is not None


def test_a_surveyed_square_kilometre_is_refused_whole_and_fits_around_the_drone():
    g = GridGeometry(*AREA[:2], 1.0, AREA[2], AREA[3])
    rng = np.random.default_rng(0)
    h, w = g.shape
    cl = ColumnLayers(g, np.ones((h, w), bool), rng.uniform(0, 30, (h, w)).astype(np.float32),
                      rng.integers(0, 255, (h, w, 3), dtype=np.uint8), rng.uniform(0, 600, (h, w)),
                      rng.uniform(5, 100, (h, w)).astype(np.float32))
    with pytest.raises(ValueError, match="max_bytes"):
        wire.encode_columns(cl, 600.0, "uav1")
    win = GridWindow.around(g, 0.0, 0.0, 130.0)
    data = wire.encode_columns(cl, 600.0, "uav1", None, win)
    assert len(data) < wire.MAX_BYTES
    back = wire.to_column_layers(wire.decode_layer_set(data))
    assert back.value_range("last_seen") == pytest.approx(observed_range(cl.last_seen, cl.observed), abs=0.01)
    assert np.isnan(back.elevation[0, 0]) and np.isfinite(back.elevation[win.slices]).all()


def test_a_short_lock_step_mission_over_a_1km_world(tmp_path, survey_behavior):
    mission = load_mission("default", [Override("--world-size", "sim.world.size", 1000.0),
                                       Override("--behavior", "decide.behavior", survey_behavior),
                                       Override("--window", "map_server.window", list(AREA)),
                                       Override("--duration", "evaluation.duration", 12.0),
                                       Override("--step", "evaluation.step_s", 0.1),
                                       Override("--depth", "depth.source", "ground_truth"),
                                       Override("--camera", "sim.camera", {"width": 160, "height": 120})])
    result = run_mission(mission, tmp_path / "km", record_inputs=True)
    assert result.waypoints >= 2 and result.clouds > 0 and result.final["percent_mapped"] > 0
    sets = [wire.decode_layer_set(i.layer_set) for i in result.pilot_inputs]
    assert sets and all(s.geometry.shape == (1040, 1040) and s.window.shape == (263, 263) for s in sets)
    assert all(len(i.layer_set) < wire.MAX_BYTES for i in result.pilot_inputs)


def test_a_drone_beyond_the_grid_heads_for_the_area_from_either_set():
    """Its neighbourhood misses the grid (an empty window): the pilot's "approach" fallback needs only the area."""
    g = GridGeometry(-128.0, -128.0, 1.0, 256, 256)
    cl = ColumnLayers.empty(g)
    cl.observed[10:20, 10:20], cl.elevation[10:20, 10:20], cl.last_seen[10:20, 10:20] = True, 3.0, 5.0
    cl.min_distance[10:20, 10:20] = 9.0
    far = GridWindow.around(g, 5000.0, 5000.0, 130.0)
    assert far.empty
    commands = []
    for window in (None, far):
        columns = wire.to_column_layers(wire.decode_layer_set(wire.encode_columns(cl, 1.0, "uav1", None, window)))
        commands.append(build_pilot(Mission().core).step((5000.0, 5000.0, 50.0), 1.0, columns))
    assert commands[0].position == commands[1].position == (70.5, 70.5, 50.0)
    assert commands[0].decision.fallback == commands[1].decision.fallback == "approach"
