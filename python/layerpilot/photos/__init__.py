"""Real photos in: EXIF/XMP metadata, camera poses in the map frame, image-based pose refinement
and stereo for pairs of geotagged drone photos (see docs/photos.md)."""

from layerpilot.photos.config import PhotoConfig, RefineConfig
from layerpilot.photos.folder import PhotoFolder, read_folder
from layerpilot.photos.metadata import PhotoMetadata, read_metadata
from layerpilot.photos.pairs import PairResult, PhotoStereo

__all__ = ["PhotoConfig", "RefineConfig", "PhotoFolder", "read_folder", "PhotoMetadata", "read_metadata",
           "PairResult", "PhotoStereo"]
