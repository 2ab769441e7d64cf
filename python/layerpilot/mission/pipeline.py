"""One mission pipeline: the map, depth and decision steps of a mission behind the few calls every driver makes.

The pattern of ETH's wavemap (one ``Pipeline``, driven by its ROS server and its Python bindings
alike): the live nodes, the lock-step evaluator and replay all hold a ``MissionPipeline`` and
call it; none of them wires the steps together by hand. A driver feeds it what arrives:

- ``pose(vehicle, stamp, pose)``: the vehicle's newest pose (the pilot's position, the centre of its
  layer set), and ``telemetry(...)``, the same stream for the depth service;
- ``frame(vehicle, frame)``: a camera frame -> the map-frame point cloud, or None;
- ``cloud(vehicle, cloud, max_range)``: a cloud into the fused map;
- ``layers(vehicle)``: the column layers the map publishes for that vehicle (full around it);
- ``tick(vehicle, stamp, columns, ...)``: the pilot's command, or None.

A live node holds the pipeline of its role only (``roles``): the map server ``{"map"}``, the depth
node ``{"depth"}``, the decide node ``{"decide"}``; the lock-step evaluator holds all three in one
process. Transport, files and the simulator stay with the drivers: the layer sets go through the
bus codec in the drivers, exactly as they travel.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np

from layerpilot.geometry import CameraFrame, PointCloud, Pose
from layerpilot.grid import GridWindow
from layerpilot.map.columns import ColumnLayers
from layerpilot.map.voxel_map import InsertResult
from layerpilot.mission.build import build_depth_service, build_pilot, map_volume
from layerpilot.mission.core import MissionCore
from layerpilot.mission.depth_service import DepthService
from layerpilot.mission.map_service import MapService
from layerpilot.mission.pilot import Command, Pilot

ROLES = frozenset({"map", "depth", "decide"})


@dataclass(frozen=True)
class LayerView:
    """What the map publishes for one vehicle: the configured window's column layers, in full within
    ``near`` (the cells its pilot reads around its newest pose), stamped with the newest cloud's time."""

    columns: ColumnLayers
    stamp: float
    near: GridWindow


class MissionPipeline:
    """The map service, the depth services and the pilots of a mission's vehicles, behind one interface."""

    def __init__(self, mission: MissionCore, roles: Collection[str] = ROLES, vehicles: Sequence[str] | None = None, *,
                 map_service: MapService | None = None) -> None:
        """``roles``: which steps this process runs; ``vehicles``: whose (default: the mission's);
        ``map_service``: a started one (the map server's, reloaded from its snapshot), else a fresh map."""
        if not set(roles) <= ROLES or not roles:
            raise ValueError(f"roles: expected some of {sorted(ROLES)}, got {sorted(roles)}")
        self.mission = mission
        self.roles = frozenset(roles)
        self.vehicles = tuple(vehicles or mission.vehicles)
        unknown = set(self.vehicles) - set(mission.vehicles)
        if unknown:
            raise ValueError(f"vehicles: {sorted(unknown)} are not the mission's {mission.vehicles}")
        self.map = ((map_service or MapService(mission.map_server, volume=map_volume(mission)))
                    if "map" in self.roles else None)
        self.depth: dict[str, DepthService] = ({v: build_depth_service(mission) for v in self.vehicles}
                                               if "depth" in self.roles else {})
        self.pilots: dict[str, Pilot] = ({v: build_pilot(mission, v) for v in self.vehicles}
                                         if "decide" in self.roles else {})
        home = tuple(float(c) for c in mission.decide.home)
        self._where = {v: (home[0], home[1], 0.0) for v in mission.vehicles}  # each vehicle's newest position
        # how far from its drone a pilot's tick reads: the map sends that in full
        self._reach = ((next(iter(self.pilots.values())) if self.pilots else build_pilot(mission)).layer_reach
                       if "map" in self.roles else 0.0)

    def _need(self, role: str) -> None:
        if role not in self.roles:
            raise RuntimeError(f"this pipeline runs {sorted(self.roles)}, not {role!r}")

    def _check(self, vehicle: str, of: Collection[str]) -> None:
        if vehicle not in of:
            raise ValueError(f"vehicle {vehicle!r}: not one of {sorted(of)}")

    # --- inputs ---------------------------------------------------------------------------

    def pose(self, vehicle: str, stamp: float, pose: Pose) -> None:
        """A vehicle's newest pose (map frame, mission clock): where the pilot is, where its layer set is
        centred. Any mission vehicle's pose is kept (the map serves every one)."""
        self._check(vehicle, self.mission.vehicles)
        p = np.asarray(pose.position, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or not math.isfinite(stamp):
            raise ValueError(f"pose of {vehicle}: position and stamp must be finite, got {p} at {stamp}")
        self._where[vehicle] = (float(p[0]), float(p[1]), float(p[2]))

    def telemetry(self, vehicle: str, stamp: float, pose: Pose) -> None:
        """The vehicle's pose stream for its depth service (poses at the frames' times, the camera clock's
        offset). Apart from ``pose``: a driver that runs the depth step on a worker feeds it there, in order."""
        self._need("depth")
        self._check(vehicle, self.depth)
        self.depth[vehicle].push_pose(stamp, pose)

    def frame(self, vehicle: str, frame: CameraFrame) -> PointCloud | None:
        """A camera frame -> its map-frame cloud (None: no partner yet, skipped, no points)."""
        self._need("depth")
        self._check(vehicle, self.depth)
        return self.depth[vehicle].push(frame)

    def cloud(self, vehicle: str, cloud: PointCloud, max_range: float | None = None) -> InsertResult:
        """A cloud into the fused map (ValueError names a bad argument; the map is then unchanged)."""
        self._need("map")
        self._check(vehicle, self.mission.vehicles)
        return self.map.insert(cloud.points, cloud.origin, cloud.colors, cloud.stamp, max_range)

    # --- outputs --------------------------------------------------------------------------

    def layers(self, vehicle: str) -> LayerView:
        """The layer set the map publishes for ``vehicle``."""
        return LayerView(self.map.columns(), self.map.last_stamp, self.detail(vehicle))

    def detail(self, vehicle: str) -> GridWindow:
        """The cells of ``vehicle``'s layer set sent in full: what its pilot reads around its newest pose."""
        self._need("map")
        self._check(vehicle, self.mission.vehicles)
        x, y, _ = self._where[vehicle]
        return self.map.detail(x, y, self._reach)

    def tick(self, vehicle: str, stamp: float, columns: ColumnLayers | None, *, battery: float = math.nan,
             avoid: Sequence[Sequence[float]] = (), yield_to: Sequence[Sequence[float]] = ()) -> Command | None:
        """The pilot's step at its newest position (``pose``) with the newest layers: a command or None."""
        self._need("decide")
        self._check(vehicle, self.pilots)
        return self.pilots[vehicle].step(self._where[vehicle], stamp, columns, avoid=avoid, yield_to=yield_to,
                                         battery=battery)

    def position(self, vehicle: str) -> tuple[float, float, float]:
        """The vehicle's newest position (map frame; its home before the first pose)."""
        return self._where[vehicle]
