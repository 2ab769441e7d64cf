"""The next flight: the decision maker, run ahead over a finished flight's map, proposes waypoints over its gaps.

Gaps are the cells of the area of interest that the map never observed, or last observed
more than ``stale_after`` seconds before ``now``. For the next flight a stale cell is as
good as unseen, so it is handed to the layers as unobserved.

The plan is the decision maker's own sequence of choices with a chosen behavior, made
ahead of time: after each choice the planner assumes the drone sees a disc of
``footprint`` metres around the waypoint (those cells become observed, seen now) and asks
again, so the frontier, the ages and the path history move as they would in flight. A
choice whose disc covers no remaining gap (the behavior preferred an already seen cell)
is not kept as a waypoint, but still counts as seen, so the next choice moves on. The
plan ends when ``target_coverage`` of the gaps lie under some waypoint's disc, after
``max_waypoints`` waypoints, or after ``max_idle`` choices in a row that covered nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from layerpilot.decide.area import zone_mask
from layerpilot.decide.behavior import Behavior
from layerpilot.decide.maker import DecisionMaker
from layerpilot.layers.registry import LayerContext, compute_layers
from layerpilot.map.columns import ColumnLayers


@dataclass(frozen=True)
class FlightPlan:
    """Waypoints (map frame, (n, 3)) and how much of the gaps they cover."""

    waypoints: np.ndarray
    gaps: np.ndarray  # bool (h, w): cells of the area unobserved or stale at planning time
    covered: np.ndarray  # bool (h, w): gap cells under some waypoint's footprint
    decisions: int  # choices the decision maker made (kept waypoints and skipped ones)
    stopped: str = "coverage"  # why it ended: "no gaps", "coverage" (target reached), "max_waypoints", "max_idle"

    @property
    def coverage(self) -> float:
        """Share of the gap cells under the plan's footprints (1.0 when there was no gap)."""
        total = int(self.gaps.sum())
        return 1.0 if total == 0 else float(self.covered.sum()) / total


def gap_mask(columns: ColumnLayers, zone: np.ndarray, now: float, stale_after: float) -> np.ndarray:
    """Cells of ``zone`` (bool) never observed, or last seen more than ``stale_after`` s before ``now``."""
    with np.errstate(invalid="ignore"):
        stale = columns.observed & (columns.last_seen < now - stale_after)
    return zone & (~columns.observed | stale)


def plan_next_flight(
    columns: ColumnLayers,
    behavior: Behavior,
    *,
    home: Sequence[float] = (0.0, 0.0),
    start: Sequence[float] | None = None,
    now: float | None = None,
    stale_after: float = np.inf,
    footprint: float | None = None,
    max_waypoints: int = 100,
    target_coverage: float = 0.95,
    max_idle: int = 20,
    seed: int | None = None,
) -> FlightPlan:
    """The next flight over the gaps of ``columns`` (a finished flight's map on the area's grid).

    ``start``: where the drone begins (default: above ``home`` at the behavior's altitude);
    ``now``: the planning time on the map's clock (default: its newest observation);
    ``footprint``: metres seen around a waypoint (default: the behavior's r_e, the radius
    its path history already treats as visited, at least one cell).
    """
    g = columns.geometry
    if not stale_after > 0:
        raise ValueError(f"stale_after: must be > 0 seconds, got {stale_after}")
    if not 0 < target_coverage <= 1:
        raise ValueError(f"target_coverage: must lie in (0, 1], got {target_coverage}")
    if max_waypoints < 1 or max_idle < 1:
        raise ValueError(f"max_waypoints and max_idle: must be >= 1, got {max_waypoints}, {max_idle}")
    radius = max(behavior.r_e, g.resolution) if footprint is None else float(footprint)
    if not radius > 0:
        raise ValueError(f"footprint: must be > 0 metres, got {footprint}")
    home = (float(home[0]), float(home[1]))
    if now is None:
        seen = columns.last_seen[columns.observed & np.isfinite(columns.last_seen)]
        now = float(seen.max()) if seen.size else 0.0
    zone = zone_mask(behavior.area, g, home) > 0.5
    gaps = gap_mask(columns, zone, now, stale_after)
    covered = np.zeros_like(gaps)
    position = (home[0], home[1], behavior.altitude) if start is None else tuple(float(v) for v in start[:3])
    state = _Virtual.of(columns, gaps & columns.observed)
    maker = DecisionMaker(behavior, home, seed)
    xs, ys = g.cell_centers()
    waypoints: list[tuple[float, float, float]] = []
    decisions = idle = 0
    t = now
    stopped = "no gaps" if not gaps.any() else "coverage"
    while gaps.any() and covered.sum() < target_coverage * gaps.sum():
        if len(waypoints) >= max_waypoints:
            stopped = "max_waypoints"
            break
        layers = compute_layers(state.columns(), LayerContext(now=t, home=home, position=position,
                                                              options=behavior.layers, aoi=zone),
                                behavior.layer_names)
        wp = maker.decide(layers, position, t).waypoint
        decisions += 1
        disc = (xs - wp[0]) ** 2 + (ys - wp[1]) ** 2 <= radius * radius
        new = disc & gaps & ~covered
        state.observe(disc, t, behavior.altitude)
        if new.any():
            covered |= new
            waypoints.append(wp)
            position, idle = wp, 0
        else:
            idle += 1
            if idle >= max_idle:
                stopped = "max_idle"
                break
        t += 1.0  # one decision tick on the plan's clock: what just got seen is the freshest
    return FlightPlan(np.array(waypoints, float).reshape(-1, 3), gaps, covered, decisions, stopped)


@dataclass
class _Virtual:
    """The columns as the planner imagines them while the next flight is under way."""

    geometry: object
    observed: np.ndarray
    elevation: np.ndarray
    color: np.ndarray
    last_seen: np.ndarray
    min_distance: np.ndarray
    ground: float  # elevation assumed for cells the planned flight will see

    @classmethod
    def of(cls, columns: ColumnLayers, forget: np.ndarray) -> "_Virtual":
        """A copy of ``columns`` with the ``forget`` cells (stale) made unobserved."""
        top = columns.elevation[columns.observed & ~forget]
        ground = float(np.nanmedian(top)) if np.isfinite(top).any() else 0.0
        observed = columns.observed & ~forget
        return cls(columns.geometry, observed,
                   np.where(forget, np.float32(np.nan), columns.elevation).astype(np.float32),
                   np.where(forget[..., None], np.uint8(0), columns.color).astype(np.uint8),
                   np.where(forget, np.nan, columns.last_seen),
                   np.where(forget, np.float32(np.inf), columns.min_distance).astype(np.float32), ground)

    def observe(self, cells: np.ndarray, t: float, altitude: float) -> None:
        fresh = cells & ~self.observed
        self.elevation[fresh] = self.ground
        self.observed |= cells
        self.last_seen[cells] = t
        np.minimum(self.min_distance, np.float32(altitude), out=self.min_distance, where=cells)

    def columns(self) -> ColumnLayers:
        return ColumnLayers(self.geometry, self.observed, self.elevation, self.color, self.last_seen,
                            self.min_distance)
