"""The voxel map: OctoMap occupancy with per-voxel color, last-seen time and min distance."""

from layerpilot.map.columns import ColumnLayers
from layerpilot.map.files import MapFileError
from layerpilot.map.voxel_map import InsertResult, SensorModel, VoxelMap, Voxels

__all__ = ["ColumnLayers", "InsertResult", "MapFileError", "SensorModel", "VoxelMap", "Voxels"]
