"""What a mission looks like in Rerun: one entity per thing the operator watches, on the mission clock.

``world/map``: occupied voxels as boxes (points beyond MAX_BOXES), coloured by their color, their
height or the time since they were seen; ``world/drone``: the pose, with ``world/drone/camera`` its
frustum and last image; ``world/path``: the flight path; ``world/target`` and ``world/runner_up``:
the current choice, with ``decision`` the decide node's one-line explanation; ``world/area``: the
area of interest; ``layers/<name>``: 2D layers as colormapped images, with ``layers/A0`` ..
``layers/A3`` the decision's aggregate layers placed on them where the tick computed them;
``metrics/<name>`` and ``health/<name>`` (``health/<node>/...`` per node): time series.
Timeline ``mission``: mission seconds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from functools import cache

import numpy as np
import rerun as rr

from layerpilot.geometry import CameraFrame, Pose
from layerpilot.grid import GridGeometry
from layerpilot.map.voxel_map import Voxels

COLOR_MODES = ("color", "height", "age")  # how occupied voxels are coloured
MAX_BOXES = 50_000  # beyond this many voxels the map is drawn as points (boxes cost the viewer more)
MAX_PATH = 20_000  # path vertices kept (the oldest go first)
TIMELINE = "mission"
AGGREGATE_LEVELS = 32  # colours an aggregate layer is drawn in: a quarter of the PNG bytes of a smooth ramp


def colormap(values: np.ndarray, name: str = "viridis", lo: float | None = None,
             hi: float | None = None) -> np.ndarray:
    """(..., 3) uint8 RGB of ``values`` through a matplotlib colormap; NaN/inf cells are black."""
    from matplotlib import colormaps

    v = np.asarray(values, np.float64)
    finite = np.isfinite(v)
    if not finite.any():
        return np.zeros(v.shape + (3,), np.uint8)
    lo = float(v[finite].min()) if lo is None else lo
    hi = float(v[finite].max()) if hi is None else hi
    scaled = np.clip((np.where(finite, v, lo) - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    rgb = (colormaps[name](scaled)[..., :3] * 255).astype(np.uint8)
    rgb[~finite] = 0
    return rgb


@cache
def aggregate_colors() -> np.ndarray:
    """RGBA per aggregate step: 0 transparent (the cell scores 0), then the colormap from 0 to the tick's maximum."""
    ramp = colormap(np.arange(AGGREGATE_LEVELS + 1.0), "inferno")
    return np.vstack([np.zeros((1, 4), np.uint8), np.column_stack([ramp, np.full(len(ramp), 255, np.uint8)])])


def encoded(rgb: np.ndarray, suffix: str, draw_order: float | None = None, params: Sequence[int] = ()) -> rr.EncodedImage:
    """An RGB(A) image compressed (PNG for layers, JPEG for camera frames): an .rrd of a long run stays small."""
    import cv2

    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGBA2BGRA) if rgb.shape[-1] == 4 else rgb[..., ::-1]
    ok, data = cv2.imencode(suffix, np.ascontiguousarray(bgr), list(params))
    if not ok:
        raise ValueError(f"image: OpenCV could not encode a {rgb.shape} image as {suffix}")
    return rr.EncodedImage(contents=data.tobytes(), media_type="image/png" if suffix == ".png" else "image/jpeg",
                           draw_order=draw_order)


def area_outline(shape: str, radius: float, center: Sequence[float], polygon: Sequence[Sequence[float]],
                 z: float = 0.0) -> np.ndarray:
    """(n, 3) closed outline of an area of interest (a circle of ``radius`` around ``center``, or ``polygon``)."""
    if shape == "polygon":
        xy = np.asarray(polygon, np.float64).reshape(-1, 2)
    else:
        a = np.linspace(0.0, 2 * math.pi, 73)
        xy = np.stack([center[0] + radius * np.cos(a), center[1] + radius * np.sin(a)], axis=1)
    xy = np.vstack([xy, xy[:1]])
    return np.column_stack([xy, np.full(len(xy), z)])


class MissionScene:
    """Logs one mission into a Rerun recording stream (a file, a viewer, or both: see viz.stream)."""

    def __init__(self, stream: rr.RecordingStream, color_by: str = "color") -> None:
        if color_by not in COLOR_MODES:
            raise ValueError(f"color_by: expected one of {', '.join(COLOR_MODES)}, got {color_by!r}")
        self.stream = stream
        self.color_by = color_by
        self._path: list[np.ndarray] = []
        self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.stream.log("world/drone/body", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.8, colors=[[255, 60, 60]]),
                        static=True)

    def at(self, t: float) -> None:
        """Everything logged next happens at mission time ``t`` (s)."""
        self.stream.set_time(TIMELINE, duration=float(t))

    def voxels(self, v: Voxels, now: float, resolution: float) -> bool:
        """The occupied voxels, replacing the previous ones; False when there were none (nothing logged)."""
        if len(v) == 0:
            return False
        if self.color_by == "color":
            colors = v.color
        elif self.color_by == "height":
            colors = colormap(v.centers[:, 2], "terrain")
        else:
            colors = colormap(now - v.last_seen, "magma_r", 0.0)
        if len(v) <= MAX_BOXES:
            self.stream.log("world/map", rr.Boxes3D(centers=v.centers, half_sizes=[resolution / 2] * 3,
                                                    colors=colors, fill_mode="solid"))
        else:
            self.stream.log("world/map", rr.Points3D(v.centers, colors=colors, radii=resolution / 2))
        return True

    def layers(self, images: Mapping[str, np.ndarray], geometry: GridGeometry) -> None:
        """2D layers as images, north up (row 0 of a layer is its southern edge); RGB ones as they are."""
        for name, values in images.items():
            values = np.asarray(values)
            image = values if values.ndim == 3 else colormap(values.astype(np.float64), "viridis")
            self.stream.log(f"layers/{name}", encoded(image[::-1], ".png"))

    def aggregates(self, images: Mapping[str, np.ndarray], placement: GridGeometry, under: GridGeometry) -> None:
        """The decision's A0..A3 (``layers/A0`` ...) on the window a tick computed (``placement``, map frame),
        drawn in place over the layer images of grid ``under``; cells scoring 0 are transparent. Values are drawn
        in AGGREGATE_LEVELS steps of the tick's own maximum (a picture of where the score is high)."""
        import cv2

        scale = placement.resolution / under.resolution
        left = (placement.origin_x - under.origin_x) / under.resolution
        top = (under.extent[3] - placement.extent[3]) / under.resolution  # images are north up
        for name, values in images.items():
            v = np.nan_to_num(np.asarray(values, np.float64), nan=0.0)
            high = float(v.max(initial=0.0))
            steps = np.where(v > 0, np.rint(v * (AGGREGATE_LEVELS / high)) + 1, 0) if high > 0 else np.zeros(v.shape)
            self.stream.log(f"layers/{name}", rr.Transform3D(translation=[left, top, 0.0], scale=[scale, scale, 1.0]))
            self.stream.log(f"layers/{name}", encoded(aggregate_colors()[steps[::-1].astype(np.intp)], ".png",
                                                      draw_order=10.0, params=(cv2.IMWRITE_PNG_COMPRESSION, 6)))

    def pose(self, pose: Pose) -> None:
        """The drone (body -> map); its position is the path's next vertex (see ``path``)."""
        w, x, y, z = pose.orientation
        self.stream.log("world/drone", rr.Transform3D(translation=pose.position, quaternion=[x, y, z, w]))
        self._path.append(np.asarray(pose.position, np.float64))
        del self._path[:-MAX_PATH]

    def fleet_member(self, name: str, position: Sequence[float] | None, target: Sequence[float] | None) -> None:
        """Another drone of the fleet: where it is and where it is going (either may be unknown yet)."""
        if position is not None:
            self.stream.log(f"world/fleet/{name}", rr.Points3D([position], radii=[1.5], colors=[[60, 140, 255]],
                                                                labels=[name]))
        if target is not None:
            self.stream.log(f"world/fleet/{name}/target", rr.Points3D([target], radii=[1.0], colors=[[60, 140, 255]]))

    def path(self) -> None:
        """The flight path so far (logged on the caller's period: each call stores the whole path again)."""
        if len(self._path) > 1:
            self.stream.log("world/path", rr.LineStrips3D([np.array(self._path)], colors=[[255, 60, 60]]))

    def camera(self, frame: CameraFrame) -> None:
        """The camera's frustum at its pose (OpenCV axes: x right, y down, z forward) and its image."""
        k, (w, x, y, z) = frame.intrinsics, frame.pose.orientation
        self.stream.log("world/camera", rr.Transform3D(translation=frame.pose.position, quaternion=[x, y, z, w]))
        self.stream.log("world/camera", rr.Pinhole(focal_length=[k.fx, k.fy], principal_point=[k.cx, k.cy],
                                                   width=k.width, height=k.height, camera_xyz=rr.ViewCoordinates.RDF,
                                                   image_plane_distance=5.0))
        self.stream.log("world/camera", encoded(frame.image, ".jpg"))

    def decision(self, target: Sequence[float], runner_up: Sequence[float] | None, explanation: str) -> None:
        self.stream.log("world/target", rr.Points3D([target], radii=1.5, colors=[[0, 220, 255]], labels=["target"]))
        if runner_up is not None:
            self.stream.log("world/runner_up", rr.Points3D([runner_up], radii=1.0, colors=[[255, 200, 0]],
                                                           labels=["runner-up"]))
        self.stream.log("decision", rr.TextLog(explanation, level="INFO"))

    def area(self, outline: np.ndarray) -> None:
        self.stream.log("world/area", rr.LineStrips3D([outline], colors=[[255, 255, 0]]), static=True)

    def scalars(self, group: str, values: Mapping[str, float]) -> None:
        """One point per finite value: ``metrics`` (percent mapped, ...) or ``health`` (rates, drops, rejections)."""
        for name, value in values.items():
            if value is not None and math.isfinite(float(value)):
                self.stream.log(f"{group}/{name}", rr.Scalars(float(value)))

    def text(self, line: str, level: str = "INFO") -> None:
        self.stream.log("log", rr.TextLog(line, level=level))
