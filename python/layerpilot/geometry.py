"""Ground floor: the data types every package shares (pose, camera intrinsics, camera frame, point cloud).

Imports only numpy and the standard library; everything else builds on it.

Conventions:
  * map frame: ENU metres, z up (x east, y north). MAVLink's NED appears only in
    ``link/`` and in the simulator's MAVLink endpoint.
  * ``Pose``: a rigid transform local -> map, ``p_map = rotation @ p_local + position``;
    ``orientation`` is the unit quaternion (w, x, y, z) of ``rotation`` (Hamilton
    convention, stored with w >= 0). ``rotation``'s columns are the local axes in the
    map frame; a map point X has local coordinates ``rotation.T @ (X - position)``.
  * body frame (vehicle): FLU, x forward, y left, z up (ROS REP-103). Euler angles
    are ZYX: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``; yaw is counter-clockwise from
    east, so yaw 0 heads east and pi/2 north.
  * camera frame (OpenCV): x right, y down, z forward along the optical axis; a
    camera ``Pose`` maps camera coordinates to the map frame and its ``position``
    is the optical centre.
  * pixels: (u, v) = (column, row); the centre of the top-left pixel is (0, 0); a
    camera-frame point p projects to ``K @ p / p[2]``. Images have row 0 at the top.
  * time: mission-clock seconds (float64).

Constructors check what they are given and raise ``ValueError`` naming the
argument (shape, dtype, non-finite values). Arrays held by ``Pose`` are read-only
copies; images, depths and points are kept as given (no copy).
"""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

__all__ = ["CameraFrame", "CameraIntrinsics", "PointCloud", "Pose", "matrix_from_quat", "quat_from_euler",
           "quat_from_matrix"]


def _array(value: object, name: str, dtype: type, shape: tuple[int | None, ...]) -> np.ndarray:
    """``value`` as an array of exactly ``dtype`` and ``shape`` (None = any length); ValueError names ``name``."""
    a = np.asarray(value)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    if a.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {np.dtype(dtype).name}, got {a.dtype.name}")
    return a


def _vector(value: object, name: str, size: int) -> np.ndarray:
    """A finite float64 vector of ``size`` (read-only copy); ValueError names ``name``."""
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {size} numbers, got {value!r}") from None
    if a.shape != (size,):
        raise ValueError(f"{name}: expected shape ({size},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf: {a}")
    a.flags.writeable = False
    return a


def _finite(value: object, name: str) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name}: must be finite, got {v}")
    return v


# --- rotations -------------------------------------------------------------------------------

def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a 3x3 rotation matrix (Shepperd's method, w >= 0)."""
    R = np.asarray(R, np.float64).tolist()  # Python floats: numpy's arithmetic, faster on scalars
    t = R[0][0] + R[1][1] + R[2][2]
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = [0.25 * s, (R[2][1] - R[1][2]) / s, (R[0][2] - R[2][0]) / s, (R[1][0] - R[0][1]) / s]
    else:
        i = max(range(3), key=lambda n: R[n][n])  # the first of equal maxima, as np.argmax
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + R[i][i] - R[j][j] - R[k][k], 1e-300))
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (R[k][j] - R[j][k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j][i] + R[i][j]) / s
        q[1 + k] = (R[k][i] + R[i][k]) / s
    out = np.array(q)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0 else -out


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a quaternion (w, x, y, z); the quaternion is normalised first."""
    # Python floats: the same IEEE arithmetic as numpy's scalars, several times faster (every pose's rotation)
    w, x, y, z = (np.asarray(q, np.float64) / np.linalg.norm(q)).tolist()
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def quat_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(w, x, y, z) of ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (radians, ZYX)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                  cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])
    return q if q[0] >= 0 else -q


# --- pose ------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Pose:
    """Rigid transform local (camera or body) -> map: ``position`` (3,) and unit quaternion ``orientation``.

    ``orientation`` is (w, x, y, z); it is normalised (a norm off 1 by more than 1e-3
    is an error, not rounding) and stored with w >= 0.
    """

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vector(self.position, "position", 3))
        q = np.array(_vector(self.orientation, "orientation", 4))
        with np.errstate(over="ignore"):
            norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 1e-3:
            raise ValueError(f"orientation: norm {norm:.6g}, expected a unit quaternion (w, x, y, z)")
        q = q / norm if q[0] >= 0 else -q / norm
        q.flags.writeable = False
        object.__setattr__(self, "orientation", q)

    @classmethod
    def from_rotation(cls, rotation: np.ndarray, position: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0)
                      ) -> "Pose":
        """From a 3x3 rotation matrix (local -> map) and a position; ValueError if it is not a rotation."""
        R = np.asarray(rotation, np.float64)
        if R.shape != (3, 3):
            raise ValueError(f"rotation: expected shape (3, 3), got {R.shape}")
        if not np.all(np.isfinite(R)):
            raise ValueError("rotation: contains NaN or inf")
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
            raise ValueError("rotation: not a rotation matrix (orthonormal, determinant +1)")
        return cls(position, quat_from_matrix(R))

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> "Pose":
        """From a 4x4 homogeneous transform local -> map."""
        T = np.asarray(matrix, np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"matrix: expected shape (4, 4), got {T.shape}")
        if not np.all(np.isfinite(T)) or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
            raise ValueError("matrix: last row must be (0, 0, 0, 1) and every entry finite")
        try:
            return cls.from_rotation(T[:3, :3], T[:3, 3])
        except ValueError as exc:
            raise ValueError(str(exc).replace("rotation:", "matrix: rotation part", 1)) from None

    @classmethod
    def from_euler(cls, roll: float, pitch: float, yaw: float,
                   position: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0)) -> "Pose":
        """ZYX Euler angles in radians (``Rz(yaw) @ Ry(pitch) @ Rx(roll)``), e.g. a FLU body in ENU."""
        angles = [_finite(v, n) for v, n in ((roll, "roll"), (pitch, "pitch"), (yaw, "yaw"))]
        return cls(position, quat_from_euler(*angles))

    @cached_property
    def rotation(self) -> np.ndarray:
        """3x3 rotation local -> map (read-only)."""
        R = matrix_from_quat(self.orientation)
        R.flags.writeable = False
        return R

    @cached_property
    def matrix(self) -> np.ndarray:
        """4x4 homogeneous transform local -> map (read-only)."""
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = self.position
        T.flags.writeable = False
        return T

    @property
    def euler(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in radians, ZYX; pitch in [-pi/2, pi/2]."""
        w, x, y, z = self.orientation
        roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - x * z))))
        return roll, pitch, self.yaw

    @property
    def yaw(self) -> float:
        """ZYX yaw (rad): the heading of the local x axis, counter-clockwise from map +x (east)."""
        w, x, y, z = self.orientation
        return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))

    def inverse(self) -> "Pose":
        """The transform map -> local."""
        R = self.rotation
        return Pose(-R.T @ self.position, self.orientation * np.array([1.0, -1.0, -1.0, -1.0]))

    def __matmul__(self, other: "Pose") -> "Pose":
        """Composition: ``(a @ b)`` maps b's local frame through b, then a (``a.matrix @ b.matrix``)."""
        if not isinstance(other, Pose):
            return NotImplemented
        return Pose.from_rotation(self.rotation @ other.rotation, self.rotation @ other.position + self.position)

    def to_map(self, points: np.ndarray) -> np.ndarray:
        """Local points (N, 3) -> map frame (float64)."""
        return np.asarray(points, np.float64) @ self.rotation.T + self.position

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """Map points (N, 3) -> local frame (float64)."""
        return (np.asarray(points, np.float64) - self.position) @ self.rotation

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Pose):
            return NotImplemented
        return bool(np.array_equal(self.position, other.position) and np.array_equal(self.orientation, other.orientation))

    def __hash__(self) -> int:
        return hash((self.position.tobytes(), self.orientation.tobytes()))

    def __repr__(self) -> str:
        return f"Pose(position={self.position.tolist()}, orientation={self.orientation.tolist()})"


# --- camera ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole camera in pixels (no distortion): focal lengths, principal point, image size."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, _finite(getattr(self, name), name))
        if not (self.fx > 0 and self.fy > 0):
            raise ValueError(f"fx, fy: focal lengths must be > 0, got {self.fx}, {self.fy}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name}: expected a positive whole number of pixels, got {v!r}")
            object.__setattr__(self, name, int(v))

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> "CameraIntrinsics":
        """Square pixels, horizontal field of view ``hfov_deg``, principal point at the image centre."""
        hfov = _finite(hfov_deg, "hfov_deg")
        if not 0 < hfov < 180:
            raise ValueError(f"hfov_deg: must be in (0, 180), got {hfov}")
        f = (width / 2) / math.tan(math.radians(hfov) / 2)
        return cls(f, f, (width - 1) / 2, (height - 1) / 2, width, height)

    @classmethod
    def from_K(cls, K: np.ndarray, width: int, height: int) -> "CameraIntrinsics":
        """From a 3x3 matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (skew must be 0)."""
        K = np.asarray(K, np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"K: expected shape (3, 3), got {K.shape}")
        if K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
            raise ValueError("K: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height)

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix (float64, a new array)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def size(self) -> tuple[int, int]:
        """(width, height), OpenCV's order."""
        return self.width, self.height

    def scaled(self, factor: float) -> "CameraIntrinsics":
        """The same camera at ``factor`` times the resolution (pixel centres keep their place)."""
        s = _finite(factor, "factor")
        if s <= 0:
            raise ValueError(f"factor: must be > 0, got {s}")
        return CameraIntrinsics(self.fx * s, self.fy * s, (self.cx + 0.5) * s - 0.5, (self.cy + 0.5) * s - 0.5,
                                max(1, round(self.width * s)), max(1, round(self.height * s)))

    def project(self, camera_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) and z-depth (N,) of camera-frame points; inf/NaN where z <= 0."""
        p = np.asarray(camera_points, np.float64)
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = p[:, :2] / z[:, None] * [self.fx, self.fy] + [self.cx, self.cy]
        return uv, z

    def rays(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Camera-frame directions (..., 3) through pixels (u, v), with unit z (z-depth 1)."""
        u, v = np.asarray(u, np.float64), np.asarray(v, np.float64)
        return np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones(np.broadcast(u, v).shape)], -1)


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One camera image with its pose (camera -> map, OpenCV camera axes), intrinsics and stamp.

    ``depth`` is optional ground truth (simulator, RGB-D): z-depth in metres along the
    optical axis (camera z, not the ray length); inf or NaN = no measurement (sky).
    """

    image: np.ndarray  # uint8 (H, W, 3) RGB, row 0 = top
    pose: Pose
    intrinsics: CameraIntrinsics
    stamp: float
    depth: np.ndarray | None = None  # float32 (H, W)

    def __post_init__(self) -> None:
        img = _array(self.image, "image", np.uint8, (None, None, 3))
        object.__setattr__(self, "image", img)
        if not isinstance(self.pose, Pose):
            raise ValueError(f"pose: expected a Pose, got {type(self.pose).__name__}")
        if not isinstance(self.intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics: expected CameraIntrinsics, got {type(self.intrinsics).__name__}")
        if self.intrinsics.size != (img.shape[1], img.shape[0]):
            raise ValueError(f"intrinsics: size {self.intrinsics.width}x{self.intrinsics.height} does not match "
                             f"the image's {img.shape[1]}x{img.shape[0]}")
        object.__setattr__(self, "stamp", _finite(self.stamp, "stamp"))
        if self.depth is not None:
            d = _array(self.depth, "depth", np.float32, img.shape[:2])
            if np.any(d < 0):
                raise ValueError("depth: negative values")
            object.__setattr__(self, "depth", d)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels, OpenCV's order."""
        return self.intrinsics.size

    @property
    def K(self) -> np.ndarray:
        return self.intrinsics.K

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit viewing direction (camera +z) in the map frame."""
        return self.pose.rotation[:, 2]

    def project(self, points_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) and z-depth (N,) of map-frame points in this camera."""
        return self.intrinsics.project(self.pose.to_local(points_map))

    def seen_from(self, origin: np.ndarray | tuple[float, float, float]) -> "CameraFrame":
        """The same frame in a map frame whose origin lies at ``origin`` of this one (a translation:
        the simulated world's frame -> an autopilot's local frame, zero on the ground at home)."""
        shift = _vector(origin, "origin", 3)
        return dataclasses.replace(self, pose=Pose(self.pose.position - shift, self.pose.orientation))


# --- point cloud -----------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class PointCloud:
    """Finite map-frame points seen from ``origin`` (the sensor's position) at ``stamp``.

    What ``VoxelMap.insert(points, origin, colors, stamp)`` takes: rays run from
    ``origin`` to each point. ``colors`` is None when the sensor has no color.
    """

    points: np.ndarray  # float32 (N, 3)
    origin: np.ndarray  # float64 (3,)
    stamp: float
    colors: np.ndarray | None = None  # uint8 (N, 3) RGB

    def __post_init__(self) -> None:
        pts = _array(self.points, "points", np.float32, (None, 3))
        if not np.all(np.isfinite(pts)):
            raise ValueError("points: contains NaN or inf")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "origin", _vector(self.origin, "origin", 3))
        object.__setattr__(self, "stamp", _finite(self.stamp, "stamp"))
        if self.colors is not None:
            object.__setattr__(self, "colors", _array(self.colors, "colors", np.uint8, (len(pts), 3)))

    def __len__(self) -> int:
        return len(self.points)
