"""Layers as GeoTIFF for GIS users (QGIS, GDAL), in the map frame's own projected CRS.

The map frame is a transverse Mercator projection centred on its geodetic origin
(layerpilot.geodesy), so a layer grid *is* a grid of that CRS: the files carry it as a
user-defined GeoTIFF projection (ProjCoordTransGeoKey = transverse Mercator with the
origin as natural origin, scale 1, WGS 84) and need no resampling; GDAL and QGIS read it
and reproject on the fly. Rows are written north first (GeoTIFF's order; the grid's row 0
is the south edge). Pixels are areas: the tie point is the grid's north-west corner.

Files: ``color.tif`` (RGBA uint8, alpha 0 where unobserved), ``elevation_m.tif`` (float32,
the top of each column in metres in the origin altitude's vertical reference, i.e. map z +
origin alt, usually above mean sea level; NaN nodata where unobserved), one
``layer_<name>.tif`` per decision layer (float32 in [0, 1]).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import tifffile

from layerpilot.geodesy import LocalFrame
from layerpilot.grid import GridGeometry
from layerpilot.layers import LayerContext, compute_layers, layer_names
from layerpilot.map import VoxelMap
from layerpilot.progress import Progress

MAP_LAYERS = ("fringe", "time", "distance", "elevation")  # the built-in layers that need only the map

# GeoTIFF 1.0 tags and keys (OGC 19-008r4)
_PIXEL_SCALE, _TIEPOINT, _KEY_DIRECTORY, _DOUBLE_PARAMS, _ASCII_PARAMS, _GDAL_NODATA = (
    33550, 33922, 34735, 34736, 34737, 42113)
_USER_DEFINED, _CT_TRANSVERSE_MERCATOR, _METRE, _DEGREE, _WGS84 = 32767, 1, 9001, 9102, 4326


def geokeys(frame: LocalFrame) -> list[tuple[int, int, int, int]]:
    """The tags that put a raster in ``frame.crs``: user-defined transverse Mercator on WGS 84."""
    citation = f"{frame.crs.name}|"
    doubles = [frame.lon, frame.lat, 0.0, 0.0, 1.0]
    keys = [  # (key id, tag holding the value (0: inline short), count, value or index)
        (1024, 0, 1, 1),  # GTModelType: projected
        (1025, 0, 1, 1),  # GTRasterType: PixelIsArea
        (1026, _ASCII_PARAMS, len(citation), 0),  # GTCitation
        (2048, 0, 1, _WGS84),  # GeographicType
        (2054, 0, 1, _DEGREE),  # GeogAngularUnits
        (3072, 0, 1, _USER_DEFINED),  # ProjectedCSType
        (3074, 0, 1, _USER_DEFINED),  # Projection
        (3075, 0, 1, _CT_TRANSVERSE_MERCATOR),  # ProjCoordTrans
        (3076, 0, 1, _METRE),  # ProjLinearUnits
        (3080, _DOUBLE_PARAMS, 1, 0),  # ProjNatOriginLong
        (3081, _DOUBLE_PARAMS, 1, 1),  # ProjNatOriginLat
        (3082, _DOUBLE_PARAMS, 1, 2),  # ProjFalseEasting
        (3083, _DOUBLE_PARAMS, 1, 3),  # ProjFalseNorthing
        (3092, _DOUBLE_PARAMS, 1, 4),  # ProjScaleAtNatOrigin
    ]
    directory = [1, 1, 0, len(keys)] + [v for key in keys for v in key]
    return [
        (_KEY_DIRECTORY, "H", len(directory), directory, True),
        (_DOUBLE_PARAMS, "d", len(doubles), doubles, True),
        (_ASCII_PARAMS, "s", 0, citation, True),
    ]


def write_geotiff(path: Path, data: np.ndarray, geometry: GridGeometry, frame: LocalFrame,
                  nodata: float | None = None) -> Path:
    """Write ``data`` ((h, w) or (h, w, 3|4) on ``geometry``, row 0 south) as a GeoTIFF in ``frame.crs``."""
    if data.shape[:2] != geometry.shape:
        raise ValueError(f"data: expected shape {geometry.shape} (the grid's), got {data.shape}")
    xmin, _, _, ymax = geometry.extent
    r = geometry.resolution
    tags = [(_PIXEL_SCALE, "d", 3, (r, r, 0.0), True), (_TIEPOINT, "d", 6, (0, 0, 0, xmin, ymax, 0.0), True),
            *geokeys(frame)]
    if nodata is not None:
        tags.append((_GDAL_NODATA, "s", 0, f"{nodata}", True))
    options: dict = {}
    if data.ndim == 3:
        options = {"photometric": "rgb", "extrasamples": ("unassalpha",) if data.shape[2] == 4 else ()}
    else:
        options = {"photometric": "minisblack"}
    tifffile.imwrite(path, np.ascontiguousarray(data[::-1]), extratags=tags, compression="zlib",
                     metadata=None, **options)
    return path


def map_grid(voxel_map: VoxelMap) -> GridGeometry:
    """The grid over the map's known space, aligned to its voxels."""
    s = voxel_map.stats()
    if not s["occupied_leaves"]:
        raise ValueError("map: it has no occupied voxel, so no layer to export")
    r = voxel_map.resolution
    (x0, y0, _), (x1, y1, _) = s["bounds_min"], s["bounds_max"]
    ox, oy = np.floor(x0 / r) * r, np.floor(y0 / r) * r
    return GridGeometry(float(ox), float(oy), r, max(1, int(np.ceil((x1 - ox) / r))),
                        max(1, int(np.ceil((y1 - oy) / r))))


def exportable_layers() -> list[str]:
    """The registered layers computable from a map alone (what ``export_layers`` accepts)."""
    return layer_names(LayerContext(now=0.0))


def export_layers(voxel_map: VoxelMap, frame: LocalFrame, out: Path, names: Sequence[str] = MAP_LAYERS) -> list[Path]:
    """color.tif, elevation_m.tif and one GeoTIFF per named layer of ``voxel_map`` into ``out``.

    Time-dependent layers are taken at the map's newest observation. Only layers a map alone gives
    can be exported (``exportable_layers``); one needing a decision's context (view_gain: a camera
    view and an area of interest) is a ValueError naming what can.
    """
    exportable = exportable_layers()
    if refused := [n for n in names if n not in exportable]:
        why = ", ".join(f"{n!r} ({'needs a decision context, not a map alone' if n in layer_names() else 'unknown'})"
                        for n in refused)
        raise ValueError(f"layer: cannot export {why}; exportable: {', '.join(exportable)}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = voxel_map.column_layers_for(map_grid(voxel_map))
    seen = columns.last_seen[columns.observed]
    now = float(np.nanmax(seen)) if np.isfinite(seen).any() else 0.0
    layers = compute_layers(columns, LayerContext(now=now), names, voxel_map)
    g = columns.geometry
    progress = Progress(len(names) + 2, "geotiff")
    rgba = np.dstack([layers.rgb, np.where(layers.observed, 255, 0).astype(np.uint8)])
    written = [write_geotiff(out / "color.tif", rgba, g, frame)]
    progress.update(1)
    height = (layers.elevation_m + np.float32(frame.alt)).astype(np.float32)
    written.append(write_geotiff(out / "elevation_m.tif", height, g, frame, nodata=float("nan")))
    progress.update(2)
    for i, name in enumerate(layers.names, 3):
        written.append(write_geotiff(out / f"layer_{name}.tif", layers[name], g, frame))
        progress.update(i)
    progress.close(f"{len(written)} GeoTIFFs of {g.width} x {g.height} cells")
    return written
