"""What a geotagged drone photo says about itself: position, camera, attitude.

EXIF (read with ``exifread``): GPS latitude, longitude and altitude, focal length, the 35 mm
equivalent focal length, the focal-plane resolution (sensor size) and the image size. XMP
(``photos.xmp``): the gimbal and flight attitude and the height above take-off. DJI writes
``drone-dji:GimbalPitchDegree`` and friends; Parrot writes ``drone-parrot:CameraPitchDegree``
with the same conventions; both are read by local name. Angles are degrees in the vendors'
convention: yaw clockwise from north, pitch -90 = straight down, roll right wing down.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import exifread

from layerpilot.photos.xmp import read_xmp

# Equivalent XMP names, first found wins (local names, any namespace prefix).
XMP_NAMES = {
    "gimbal_yaw": ("GimbalYawDegree", "CameraYawDegree"),
    "gimbal_pitch": ("GimbalPitchDegree", "CameraPitchDegree"),
    "gimbal_roll": ("GimbalRollDegree", "CameraRollDegree"),
    "flight_yaw": ("FlightYawDegree",),
    "flight_pitch": ("FlightPitchDegree",),
    "flight_roll": ("FlightRollDegree",),
    "relative_altitude": ("RelativeAltitude",),
}


@dataclass(frozen=True)
class PhotoMetadata:
    """One photo's metadata; None where the file does not say."""

    path: Path
    width: int
    height: int
    lat: float | None
    lon: float | None
    alt: float | None  # metres, EXIF GPS altitude (above sea level, as the camera writes it)
    focal_mm: float | None
    focal_35mm: float | None
    sensor_width_mm: float | None  # from the EXIF focal-plane resolution
    make: str
    model: str
    gimbal_yaw: float | None = None
    gimbal_pitch: float | None = None
    gimbal_roll: float | None = None
    flight_yaw: float | None = None
    flight_pitch: float | None = None
    flight_roll: float | None = None
    relative_altitude: float | None = None  # metres above take-off
    taken_at: float | None = None  # s: EXIF DateTimeOriginal (+ SubSecTimeOriginal) read as UTC; differences count

    @property
    def has_position(self) -> bool:
        return self.lat is not None and self.lon is not None and self.alt is not None

    def focal_px(self) -> float:
        """Focal length in pixels: from the sensor width if EXIF has it, else from the 35 mm
        equivalent (36 mm across the image width, the usual rule), else ValueError."""
        if self.focal_mm and self.sensor_width_mm:
            return self.focal_mm / self.sensor_width_mm * self.width
        if self.focal_35mm:
            return self.focal_35mm / 36.0 * self.width
        raise ValueError(f"{self.path.name}: no sensor size or 35 mm equivalent focal length in EXIF; "
                         "give a calibration file")


def _ratio(value) -> float:
    return float(value.num) / float(value.den) if value.den else math.nan


def _number(tags: dict, key: str) -> float | None:
    tag = tags.get(key)
    if tag is None or not tag.values:
        return None
    v = tag.values[0]
    out = _ratio(v) if hasattr(v, "num") else float(v)
    return out if math.isfinite(out) and out > 0 else None


def _degrees(tags: dict, key: str, ref_key: str, negative: str) -> float | None:
    tag = tags.get(key)
    if tag is None or len(tag.values) != 3:
        return None
    d, m, s = (_ratio(v) for v in tag.values)
    value = d + m / 60.0 + s / 3600.0
    if not math.isfinite(value):
        return None
    return -value if str(tags.get(ref_key, "")).strip().upper() == negative else value


def _sensor_width_mm(tags: dict, width: int) -> float | None:
    """Sensor width from the focal-plane resolution (pixels per unit across the sensor)."""
    res = _number(tags, "EXIF FocalPlaneXResolution")
    unit = {2: 25.4, 3: 10.0, 4: 1.0}.get(int(_number(tags, "EXIF FocalPlaneResolutionUnit") or 2))
    return width / res * unit if res and unit else None


def _taken_at(tags: dict) -> float | None:
    """EXIF's "YYYY:MM:DD HH:MM:SS" capture time with its sub-seconds; None if absent or malformed."""
    text = str(tags.get("EXIF DateTimeOriginal", "")).strip()
    try:
        t = datetime.strptime(text, "%Y:%m:%d %H:%M:%S").replace(tzinfo=timezone.utc).timestamp()
    except ValueError:
        return None
    sub = str(tags.get("EXIF SubSecTimeOriginal", "")).strip()
    return t + (float(f"0.{sub}") if sub.isdigit() else 0.0)


def read_metadata(path: str | Path) -> PhotoMetadata:
    """EXIF and XMP of one JPEG; ValueError names the file when it is not a readable photo."""
    path = Path(path)
    data = path.read_bytes()
    tags = exifread.process_file(io.BytesIO(data), details=False)
    width = _number(tags, "EXIF ExifImageWidth")
    height = _number(tags, "EXIF ExifImageLength")
    if not width or not height:
        raise ValueError(f"{path.name}: no image size in EXIF (not a camera JPEG?)")
    alt = None
    if (a := tags.get("GPS GPSAltitude")) is not None:
        alt = _ratio(a.values[0])
        if str(tags.get("GPS GPSAltitudeRef", "0")).strip() in ("1", "Below Sea Level"):
            alt = -alt
    try:
        xmp = read_xmp(data)
    except ValueError as exc:
        raise ValueError(f"{path.name}: {exc}") from None
    attitude = {}
    for field, names in XMP_NAMES.items():
        raw = next((xmp[n] for n in names if n in xmp), None)
        try:
            attitude[field] = float(raw) if raw is not None else None
        except ValueError:
            raise ValueError(f"{path.name}: XMP {names[0]} = {raw!r} is not a number") from None
    return PhotoMetadata(
        path=path, width=int(width), height=int(height),
        lat=_degrees(tags, "GPS GPSLatitude", "GPS GPSLatitudeRef", "S"),
        lon=_degrees(tags, "GPS GPSLongitude", "GPS GPSLongitudeRef", "W"), alt=alt,
        focal_mm=_number(tags, "EXIF FocalLength"), focal_35mm=_number(tags, "EXIF FocalLengthIn35mmFilm"),
        sensor_width_mm=_sensor_width_mm(tags, int(width)),
        make=str(tags.get("Image Make", "")).strip(), model=str(tags.get("Image Model", "")).strip(),
        taken_at=_taken_at(tags), **attitude)
