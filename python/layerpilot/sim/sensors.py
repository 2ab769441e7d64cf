"""Sensor profiles: how far what the drone reports (EKF pose, camera stamps, images) is from the truth.

A profile is one table of explicit numbers; a mission picks a preset by name
(``[sim] sensors = "consumer"``) and may override single fields
(``[sim.sensor_overrides] horizontal_sigma_m = 3.0``). The presets and where their
numbers come from:

* ``perfect``: no error anywhere (the simulator as it always was).
* ``rtk``: a u-blox ZED-F9P-class RTK receiver under the EKF. F9P datasheet
  (UBX-17051259): RTK 0.01 m + 1 ppm CEP horizontal, 0.01 m + 1 ppm R50 vertical; the
  EKF's output is kept a few times worse (2 cm / 4 cm per axis) for antenna-offset and
  fusion lag. Attitude from a tuned EKF3 (0.2 deg tilt); heading with a dual-antenna
  moving base (u-blox quotes a few tenths of a degree at a 1 m baseline) -> 0.5 deg. A camera with a
  hot-shoe feedback pin (PX4 "camera capture", ArduPilot CAM_FEEDBACK_PIN): 10 ms offset,
  2 ms jitter (ArduPilot logs CAM events at 50 Hz, ardupilot issue 7892).
* ``consumer``: a u-blox M8/M9-class receiver under ArduPilot EKF3 / PX4 EKF2 with a
  compass and a USB/MIPI camera stamped by the companion. NEO-M8N datasheet
  (UBX-15031086): 2.5 m CEP (GPS), 2.0 m CEP (GPS+GLONASS); CEP 2.0 m is 1.70 m per axis
  for a circular Gaussian (CEP = 1.1774 sigma) -> 1.7 m; NEO-M9N: 1.5 m CEP. GNSS errors
  (multipath, ionosphere, orbits) decorrelate over minutes: the measured autocorrelation
  of a consumer receiver bends near 1 min and decays over tens of minutes
  (D. L. Wilson, "Correlation of errors", erols.com/dlwilson/gpscorr.htm) -> tau 120 s.
  Vertical GNSS is 1.5-2x worse than horizontal -> 3.0 m; EKF3 takes height from the
  barometer by default (EK3_SRC1_POSZ = 1), which drifts with temperature and weather
  (1 hPa ~ 8 m; EK3_HGT_M_NSE default 2 m) -> 0.3 m/min. Roll and pitch 0.5 deg
  (accelerometer bias and manoeuvre errors of MEMS IMUs), heading 2 deg with a 2 deg
  bias (compass calibration and motor interference; EK3_YAW_M_NSE default 0.5 rad is
  the filter's own, much looser, assumption); position and attitude errors low-passed over
  2 s (the EKF integrates the gyros between corrections: its attitude does not jump between
  reports). Camera clock 100 ms behind the telemetry with 10 ms jitter and up to 20 ms
  trigger latency (UVC/MIPI capture latency, MAVLink telemetry latency and time_boot_ms
  alignment on a companion computer). Images: 1/250 s
  exposure, +-0.15 EV auto-exposure steps, 2 DN sensor noise (8-bit, base ISO), JPEG 85,
  a wide lens with k1 = -0.05, k2 = 0.01 calibrated 2 % off.
* ``degraded``: a poor day for the same hardware - multipath near trees, an uncalibrated
  compass, a rolling-shutter webcam on a busy USB bus: about twice ``consumer`` everywhere.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass
from typing import Any

from layerpilot.config import ConfigError, check_range

_POSE_FIELDS = ("horizontal_sigma_m", "horizontal_white_m", "vertical_sigma_m", "baro_drift_m_per_min",
                "tilt_sigma_deg", "heading_sigma_deg", "heading_bias_deg")
_CAMERA_FIELDS = ("clock_offset_s", "clock_jitter_s", "trigger_jitter_s", "exposure_s", "exposure_sigma_ev",
                  "noise_std", "jpeg_quality", "k1", "k2", "calibration_error")


@dataclass(frozen=True)
class SensorProfile:
    """Errors of the reported pose (EKF), the camera's clock and its images; all zero = perfect sensors.

    Position and attitude errors are first-order Gauss-Markov processes: stationary standard
    deviation ``*_sigma_*``, autocorrelation exp(-|dt| / ``*_tau_s``), low-passed over
    ``*_smoothing_s`` as an EKF's outputs are.
    """

    horizontal_sigma_m: float = 0.0    # GNSS/EKF horizontal error per axis (east, north), Gauss-Markov
    horizontal_tau_s: float = 120.0
    horizontal_white_m: float = 0.0    # white noise on top, per axis and per EKF output
    vertical_sigma_m: float = 0.0      # vertical Gauss-Markov error
    vertical_tau_s: float = 120.0
    position_smoothing_s: float = 2.0  # the receiver's and EKF's low-pass on the position error
    baro_drift_m_per_min: float = 0.0  # barometric height drift (its sign is drawn from the seed)
    tilt_sigma_deg: float = 0.0        # roll and pitch error each, Gauss-Markov
    tilt_tau_s: float = 30.0
    heading_sigma_deg: float = 0.0     # heading error, Gauss-Markov around the bias
    heading_tau_s: float = 60.0
    heading_bias_deg: float = 0.0      # constant heading error
    attitude_smoothing_s: float = 2.0  # the EKF's low-pass on the attitude error (gyros integrated between corrections)
    clock_offset_s: float = 0.0        # the camera's stamps run this far behind the telemetry's clock
    clock_jitter_s: float = 0.0        # standard deviation of each stamp around that offset
    trigger_jitter_s: float = 0.0      # exposure starts up to this long (uniform) after the stamped trigger
    exposure_s: float = 0.0            # exposure time: motion blur = image motion during it (0 = none)
    exposure_sigma_ev: float = 0.0     # frame-to-frame brightness changes of auto-exposure (stops, Gaussian)
    noise_std: float = 0.0             # sensor noise, 8-bit digital numbers (Gaussian)
    jpeg_quality: int = 0              # JPEG compression quality 1-100 (0 = no JPEG)
    k1: float = 0.0                    # the lens's true radial distortion (Brown-Conrady k1, k2)
    k2: float = 0.0
    calibration_error: float = 0.0     # the calibration's focal length and k1, k2 are (1 + this) x the truth

    def __post_init__(self) -> None:
        for name in ("horizontal_sigma_m", "horizontal_white_m", "vertical_sigma_m"):
            check_range(name, getattr(self, name), 0.0, 100.0)
        for name in ("horizontal_tau_s", "vertical_tau_s", "tilt_tau_s", "heading_tau_s"):
            check_range(name, getattr(self, name), 0.1, 1e5)
        check_range("position_smoothing_s", self.position_smoothing_s, 0.1, 60.0)
        check_range("attitude_smoothing_s", self.attitude_smoothing_s, 0.1, 60.0)
        check_range("baro_drift_m_per_min", self.baro_drift_m_per_min, 0.0, 10.0)
        check_range("tilt_sigma_deg", self.tilt_sigma_deg, 0.0, 10.0)
        check_range("heading_sigma_deg", self.heading_sigma_deg, 0.0, 45.0)
        check_range("heading_bias_deg", self.heading_bias_deg, -45.0, 45.0)
        check_range("clock_offset_s", self.clock_offset_s, 0.0, 1.0)
        for name in ("clock_jitter_s", "trigger_jitter_s", "exposure_s"):
            check_range(name, getattr(self, name), 0.0, 0.1)
        check_range("exposure_sigma_ev", self.exposure_sigma_ev, 0.0, 2.0)
        check_range("noise_std", self.noise_std, 0.0, 50.0)
        check_range("jpeg_quality", self.jpeg_quality, 0, 100)
        check_range("k1", self.k1, -0.5, 0.5)
        check_range("k2", self.k2, -0.5, 0.5)
        check_range("calibration_error", self.calibration_error, -0.2, 0.2)

    @property
    def exact_pose(self) -> bool:
        """The autopilot reports the true pose."""
        return all(getattr(self, name) == 0 for name in _POSE_FIELDS)

    @property
    def exact_camera(self) -> bool:
        """The camera delivers the rendered image, stamped at its true time."""
        return all(getattr(self, name) == 0 for name in _CAMERA_FIELDS)


PROFILES: dict[str, SensorProfile] = {
    "perfect": SensorProfile(),
    "rtk": SensorProfile(horizontal_sigma_m=0.02, horizontal_white_m=0.005, vertical_sigma_m=0.04,
                         tilt_sigma_deg=0.2, heading_sigma_deg=0.5, heading_bias_deg=0.2,
                         clock_offset_s=0.01, clock_jitter_s=0.002, trigger_jitter_s=0.002,
                         exposure_s=0.002, exposure_sigma_ev=0.05, noise_std=1.0, jpeg_quality=95,
                         k1=-0.05, k2=0.01, calibration_error=0.005),
    "consumer": SensorProfile(horizontal_sigma_m=1.7, horizontal_white_m=0.1, vertical_sigma_m=3.0,
                              baro_drift_m_per_min=0.3, tilt_sigma_deg=0.5, heading_sigma_deg=2.0,
                              heading_bias_deg=2.0, clock_offset_s=0.1, clock_jitter_s=0.01,
                              trigger_jitter_s=0.02, exposure_s=0.004, exposure_sigma_ev=0.15, noise_std=2.0,
                              jpeg_quality=85, k1=-0.05, k2=0.01, calibration_error=0.02),
    "degraded": SensorProfile(horizontal_sigma_m=3.5, horizontal_white_m=0.15, vertical_sigma_m=6.0,
                              baro_drift_m_per_min=0.6, tilt_sigma_deg=1.0, heading_sigma_deg=5.0,
                              heading_bias_deg=5.0, clock_offset_s=0.25, clock_jitter_s=0.03,
                              trigger_jitter_s=0.04, exposure_s=0.015, exposure_sigma_ev=0.3, noise_std=5.0,
                              jpeg_quality=60, k1=-0.1, k2=0.02, calibration_error=0.05),
}


def sensor_profile(name: str, overrides: dict[str, Any] | None = None, prefix: str = "") -> SensorProfile:
    """Preset ``name`` with single fields replaced; an unknown name, key or bad value is an error naming it
    (``<prefix>sensors``, ``<prefix>sensor_overrides.<key>``)."""
    where = f"{prefix}sensor_overrides"
    if name not in PROFILES:
        raise ConfigError(f"{prefix}sensors: expected one of {', '.join(map(repr, PROFILES))}, got {name!r}")
    overrides = dict(overrides or {})
    hints = typing.get_type_hints(SensorProfile)
    fields = [f.name for f in dataclasses.fields(SensorProfile)]
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        raise ConfigError(f"unknown key(s) {', '.join(f'{where}.{k}' for k in unknown)}; "
                          f"allowed: {', '.join(fields)}")
    for key, value in overrides.items():
        if hints[key] is int:
            if float(value) != int(value):
                raise ConfigError(f"{where}.{key}: expected a whole number, got {value!r}")
            overrides[key] = int(value)
    try:
        return dataclasses.replace(PROFILES[name], **overrides)
    except ConfigError as exc:
        raise ConfigError(f"{where}.{exc}") from None
