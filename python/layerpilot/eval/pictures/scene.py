"""One decision on a map, drawn: what `layerpilot layers render` does."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from layerpilot.eval.pictures.layers import render
from layerpilot.layers.registry import LayerContext, compute_layers, layer_names


def render_scene(
    behavior_name: str | Path,
    out: Path,
    map_path: Path | None = None,
    position: tuple[float, float, float] | None = None,
    home: tuple[float, float] = (0.0, 0.0),
    now: float | None = None,
    frames: int = 6,
) -> list[Path]:
    """Build or load a map, compute every layer, decide once from ``position``, write the pictures.

    Without a map, a synthetic survey leg (``layerpilot.eval.fixtures.survey_clouds``) is inserted and
    the decision maker ticks once at each frame's position, so the path history shows
    the leg; the drone is then at the last frame.
    """
    from layerpilot.decide import DecisionMaker, area_geometry, load_behavior
    from layerpilot.map import VoxelMap

    behavior = load_behavior(behavior_name)
    dm = DecisionMaker(behavior, home=home)
    path_positions: list[np.ndarray] = []
    if map_path is None:
        from layerpilot.eval.fixtures import survey_clouds

        m = VoxelMap(1.0)
        for frame in survey_clouds(frames, width=160, height=120):
            m.insert(frame.points, frame.origin, frame.colors, frame.stamp)
            path_positions.append(frame.origin)
        source = f"synthetic survey, {frames} frames"
    else:
        m = VoxelMap.load(map_path)
        source = map_path.name
    geometry = area_geometry(behavior.area, home, m.resolution)
    columns = m.column_layers_for(geometry)
    if now is None:
        seen = columns.last_seen[columns.observed]
        now = float(seen.max()) + 1.0 if seen.size else 0.0
    if position is None:
        position = tuple(path_positions[-1]) if path_positions else (home[0], home[1], behavior.altitude)
    context = LayerContext(now=now, home=home, position=position, options=behavior.layers)
    layers = compute_layers(columns, context, layer_names(context), voxel_map=m)
    for k, earlier in enumerate(path_positions[:-1]):
        dm.decide(layers, earlier, now - len(path_positions) + k)
    decision = dm.decide(layers, position, now, intermediates=True)
    title = f"{behavior.name} behavior, {source}, t = {now:.1f} s"
    return render(layers, out, decision, position, title)
