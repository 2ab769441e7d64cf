"""The decision maker: layers -> A0 (weights) -> A1 (zone) -> A2 (distance ring) -> A3 (path history) -> waypoint."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from layerpilot.decide.area import zone_mask
from layerpilot.decide.behavior import Behavior
from layerpilot.decide.decision import Candidate, Decision
from layerpilot.decide.history import PathHistory
from layerpilot.decide.schedule import WeightSchedule
from layerpilot.decide.terrain import terrain_altitude
from layerpilot.grid import GridGeometry
from layerpilot.layers.layerset import LayerSet


def distance_preference(distance: np.ndarray, r_e: float, r_i: float) -> np.ndarray:
    """P: 0 for d < r_e, 1 - (d - r_e) / (r_i - r_e) between r_e and r_i, 0 beyond r_i."""
    p = (np.float32(r_i) - distance) / np.float32(r_i - r_e)
    np.clip(p, 0.0, 1.0, out=p)
    p[distance < r_e] = 0.0
    return p


@dataclass(frozen=True)
class _Grid:
    """Everything that depends only on the grid, computed once per geometry."""

    geometry: GridGeometry
    xs: np.ndarray  # float32 (1, w) cell-centre x
    ys: np.ndarray  # float32 (h, 1) cell-centre y
    zone: np.ndarray  # float32 (h, w) Z
    inside: np.ndarray  # bool Z > 0
    zone_cells: int

    def distance(self, x: float, y: float) -> np.ndarray:
        dx, dy = self.xs - np.float32(x), self.ys - np.float32(y)
        d = dx * dx + dy * dy
        return np.sqrt(d, out=d)


@dataclass
class _Scores:
    layers: LayerSet
    grid: _Grid
    weights: dict[str, float]
    coverage: float
    a0: np.ndarray
    a1: np.ndarray
    p: np.ndarray
    h: np.ndarray
    a3: np.ndarray
    allowed: np.ndarray | None  # False near other drones' targets (None: everywhere allowed)
    distance: np.ndarray


class DecisionMaker:
    """Chooses waypoints for one drone; keeps path history, schedule phase and current target.

    ``decide`` is one decision tick (the drone reached its target, or the mission starts):
    it updates the path history and returns a fresh choice. ``reconsider`` is for use
    while flying; it only acts when the behavior opts into retargeting.
    """

    def __init__(self, behavior: Behavior, home: Sequence[float] = (0.0, 0.0), seed: int | None = None) -> None:
        self.behavior = behavior
        self.home = (float(home[0]), float(home[1]))
        self.rng = np.random.default_rng(behavior.seed if seed is None else seed)
        self.history = PathHistory(behavior.r_e, behavior.n)
        self.schedule = WeightSchedule(behavior)
        self.target: Decision | None = None
        self._target_p = 0.0
        self._switched_at = -np.inf
        self._grid_cache: _Grid | None = None

    def decide(
        self,
        layers: LayerSet,
        position: Sequence[float],
        time: float,
        *,
        intermediates: bool = False,
        avoid: Sequence[Sequence[float]] = (),
    ) -> Decision:
        """A decision tick: the next waypoint from ``position`` (map frame) at mission ``time``.

        ``avoid``: (x, y) points, e.g. other drones' targets; cells within r_e of them are not chosen.
        """
        scores = self._evaluate(layers, position, time, tick=True, avoid=avoid)
        decision = self._choose(scores, position, time, intermediates)
        self._set_target(decision, scores, time)
        return decision

    def reconsider(
        self, layers: LayerSet, position: Sequence[float], time: float, *, avoid: Sequence[Sequence[float]] = ()
    ) -> Decision | None:
        """While flying: a new target if retargeting is on and another cell beats the current one.

        The current target keeps the distance preference it had when chosen (the drone has
        committed to that hop; its P falls to 0 as the drone arrives); its other terms are
        re-read from the fresh layers and history. A switch needs the best cell to beat it by
        ``margin`` (relative), lie ``min_separation`` metres from it, and ``min_interval``
        seconds to have passed since the last switch: hysteresis against oscillation.
        """
        rt = self.behavior.retarget
        if not rt.enabled or self.target is None or time - self._switched_at < rt.min_interval:
            return None
        scores = self._evaluate(layers, position, time, tick=False, avoid=avoid)
        best = self._pick(scores.a3)
        if best is None:
            return None
        g = scores.grid.geometry
        row, col = g.cell_of(*self.target.waypoint[:2])
        current = 0.0
        if g.contains(row, col):
            current = float(scores.a1[row, col] * scores.h[row, col]) * self._target_p
        bx, by = g.cell_center(*best)
        tx, ty = self.target.waypoint[:2]
        if float(scores.a3[best]) <= current * (1.0 + rt.margin) or np.hypot(bx - tx, by - ty) < rt.min_separation:
            return None
        decision = self._explain(scores, best, position, time, None, retargeted=True)
        self._set_target(decision, scores, time)
        return decision

    # -- the equations ---------------------------------------------------------------------

    def _grid(self, geometry: GridGeometry) -> _Grid:
        if self._grid_cache is None or self._grid_cache.geometry != geometry:
            xs, ys = geometry.cell_centers()
            zone = zone_mask(self.behavior.area, geometry, self.home)
            cells = int(zone.sum())
            if cells == 0:
                raise ValueError(f"geometry: the grid {geometry} does not overlap the area of interest")
            self._grid_cache = _Grid(
                geometry, xs[:1].astype(np.float32), ys[:, :1].astype(np.float32), zone, zone > 0, cells
            )
        return self._grid_cache

    def _evaluate(
        self, layers: LayerSet, position: Sequence[float], time: float, tick: bool, avoid: Sequence[Sequence[float]]
    ) -> _Scores:
        if len(position) < 2 or not np.all(np.isfinite(np.asarray(position[:3], float))):
            raise ValueError(f"position: expected finite (x, y[, z]), got {position!r}")
        if not np.isfinite(time):
            raise ValueError(f"time: must be finite, got {time}")
        b = self.behavior
        grid = self._grid(layers.geometry)
        coverage = float(np.count_nonzero(layers.observed & grid.inside)) / grid.zone_cells
        weights = self.schedule.weights(time, coverage)
        a0 = np.zeros(layers.geometry.shape, np.float32)
        for name, w in weights.items():
            if w > 0:
                if name not in layers.layers:
                    raise ValueError(f"layers: behavior weights {name!r} but the layer set has only {layers.names}")
                a0 += np.float32(w) * layers.layers[name]
        a1 = a0 * grid.zone
        d = grid.distance(position[0], position[1])
        p = distance_preference(d, b.r_e, b.r_i)
        h = self.history.tick(layers.geometry, d) if tick else self.history.on(layers.geometry)
        a3 = a1 * p
        a3 *= h
        allowed = None
        for point in avoid:
            near = grid.distance(point[0], point[1]) < b.r_e
            allowed = ~near if allowed is None else allowed & ~near
        if allowed is not None:
            a3 *= allowed
        return _Scores(layers, grid, weights, coverage, a0, a1, p, h, a3, allowed, d)

    def _pick(self, score: np.ndarray) -> tuple[int, int] | None:
        """Argmax of ``score`` + seeded noise in [0, noise) on positive cells; None if no cell is > 0.

        Only cells within ``noise`` of the maximum can win, so noise is drawn for those
        alone: the same choice as noising every cell, at the cost of one comparison.
        """
        top = float(score.max())
        if not top > 0:
            return None
        noise = np.float32(self.behavior.noise)
        flat = np.flatnonzero(score >= max(top - noise, np.finfo(np.float32).tiny))
        if len(flat) > 1 and noise > 0:
            flat = flat[np.argmax(score.flat[flat] + noise * self.rng.random(len(flat), dtype=np.float32))]
        else:
            flat = flat[0]
        return divmod(int(flat), score.shape[1])

    def _runner_up(self, scores: _Scores, best: tuple[int, int]) -> tuple[int, int] | None:
        """Best cell at least r_e (and one cell) from the winner: a genuinely different option."""
        g = scores.grid.geometry
        reach = max(self.behavior.r_e, g.resolution)
        k = int(np.ceil(reach / g.resolution))
        r0, r1 = max(best[0] - k, 0), min(best[0] + k + 1, g.height)
        c0, c1 = max(best[1] - k, 0), min(best[1] + k + 1, g.width)
        bx, by = g.cell_center(*best)
        dx = scores.grid.xs[:, c0:c1] - np.float32(bx)
        dy = scores.grid.ys[r0:r1] - np.float32(by)
        window = scores.a3[r0:r1, c0:c1]
        saved = window.copy()
        window[dx * dx + dy * dy < reach * reach] = 0.0
        try:
            return self._pick(scores.a3)
        finally:
            window[...] = saved

    def _choose(self, scores: _Scores, position: Sequence[float], time: float, intermediates: bool) -> Decision:
        best = self._pick(scores.a3)
        if best is not None:
            runner = self._runner_up(scores, best)
            return self._explain(scores, best, position, time, runner, intermediates=intermediates)
        cell, rule = self._fallback(scores)
        return self._explain(scores, cell, position, time, None, fallback=rule, intermediates=intermediates)

    def _fallback(self, scores: _Scores) -> tuple[tuple[int, int], str]:
        """Nothing scored above zero (empty map, everything seen, weights all on empty layers).

        1. ``wander``: the best of Z * P * H (the distance ring and path history alone), so
           the drone keeps moving through the area and the map keeps growing.
        2. ``approach``: if no cell of the area lies in the ring with H > 0 (e.g. the drone is
           far outside the area): the nearest cell of the area at least r_e away, or, if the
           whole area is within r_e, its farthest cell.
        """
        z = scores.grid.zone if scores.allowed is None else scores.grid.zone * scores.allowed
        cell = self._pick(z * scores.p * scores.h)
        if cell is not None:
            return cell, "wander"
        if not z.any():
            z = scores.grid.zone  # every area cell is near another drone's target: ignore that
        d = np.where(z > 0, scores.distance, np.nan)
        far = d >= self.behavior.r_e
        flat = int(np.nanargmin(np.where(far, d, np.nan))) if far.any() else int(np.nanargmax(d))
        return divmod(flat, d.shape[1]), "approach"

    def _waypoint(self, scores: _Scores, cell: tuple[int, int], position: Sequence[float]) -> tuple[float, float, float]:
        g = scores.grid.geometry
        x, y = g.cell_center(*cell)
        b = self.behavior
        z = b.altitude
        if b.terrain.enabled:
            z = terrain_altitude(scores.layers.elevation_m, g, (position[0], position[1]), (x, y), b.terrain, b.altitude)
        return (x, y, float(z))

    def _explain(
        self,
        scores: _Scores,
        cell: tuple[int, int],
        position: Sequence[float],
        time: float,
        runner: tuple[int, int] | None,
        *,
        fallback: str | None = None,
        retargeted: bool = False,
        intermediates: bool = False,
    ) -> Decision:
        r, c = cell
        layers = scores.layers
        contributions = {k: float(np.float32(w) * layers.layers[k][r, c]) for k, w in scores.weights.items() if w > 0}
        images = None
        if intermediates:
            a2 = scores.a1 * scores.p
            images = {"A0": scores.a0, "A1": scores.a1, "A2": a2, "A3": scores.a3,
                      "Z": scores.grid.zone, "P": scores.p, "H": scores.h.copy()}
        runner_up = None
        if runner is not None:
            runner_up = Candidate(self._waypoint(scores, runner, position), runner, float(scores.a3[runner]))
        return Decision(
            time=float(time),
            waypoint=self._waypoint(scores, cell, position),
            cell=(int(r), int(c)),
            score=float(scores.a3[r, c]),
            contributions=contributions,
            aggregate=float(scores.a0[r, c]),
            zone=float(scores.grid.zone[r, c]),
            preference=float(scores.p[r, c]),
            history=float(scores.h[r, c]),
            weights=dict(scores.weights),
            coverage=scores.coverage,
            runner_up=runner_up,
            fallback=fallback,
            retargeted=retargeted,
            intermediates=images,
        )

    def _set_target(self, decision: Decision, scores: _Scores, time: float) -> None:
        self.target = decision
        self._target_p = decision.preference
        self._switched_at = time
