"""What a real camera does to the rendered image and its stamp (the other half of a :class:`SensorProfile`).

In order: the lens (rendered through the true distortion, then undistorted with the slightly
wrong calibration, so the image carries the residual), motion blur (the image motion during
the exposure, from the vehicle's true velocity and yaw rate), auto-exposure changes, sensor
noise, JPEG. The stamp runs ``clock_offset_s`` behind the true exposure, with jitter, and
the exposure starts a random trigger latency after the stamped trigger.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from layerpilot.geometry import CameraFrame, CameraIntrinsics
from layerpilot.sim.sensors import SensorProfile


def lens_maps(intrinsics: CameraIntrinsics, profile: SensorProfile) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps: for each pixel of the delivered (calibrated, undistorted) image, where it lies in the
    rendered pinhole image. The calibration has focal length f and distortion (1 + e) k; the lens has
    f / (1 + e) and k, so a perfect calibration (e = 0) gives the identity."""
    e = profile.calibration_error
    k_true = np.array([profile.k1, profile.k2, 0.0, 0.0])
    u, v = np.meshgrid(np.arange(intrinsics.width, dtype=np.float64), np.arange(intrinsics.height, dtype=np.float64))
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    x, y = (u - cx) / fx, (v - cy) / fy
    r2 = x * x + y * y
    radial = 1.0 + (1.0 + e) * (profile.k1 * r2 + profile.k2 * r2 * r2)  # the calibration's distortion
    raw_x, raw_y = x * radial * (1.0 + e), y * radial * (1.0 + e)         # on the sensor, in true focal units
    points = np.stack([raw_x, raw_y], axis=-1).reshape(-1, 1, 2)
    undistorted = cv2.undistortPoints(points, np.eye(3), k_true, None, None, None,
                                      (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10))
    ux, uy = undistorted.reshape(intrinsics.height, intrinsics.width, 2).transpose(2, 0, 1)
    return (ux * fx + cx).astype(np.float32), (uy * fy + cy).astype(np.float32)


def blur_kernel(shift: np.ndarray) -> np.ndarray | None:
    """A normalised line kernel along the image motion ``shift`` (pixels, (du, dv)); None below half a pixel."""
    length = float(np.hypot(*shift))
    if length < 0.5:
        return None
    r = int(math.ceil(length / 2)) + 1
    kernel = np.zeros((2 * r + 1, 2 * r + 1), np.float64)
    for s in np.linspace(-0.5, 0.5, int(math.ceil(4 * length)) + 1):  # bilinear splats along the segment
        x, y = r + s * shift[0], r + s * shift[1]
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        fx, fy = x - x0, y - y0
        kernel[y0, x0] += (1 - fx) * (1 - fy)
        kernel[y0, x0 + 1] += fx * (1 - fy)
        kernel[y0 + 1, x0] += (1 - fx) * fy
        kernel[y0 + 1, x0 + 1] += fx * fy
    return kernel / kernel.sum()


def image_motion(frame: CameraFrame, velocity: np.ndarray, yaw_rate: float, exposure_s: float) -> np.ndarray:
    """Pixels the image centre moves during the exposure: the scene at the median depth seen from the camera
    moved by ``velocity`` x exposure and turned by ``yaw_rate`` x exposure (the map's z axis)."""
    depth = frame.depth
    finite = depth[np.isfinite(depth)] if depth is not None else np.empty(0)
    if not len(finite) or exposure_s <= 0.0:
        return np.zeros(2)
    k = frame.intrinsics
    centre = np.array([(k.width - 1) / 2, (k.height - 1) / 2])
    ray = np.array([(centre[0] - k.cx) / k.fx, (centre[1] - k.cy) / k.fy, 1.0])
    point = frame.pose.position + frame.pose.rotation @ (ray * float(np.median(finite)))
    a = yaw_rate * exposure_s
    turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    rotation, position = turn @ frame.pose.rotation, frame.pose.position + np.asarray(velocity) * exposure_s
    pixels, z = k.project(((point - position) @ rotation)[None, :])
    return pixels[0] - centre if np.isfinite(z[0]) else np.zeros(2)


class CameraErrors:
    """The camera of one flight, with its own seeded generator: stamps and image degradations."""

    def __init__(self, profile: SensorProfile, intrinsics: CameraIntrinsics, seed: int) -> None:
        self.profile = profile
        self._rng = np.random.default_rng([seed, 2])
        identity = profile.k1 == profile.k2 == profile.calibration_error == 0.0
        self._maps = None if identity else lens_maps(intrinsics, profile)

    def stamp_error(self) -> float:
        """Stamp minus true exposure time of the next frame (s): -offset + jitter - trigger latency."""
        p = self.profile
        return -p.clock_offset_s + self._rng.normal(0.0, p.clock_jitter_s) - self._rng.uniform(0.0, p.trigger_jitter_s)

    def degrade(self, truth: CameraFrame, velocity: np.ndarray, yaw_rate: float) -> np.ndarray:
        """The image the camera delivers of the exposure ``truth`` (rendered at the true pose)."""
        p = self.profile
        image = truth.image
        if self._maps is not None:
            image = cv2.remap(image, *self._maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        kernel = blur_kernel(image_motion(truth, velocity, yaw_rate, p.exposure_s))
        if kernel is not None:
            image = cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REPLICATE)
        gain = 2.0 ** self._rng.normal(0.0, p.exposure_sigma_ev)
        if gain != 1.0 or p.noise_std > 0.0:
            noisy = image.astype(np.float32) * np.float32(gain)
            noisy += self._rng.normal(0.0, p.noise_std, image.shape).astype(np.float32)
            image = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        if p.jpeg_quality > 0:
            ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                                    [cv2.IMWRITE_JPEG_QUALITY, p.jpeg_quality])
            image = cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        return image
