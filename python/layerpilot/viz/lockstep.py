"""The scene of a lock-step mission (`demo`, `study`): the evaluator hands over what it has, this logs it.

Poses and decisions (with the tick's aggregate layers A0..A3 over the layers) are logged as they
come; the path, the camera image and the layers every
``IMAGE_PERIOD`` and the voxel map every ``MAP_PERIOD`` mission seconds, so that a 600 s run's
.rrd stays a few MB (the scene is a picture of the run, not a second copy of its map).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from layerpilot.decide.behavior import Behavior
from layerpilot.decide.maker import TickTerms
from layerpilot.geometry import CameraFrame, Pose
from layerpilot.grid import GridGeometry
from layerpilot.map import VoxelMap
from layerpilot.viz.scene import MissionScene, area_outline
from layerpilot.viz.stream import ViewStream, open_stream

IMAGE_PERIOD = 5.0  # mission s between camera images and layer images
MAP_PERIOD = 30.0  # mission s between voxel maps
BOX_HEIGHT = (-50.0, 200.0)  # m: the z range of the logged voxels


class LockstepView:
    """Opened by the command (where the scene goes), started by the evaluator (what area it shows)."""

    def __init__(self, stream: ViewStream) -> None:
        self.view = stream
        self.scene = MissionScene(stream.stream)
        self.geometry: GridGeometry | None = None
        self._next_image = self._next_map = 0.0

    @classmethod
    def open(cls, name: str, *, save: str | Path | None = None, web_port: int | None = None, grpc_port: int = 9876,
             spawn: bool = False) -> "LockstepView":
        return cls(open_stream(name, save=save, web_port=web_port, grpc_port=grpc_port, spawn=spawn))

    @property
    def url(self) -> str:
        return self.view.url

    def start(self, behavior: Behavior, home: Sequence[float], geometry: GridGeometry) -> None:
        """The behavior's area of interest, and the grid its layers are shown on."""
        self.geometry = geometry
        self.scene.area(area_outline(behavior.area.shape, behavior.area.radius, behavior.area.center or home,
                                     behavior.area.polygon))

    def reads_map(self, t: float) -> bool:
        """Whether the frame at ``t`` logs map images or voxels (the evaluator lets the map settle first)."""
        return self._images_due(t) or self._map_due(t)

    def _images_due(self, t: float) -> bool:
        return t >= self._next_image - 1e-9

    def _map_due(self, t: float) -> bool:
        return t >= self._next_map - 1e-9

    def frame(self, t: float, frame: CameraFrame, body: np.ndarray, voxel_map: VoxelMap) -> None:
        """One camera frame (map frame) with the drone's position ``body``; images and map on their periods."""
        self.scene.at(t)
        self.scene.pose(Pose(np.asarray(body, np.float64)))
        if self._images_due(t):
            self._next_image = t + IMAGE_PERIOD
            self.scene.path()
            self.scene.camera(frame)
            cl = voxel_map.column_layers_for(self.geometry)
            seen = cl.observed
            self.scene.layers({"color": cl.color, "elevation": np.where(seen, cl.elevation, np.nan),
                               "time_since_seen": np.where(seen, t - cl.last_seen, np.nan),
                               "distance": np.where(seen, cl.min_distance, np.nan)}, self.geometry)
        if self._map_due(t):  # the first map as soon as there is one, then every MAP_PERIOD
            x0, x1, y0, y1 = self.geometry.extent
            box = np.array([x0, y0, BOX_HEIGHT[0]]), np.array([x1, y1, BOX_HEIGHT[1]])
            if self.scene.voxels(voxel_map.voxels(*box), t, voxel_map.resolution):
                self._next_map = t + MAP_PERIOD

    def fleet_member(self, t: float, name: str, position: Sequence[float], target: Sequence[float] | None) -> None:
        """Another drone of a fleet at one of its camera frames: where it is and where it is going."""
        self.scene.at(t)
        self.scene.fleet_member(name, position, target)

    def decision(self, t: float, record: Mapping, tick: TickTerms | None = None) -> None:
        """A command's decisions.jsonl record: its waypoint, runner-up and explanation; ``tick``: the
        decision maker's tick that chose it (its A0..A3, on the window it computed)."""
        self.scene.at(t)
        if tick is not None and tick.placement is not None:
            self.scene.aggregates(tick.aggregates(), tick.placement, self.geometry)
        runner = record.get("runner_up")
        self.scene.decision(record["waypoint"], None if runner is None else runner["waypoint"],
                            record.get("explanation") or f"{record.get('reason', '')} waypoint {record['seq']}: "
                            f"({record['waypoint'][0]:.1f}, {record['waypoint'][1]:.1f}, {record['waypoint'][2]:.1f})")

    def metrics(self, t: float, values: Mapping[str, float]) -> None:
        self.scene.at(t)
        self.scene.scalars("metrics", {k: v for k, v in values.items() if k != "t"})

    def close(self) -> None:
        self.view.close()
