"""The decision maker: layers -> A0 (weights) -> A1 (zone) -> A2 (distance ring) -> A3 (path history) -> waypoint.

P is exactly 0 beyond r_i, so A3 is 0 on every cell farther than r_i from the drone and
no such cell can be chosen: a tick computes every term on the window of cells within r_i
(``DecisionMaker.window``), not on the whole grid. Coverage (a count over the whole area)
and the layers' own normalisation still see the whole grid. Being a rectangle, the
window keeps the grid's row-major order, so argmax, ties and the seeded noise draw the
same cells as a whole-grid pass (tests/test_decide_window.py).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from layerpilot.decide.area import zone_mask
from layerpilot.decide.behavior import Behavior
from layerpilot.decide.decision import Candidate, Decision
from layerpilot.decide.history import PathHistory
from layerpilot.decide.schedule import WeightSchedule
from layerpilot.decide.terrain import terrain_altitude
from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.layers.feature_layers import FeatureLayers


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

    def distance(self, x: float, y: float, window: GridWindow) -> np.ndarray:
        """Metres from (x, y) to each cell centre of ``window``."""
        dx = self.xs[:, window.col0:window.col1] - np.float32(x)
        dy = self.ys[window.row0:window.row1] - np.float32(y)
        d = dx * dx + dy * dy
        return np.sqrt(d, out=d)


@dataclass
class _Scores:
    """Every term on ``window`` (arrays of its shape); cells are (row, col) of the whole grid."""

    layers: FeatureLayers
    grid: _Grid
    window: GridWindow
    position: Sequence[float]
    time: float
    avoid: Sequence[Sequence[float]]
    weights: dict[str, float]
    coverage: float
    a0: np.ndarray
    a1: np.ndarray
    p: np.ndarray
    h: np.ndarray
    a3: np.ndarray
    allowed: np.ndarray | None  # False near other drones' targets (None: everywhere allowed)
    distance: np.ndarray

    def at(self, arr: np.ndarray, cell: tuple[int, int]) -> float:
        return float(arr[cell[0] - self.window.row0, cell[1] - self.window.col0])


@dataclass(frozen=True)
class TickTerms:
    """The aggregate layers of one tick, as it computed them on its window (kept by reference: free).

    ``placement`` is the window's own grid in the map frame (None: the window was empty, the
    drone beyond the grid). A2 = A1 * P is only multiplied out when asked (``aggregates``, a
    viewer); A3 is the score the choice maximised, other drones' targets masked.
    """

    time: float
    placement: GridGeometry | None
    a0: np.ndarray
    a1: np.ndarray
    p: np.ndarray
    a3: np.ndarray

    @classmethod
    def of(cls, s: _Scores) -> "TickTerms":
        g, w = s.grid.geometry, s.window
        placement = None if w.empty else GridGeometry(g.origin_x + w.col0 * g.resolution,
                                                      g.origin_y + w.row0 * g.resolution, g.resolution,
                                                      w.col1 - w.col0, w.row1 - w.row0)
        return cls(float(s.time), placement, s.a0, s.a1, s.p, s.a3)

    def aggregates(self) -> dict[str, np.ndarray]:
        """A0 (weighted layers), A1 (x Z), A2 (x P), A3 (x H): arrays of the window's shape."""
        return {"A0": self.a0, "A1": self.a1, "A2": self.a1 * self.p, "A3": self.a3}


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
        self._widen: Callable[[GridWindow], FeatureLayers] | None = None
        self.last_tick: TickTerms | None = None  # the terms of the last decide or reconsider, for a viewer

    def decide(
        self,
        layers: FeatureLayers,
        position: Sequence[float],
        time: float,
        *,
        intermediates: bool = False,
        avoid: Sequence[Sequence[float]] = (),
        widen: Callable[[GridWindow], FeatureLayers] | None = None,
    ) -> Decision:
        """A decision tick: the next waypoint from ``position`` (map frame) at mission ``time``.

        ``avoid``: (x, y) points, e.g. other drones' targets; cells within r_e of them are not chosen.
        ``widen``: the layers on a bigger window, for ``layers`` computed on ``window(...)``
        alone: the "approach" fallback may head for a cell beyond r_i and explains it.
        """
        scores = self._evaluate(layers, position, time, tick=True, avoid=avoid)
        self.last_tick = TickTerms.of(scores)
        self._widen = widen
        try:
            decision = self._choose(scores, position, time, intermediates)
        finally:
            self._widen = None
        self._set_target(decision, scores, time)
        return decision

    def reconsider(
        self, layers: FeatureLayers, position: Sequence[float], time: float, *, avoid: Sequence[Sequence[float]] = ()
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
        self.last_tick = TickTerms.of(scores)
        best = self._pick(scores.a3, scores.window)
        if best is None:
            return None
        g = scores.grid.geometry
        row, col = g.cell_of(*self.target.waypoint[:2])
        current = 0.0
        if g.contains(row, col):  # the window holds the target's cell (see ``window``)
            current = float(np.float32(scores.at(scores.a1, (row, col))) * np.float32(scores.at(scores.h, (row, col))))
            current *= self._target_p
        bx, by = g.cell_center(*best)
        tx, ty = self.target.waypoint[:2]
        if scores.at(scores.a3, best) <= current * (1.0 + rt.margin) or np.hypot(bx - tx, by - ty) < rt.min_separation:
            return None
        decision = self._explain(scores, best, position, time, None, retargeted=True)
        self._set_target(decision, scores, time)
        return decision

    def window(self, geometry: GridGeometry, position: Sequence[float]) -> GridWindow:
        """The cells a tick at ``position`` computes: within r_i of it, plus the current target's cell.

        Compute the layers on it (``compute_layers(..., window=...)``) to pay for the
        drone's neighbourhood instead of the whole grid; the choice is the same.
        """
        win = GridWindow.around(geometry, float(position[0]), float(position[1]), self.behavior.r_i)
        if self.target is not None:
            win = win.union(GridWindow.around(geometry, *self.target.waypoint[:2], 0.0))
        return win

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
        self, layers: FeatureLayers, position: Sequence[float], time: float, tick: bool, avoid: Sequence[Sequence[float]],
        window: GridWindow | None = None,
    ) -> _Scores:
        if len(position) < 2 or not np.all(np.isfinite(np.asarray(position[:3], float))):
            raise ValueError(f"position: expected finite (x, y[, z]), got {position!r}")
        if not np.isfinite(time):
            raise ValueError(f"time: must be finite, got {time}")
        b = self.behavior
        grid = self._grid(layers.geometry)
        win = self.window(layers.geometry, position) if window is None else window
        covered = GridWindow.full(layers.geometry) if layers.window is None else layers.window
        if not covered.contains(win):
            raise ValueError(f"layers: computed on {covered}, but this tick needs {win} (DecisionMaker.window)")
        part = win.within(covered)
        coverage = float(np.count_nonzero(layers.observed & grid.inside)) / grid.zone_cells
        weights = self.schedule.weights(time, coverage)
        a0 = np.zeros(win.shape, np.float32)
        for name, w in weights.items():
            if w > 0:
                if name not in layers.layers:
                    raise ValueError(f"layers: behavior weights {name!r} but the layer set has only {layers.names}")
                a0 += np.float32(w) * layers.layers[name][part]
        a1 = a0 * grid.zone[win.slices]
        d = grid.distance(position[0], position[1], win)
        p = distance_preference(d, b.r_e, b.r_i)
        h = self.history.tick(layers.geometry, d, win) if tick else self.history.on(layers.geometry, win)
        a3 = a1 * p
        a3 *= h
        allowed = self._allowed(grid, avoid, win)
        if allowed is not None:
            a3 *= allowed
        return _Scores(layers, grid, win, position, time, avoid, weights, coverage, a0, a1, p, h, a3, allowed, d)

    def _allowed(self, grid: _Grid, avoid: Sequence[Sequence[float]], window: GridWindow) -> np.ndarray | None:
        """False within r_e of any ``avoid`` point (None when there are none)."""
        allowed = None
        for point in avoid:
            near = grid.distance(point[0], point[1], window) < self.behavior.r_e
            allowed = ~near if allowed is None else allowed & ~near
        return allowed

    def _pick(self, score: np.ndarray, window: GridWindow) -> tuple[int, int] | None:
        """Argmax of ``score`` (on ``window``) + seeded noise in [0, noise) on positive cells; None if no cell is > 0.

        Only cells within ``noise`` of the maximum can win, so noise is drawn for those
        alone: the same choice as noising every cell, at the cost of one comparison.
        Returns the grid's (row, col).
        """
        if score.size == 0:
            return None
        top = float(score.max())
        if not top > 0:
            return None
        noise = np.float32(self.behavior.noise)
        flat = np.flatnonzero(score >= max(top - noise, np.finfo(np.float32).tiny))
        if len(flat) > 1 and noise > 0:
            flat = flat[np.argmax(score.flat[flat] + noise * self.rng.random(len(flat), dtype=np.float32))]
        else:
            flat = flat[0]
        row, col = divmod(int(flat), score.shape[1])
        return row + window.row0, col + window.col0

    def _runner_up(self, scores: _Scores, best: tuple[int, int]) -> tuple[int, int] | None:
        """Best cell at least r_e (and one cell) from the winner: a genuinely different option."""
        g = scores.grid.geometry
        reach = max(self.behavior.r_e, g.resolution)
        k = int(np.ceil(reach / g.resolution))
        win = scores.window
        r0, r1 = max(best[0] - k, win.row0), min(best[0] + k + 1, win.row1)
        c0, c1 = max(best[1] - k, win.col0), min(best[1] + k + 1, win.col1)
        bx, by = g.cell_center(*best)
        dx = scores.grid.xs[:, c0:c1] - np.float32(bx)
        dy = scores.grid.ys[r0:r1] - np.float32(by)
        near = scores.a3[r0 - win.row0:r1 - win.row0, c0 - win.col0:c1 - win.col0]
        saved = near.copy()
        near[dx * dx + dy * dy < reach * reach] = 0.0
        try:
            return self._pick(scores.a3, win)
        finally:
            near[...] = saved

    def _choose(self, scores: _Scores, position: Sequence[float], time: float, intermediates: bool) -> Decision:
        best = self._pick(scores.a3, scores.window)
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
        grid, win = scores.grid, scores.window
        z = grid.zone[win.slices] if scores.allowed is None else grid.zone[win.slices] * scores.allowed
        cell = self._pick(z * scores.p * scores.h, win)
        if cell is not None:
            return cell, "wander"
        whole = GridWindow.full(grid.geometry)  # the area may lie beyond r_i: look at all of it
        allowed = self._allowed(grid, scores.avoid, whole)
        z = grid.zone if allowed is None else grid.zone * allowed
        if not z.any():
            z = grid.zone  # every area cell is near another drone's target: ignore that
        d = np.where(z > 0, grid.distance(scores.position[0], scores.position[1], whole), np.nan)
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
        if not scores.window.contains(GridWindow(cell[0], cell[0] + 1, cell[1], cell[1] + 1)):
            scores = self._widened(scores, cell, time)
        r, c = cell
        layers = scores.layers
        lr, lc = (r, c) if layers.window is None else (r - layers.window.row0, c - layers.window.col0)
        contributions = {k: float(np.float32(w) * layers.layers[k][lr, lc]) for k, w in scores.weights.items() if w > 0}
        images = self._images(scores, time) if intermediates else None
        runner_up = None
        if runner is not None:
            runner_up = Candidate(self._waypoint(scores, runner, position), runner, scores.at(scores.a3, runner))
        return Decision(
            time=float(time),
            waypoint=self._waypoint(scores, cell, position),
            cell=(int(r), int(c)),
            score=scores.at(scores.a3, cell),
            contributions=contributions,
            aggregate=scores.at(scores.a0, cell),
            zone=float(scores.grid.zone[r, c]),
            preference=scores.at(scores.p, cell),
            history=scores.at(scores.h, cell),
            weights=dict(scores.weights),
            coverage=scores.coverage,
            runner_up=runner_up,
            fallback=fallback,
            retargeted=retargeted,
            intermediates=images,
        )

    def _widened(self, scores: _Scores, cell: tuple[int, int], time: float) -> _Scores:
        """The terms again (H as ticked) on a window that reaches ``cell``, to explain a choice beyond r_i."""
        win = scores.window.union(GridWindow(cell[0], cell[0] + 1, cell[1], cell[1] + 1))
        layers = scores.layers
        if layers.window is not None and not layers.window.contains(win):
            if self._widen is None:
                raise ValueError(f"layers: computed on {layers.window}, but the choice {cell} lies outside it; "
                                 "pass widen= to decide")
            layers = self._widen(win)
        return self._evaluate(layers, scores.position, time, tick=False, avoid=scores.avoid, window=win)

    def _images(self, scores: _Scores, time: float) -> dict[str, np.ndarray]:
        """Every term on the whole grid, for pictures (the tick has already updated H)."""
        if scores.layers.window is not None:
            raise ValueError("intermediates: need layers of the whole grid (compute_layers without a window)")
        whole = self._evaluate(scores.layers, scores.position, time, tick=False, avoid=scores.avoid,
                               window=GridWindow.full(scores.grid.geometry))
        return {"A0": whole.a0, "A1": whole.a1, "A2": whole.a1 * whole.p, "A3": whole.a3,
                "Z": whole.grid.zone, "P": whole.p, "H": whole.h}

    def _set_target(self, decision: Decision, scores: _Scores, time: float) -> None:
        self.target = decision
        self._target_p = decision.preference
        self._switched_at = time
