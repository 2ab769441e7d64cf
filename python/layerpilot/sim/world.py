"""Procedural forest world from a seed: terrain, trees, clearings, ground truth.

Frame: map frame, ENU metres, z up; the world is the square
``[-size/2, size/2]^2`` centred on the origin (the launch point, kept clear of
trees). Everything is a deterministic function of ``WorldConfig``.

Ground truth:
  * ``World.terrain_height(x, y)`` -- the terrain surface exactly as meshed
    (each grid quad split along its south-west/north-east diagonal);
  * ``World.vertices``, ``World.triangles`` -- the whole mesh, the same one
    the renderer draws; ``World.materials`` gives each vertex's material;
  * ``World.surface_height(geometry)`` -- the top of the mesh (terrain or tree
    crown) above each grid cell centre, a vertical ray cast of the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from layerpilot.config import check_range
from layerpilot.grid import GridGeometry

GROUND, TRUNK, CONIFER, BROADLEAF = 0, 1, 2, 3


@dataclass(frozen=True)
class WorldConfig:
    """World size and content; all lengths in metres."""

    seed: int = 0
    size: float = 400.0
    terrain_resolution: float = 2.0
    hill_height: float = 30.0
    hill_wavelength: float = 160.0
    trees_per_hectare: float = 200.0
    conifer_fraction: float = 0.5
    tree_height_min: float = 8.0
    tree_height_max: float = 22.0
    clearings: int = 8
    clearing_radius_max: float = 35.0
    launch_clearing_radius: float = 20.0
    tile_size: float = 50.0
    ridge_height: float = 0.0  # m from valley floor to ridge crest added to the hills (0: none)
    ridge_wavelength: float = 250.0  # m between neighbouring ridges
    fields: int = 0  # open fields: treeless rotated rectangles, larger than clearings
    field_size_max: float = 120.0  # m, a field's longer side
    tall_stand_height: float = 0.0  # m: trees in the densest patches grow to this height (0: none)

    def __post_init__(self) -> None:
        check_range("size", self.size, 20.0, 5000.0)
        check_range("terrain_resolution", self.terrain_resolution, 0.25, self.size / 4)
        check_range("hill_height", self.hill_height, 0.0, 500.0)
        check_range("hill_wavelength", self.hill_wavelength, 10.0, 10000.0)
        check_range("trees_per_hectare", self.trees_per_hectare, 0.0, 2000.0)
        check_range("conifer_fraction", self.conifer_fraction, 0.0, 1.0)
        check_range("tree_height_min", self.tree_height_min, 1.0, 100.0)
        check_range("tree_height_max", self.tree_height_max, self.tree_height_min, 100.0)
        check_range("clearings", self.clearings, 0, 1000)
        check_range("clearing_radius_max", self.clearing_radius_max, 0.0, self.size)
        check_range("launch_clearing_radius", self.launch_clearing_radius, 0.0, self.size)
        check_range("tile_size", self.tile_size, 5.0, self.size)
        check_range("ridge_height", self.ridge_height, 0.0, 1000.0)
        check_range("ridge_wavelength", self.ridge_wavelength, 20.0, 10000.0)
        check_range("fields", self.fields, 0, 100)
        check_range("field_size_max", self.field_size_max, 10.0, self.size if self.fields else None)
        check_range("tall_stand_height", self.tall_stand_height, 0.0, 100.0)
        if self.tall_stand_height and self.tall_stand_height < self.tree_height_max:
            raise ValueError(f"tall_stand_height = {self.tall_stand_height} must be 0 or >= tree_height_max "
                             f"= {self.tree_height_max}")


@dataclass(frozen=True)
class Trees:
    """One row per tree: position of the trunk foot, height, crown radius, kind."""

    x: np.ndarray
    y: np.ndarray
    ground: np.ndarray
    height: np.ndarray
    crown_radius: np.ndarray
    kind: np.ndarray  # CONIFER or BROADLEAF

    def __len__(self) -> int:
        return len(self.x)


def _value_noise(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, cell: float, extent: float) -> np.ndarray:
    """Smooth 2D value noise in [-1, 1] with lattice spacing ``cell`` over ``[-extent, extent]^2``."""
    n = int(np.ceil(2 * extent / cell)) + 3
    lattice = rng.uniform(-1.0, 1.0, size=(n, n))
    u = (x + extent) / cell
    v = (y + extent) / cell
    i = np.clip(np.floor(u).astype(int), 0, n - 2)
    j = np.clip(np.floor(v).astype(int), 0, n - 2)
    fu = u - i
    fv = v - j
    su = fu * fu * (3 - 2 * fu)
    sv = fv * fv * (3 - 2 * fv)
    a = lattice[j, i] * (1 - su) + lattice[j, i + 1] * su
    b = lattice[j + 1, i] * (1 - su) + lattice[j + 1, i + 1] * su
    return a * (1 - sv) + b * sv


class World:
    """The procedural forest; build with ``World(WorldConfig(seed=...))``."""

    def __init__(self, config: WorldConfig | None = None) -> None:
        self.config = config or WorldConfig()
        c = self.config
        rng = np.random.default_rng(c.seed)
        self.half = c.size / 2
        n = int(round(c.size / c.terrain_resolution))
        self.terrain_res = c.size / n
        axis = -self.half + np.arange(n + 1) * self.terrain_res
        gx, gy = np.meshgrid(axis, axis)
        # The harder worlds' options draw from a generator of their own: a seed's hills, clearings and tree
        # places do not depend on them.
        extra = np.random.default_rng([c.seed, 1])
        self.heightfield = (self._hills(rng, gx, gy) + self._ridges(extra, gx, gy)).astype(np.float64)  # row = y
        self.clearings = self._clearings(rng)
        self.fields = self._fields(extra)
        self.trees = self._place_trees(rng, extra)
        self._build_mesh(gx, gy, rng)

    # --- terrain -----------------------------------------------------------------
    def _hills(self, rng: np.random.Generator, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        c = self.config
        extent = self.half + c.hill_wavelength
        h = np.zeros_like(x)
        for octave, amp in enumerate((1.0, 0.45, 0.2)):
            h += amp * _value_noise(rng, x, y, c.hill_wavelength / 2 ** octave, extent)
        return 0.5 * c.hill_height * h

    def _ridges(self, rng: np.random.Generator, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ridged noise: sharp crests and round valleys ``ridge_height`` apart, zero at the launch point."""
        c = self.config
        if not c.ridge_height:
            return np.zeros_like(x)
        px, py = np.append(np.ravel(x), 0.0), np.append(np.ravel(y), 0.0)  # the launch point last
        crest = (1.0 - np.abs(_value_noise(rng, px, py, c.ridge_wavelength, self.half + c.ridge_wavelength))) ** 2
        return c.ridge_height * (crest[:-1] - crest[-1]).reshape(np.shape(x))

    def terrain_height(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Exact meshed terrain height at (x, y); points outside the world are clamped to its edge."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        n = self.heightfield.shape[0] - 1
        u = np.clip((x + self.half) / self.terrain_res, 0, n)
        v = np.clip((y + self.half) / self.terrain_res, 0, n)
        i = np.minimum(np.floor(u).astype(int), n - 1)
        j = np.minimum(np.floor(v).astype(int), n - 1)
        fx, fy = u - i, v - j
        h = self.heightfield
        z00, z10, z01, z11 = h[j, i], h[j, i + 1], h[j + 1, i], h[j + 1, i + 1]
        lower = z00 + fx * (z10 - z00) + fy * (z11 - z10)  # triangle (00, 10, 11)
        upper = z00 + fy * (z01 - z00) + fx * (z11 - z01)  # triangle (00, 11, 01)
        return np.where(fx >= fy, lower, upper)

    # --- trees -------------------------------------------------------------------
    def _clearings(self, rng: np.random.Generator) -> np.ndarray:
        """(K, 3) array of clearing circles (x, y, radius); the first is the launch clearing."""
        c = self.config
        centres = rng.uniform(-self.half, self.half, size=(c.clearings, 2))
        radii = rng.uniform(0.4, 1.0, size=c.clearings) * c.clearing_radius_max
        launch = np.array([[0.0, 0.0, c.launch_clearing_radius]])
        return np.vstack([launch, np.column_stack([centres, radii])])

    def _fields(self, rng: np.random.Generator) -> np.ndarray:
        """(F, 5) open fields: centre x, y, half length, half width, heading (rad); none touch the launch point."""
        c = self.config
        rows = []
        while len(rows) < c.fields:
            half_l = rng.uniform(0.5, 1.0) * c.field_size_max / 2
            half_w = rng.uniform(0.3, 0.7) * half_l
            centre = rng.uniform(-self.half + half_w, self.half - half_w, size=2)
            if np.hypot(*centre) > half_l + c.launch_clearing_radius:
                rows.append((*centre, half_l, half_w, rng.uniform(0, np.pi)))
        return np.array(rows, np.float64).reshape(-1, 5)

    def in_field(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """True where (x, y) lies in an open field."""
        inside = np.zeros(np.shape(x), bool)
        for fx, fy, half_l, half_w, heading in self.fields:
            ca, sa = np.cos(heading), np.sin(heading)
            along, across = (x - fx) * ca + (y - fy) * sa, -(x - fx) * sa + (y - fy) * ca
            inside |= (np.abs(along) <= half_l) & (np.abs(across) <= half_w)
        return inside

    def _place_trees(self, rng: np.random.Generator, extra: np.random.Generator) -> Trees:
        c = self.config
        count = int(round(c.trees_per_hectare * c.size * c.size / 1e4))
        cand = rng.uniform(-self.half + 2, self.half - 2, size=(4 * count + 16, 2))
        # Patchy stand density: trees are likelier where low-frequency noise is high.
        patch = _value_noise(rng, cand[:, 0], cand[:, 1], 60.0, self.half + 60)
        keep = rng.uniform(size=len(cand)) < 0.35 + 0.65 * (patch + 1) / 2
        d = np.linalg.norm(cand[:, None, :] - self.clearings[None, :, :2], axis=2)
        keep &= np.all(d > self.clearings[None, :, 2], axis=1)
        keep &= ~self.in_field(cand[:, 0], cand[:, 1])
        dense = patch[keep][:count] > 0.35  # the densest patches: tall stands, when asked for
        cand = cand[keep][:count]
        m = len(cand)
        kind = np.where(rng.uniform(size=m) < c.conifer_fraction, CONIFER, BROADLEAF)
        height = rng.uniform(c.tree_height_min, c.tree_height_max, size=m)
        if c.tall_stand_height:
            tall = extra.uniform(c.tree_height_max, c.tall_stand_height, size=m)
            height = np.where(dense, tall, height)
        crown = np.where(kind == CONIFER, 0.22, 0.3) * height * rng.uniform(0.8, 1.2, size=m)
        return Trees(cand[:, 0], cand[:, 1], self.terrain_height(cand[:, 0], cand[:, 1]), height, crown, kind)

    # --- mesh --------------------------------------------------------------------
    def _build_mesh(self, gx: np.ndarray, gy: np.ndarray, rng: np.random.Generator) -> None:
        n = gx.shape[0] - 1
        verts = [np.column_stack([gx.ravel(), gy.ravel(), self.heightfield.ravel()])]
        idx = np.arange((n + 1) * (n + 1)).reshape(n + 1, n + 1)
        v00, v10, v01, v11 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
        tris = [np.concatenate([np.column_stack([v00, v10, v11]), np.column_stack([v00, v11, v01])])]
        mats = [np.full(len(verts[0]), GROUND, dtype=np.float32)]
        tints = [np.zeros(len(verts[0]), dtype=np.float32)]
        base = len(verts[0])
        t = self.trees
        tint = rng.uniform(size=len(t)).astype(np.float32)
        yaw = rng.uniform(0, 2 * np.pi, size=len(t))
        for kind in (CONIFER, BROADLEAF):
            sel = np.flatnonzero(t.kind == kind)
            if len(sel) == 0:
                continue
            for mat, (tv, tt, scale, offset) in zip((TRUNK, kind), _tree_parts(kind, t, sel)):
                k = len(sel)
                c, s = np.cos(yaw[sel]), np.sin(yaw[sel])
                px = tv[None, :, 0] * scale[:, None, 0]
                py = tv[None, :, 1] * scale[:, None, 1]
                pz = tv[None, :, 2] * scale[:, None, 2] + offset[:, None]
                xs = c[:, None] * px - s[:, None] * py + t.x[sel, None]
                ys = s[:, None] * px + c[:, None] * py + t.y[sel, None]
                verts.append(np.stack([xs, ys, pz], axis=2).reshape(-1, 3))
                tris.append((tt[None, :, :] + base + len(tv) * np.arange(k)[:, None, None]).reshape(-1, 3))
                mats.append(np.full(k * len(tv), mat, dtype=np.float32))
                tints.append(np.repeat(tint[sel], len(tv)))
                base += k * len(tv)
        self.vertices = np.concatenate(verts).astype(np.float32)
        self.materials = np.concatenate(mats)
        self.tints = np.concatenate(tints)
        triangles = np.concatenate(tris).astype(np.int32)
        self._tile(triangles)

    def _tile(self, triangles: np.ndarray) -> None:
        """Sort triangles by square tile of their centroid; keep each tile's range and bounding box."""
        ts = self.config.tile_size
        nt = int(np.ceil(self.config.size / ts))
        cen = self.vertices[triangles].mean(axis=1)
        ti = np.clip(((cen[:, 0] + self.half) // ts).astype(int), 0, nt - 1)
        tj = np.clip(((cen[:, 1] + self.half) // ts).astype(int), 0, nt - 1)
        tile = tj * nt + ti
        order = np.argsort(tile, kind="stable")
        self.triangles = triangles[order]
        tile = tile[order]
        counts = np.bincount(tile, minlength=nt * nt)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        used = np.flatnonzero(counts)
        self.tile_ranges = np.column_stack([starts[used], counts[used]])  # in triangles
        tv = self.vertices[self.triangles]
        self.tile_boxes = np.array([
            np.concatenate([tv[s:s + k].reshape(-1, 3).min(axis=0), tv[s:s + k].reshape(-1, 3).max(axis=0)])
            for s, k in self.tile_ranges])  # (tiles, 6): min xyz, max xyz

    # --- ground truth ------------------------------------------------------------
    def surface_height(self, geometry: GridGeometry) -> np.ndarray:
        """Height of the topmost mesh surface above every cell centre, float32 (height, width).

        Terrain comes from the exact terrain interpolation; trees by casting a
        vertical ray through every cell centre against their triangles.
        """
        cx, cy = geometry.cell_centers()
        top = self.terrain_height(cx, cy)
        tri = self.triangles[self.materials[self.triangles[:, 0]] != GROUND]
        p = self.vertices[tri].astype(np.float64)  # (T, 3, 3)
        a, b, c = p[:, 0], p[:, 1], p[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        ok = np.abs(det) > 1e-9  # vertical faces have no area seen from above
        a, b, c, det = a[ok], b[ok], c[ok], det[ok]
        r = geometry.resolution
        lo = np.minimum(np.minimum(a, b), c)
        hi = np.maximum(np.maximum(a, b), c)
        i0 = np.ceil((lo[:, 0] - geometry.origin_x) / r - 0.5).astype(int)
        i1 = np.floor((hi[:, 0] - geometry.origin_x) / r - 0.5).astype(int)
        j0 = np.ceil((lo[:, 1] - geometry.origin_y) / r - 0.5).astype(int)
        j1 = np.floor((hi[:, 1] - geometry.origin_y) / r - 0.5).astype(int)
        i0, j0 = np.maximum(i0, 0), np.maximum(j0, 0)
        i1, j1 = np.minimum(i1, geometry.width - 1), np.minimum(j1, geometry.height - 1)
        ni, nj = np.maximum(i1 - i0 + 1, 0), np.maximum(j1 - j0 + 1, 0)
        cells = ni * nj
        t = np.repeat(np.arange(len(a)), cells)
        k = np.arange(cells.sum()) - np.repeat(np.cumsum(cells) - cells, cells)
        ci = i0[t] + k % ni[t]
        cj = j0[t] + k // ni[t]
        x = geometry.origin_x + (ci + 0.5) * r
        y = geometry.origin_y + (cj + 0.5) * r
        ax, ay = a[t, 0], a[t, 1]
        w1 = ((x - ax) * (c[t, 1] - ay) - (c[t, 0] - ax) * (y - ay)) / det[t]
        w2 = ((b[t, 0] - ax) * (y - ay) - (x - ax) * (b[t, 1] - ay)) / det[t]
        inside = (w1 >= 0) & (w2 >= 0) & (w1 + w2 <= 1)
        z = a[t, 2] + w1 * (b[t, 2] - a[t, 2]) + w2 * (c[t, 2] - a[t, 2])
        flat = top.ravel()
        np.maximum.at(flat, cj[inside] * geometry.width + ci[inside], z[inside])
        return flat.reshape(geometry.shape).astype(np.float32)

    def stats(self) -> dict:
        return {
            "size_m": self.config.size,
            "trees": len(self.trees),
            "conifers": int(np.sum(self.trees.kind == CONIFER)),
            "triangles": len(self.triangles),
            "vertices": len(self.vertices),
            "tiles": len(self.tile_ranges),
            "terrain_min_m": float(self.heightfield.min()),
            "terrain_max_m": float(self.heightfield.max()),
        }


def _icosphere() -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere, one subdivision (42 vertices, 80 triangles), tilted so that no face is vertical.

    (The upright icosahedron has vertical faces at its equator; a vertical face
    has no well-defined column top, which the ground truth would have to special-case.)
    """
    g = (1 + 5 ** 0.5) / 2
    v = [(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g), (0, 1, -g),
         (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    mid: dict[tuple[int, int], int] = {}

    def midpoint(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in mid:
            m = verts[a] + verts[b]
            verts.append(m / np.linalg.norm(m))
            mid[key] = len(verts) - 1
        return mid[key]

    faces = []
    for a, b, c in f:
        ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
        faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    a = 0.55  # tilt about x chosen so every face normal has |n_z| >= 0.12
    tilt = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return np.array(verts) @ tilt.T, np.array(faces)


def _prism(sides: int) -> tuple[np.ndarray, np.ndarray]:
    """Open unit prism (radius 1, z from 0 to 1): the trunk."""
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.column_stack([np.cos(ang), np.sin(ang)])
    v = np.vstack([np.column_stack([ring, np.zeros(sides)]), np.column_stack([ring, np.ones(sides)])])
    i = np.arange(sides)
    j = (i + 1) % sides
    f = np.vstack([np.column_stack([i, j, j + sides]), np.column_stack([i, j + sides, i + sides])])
    return v, f


def _cone(sides: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed unit cone (base radius 1 at z=0, apex at z=1): the conifer crown."""
    ang = 2 * np.pi * np.arange(sides) / sides
    v = np.vstack([np.column_stack([np.cos(ang), np.sin(ang), np.zeros(sides)]), [[0, 0, 1], [0, 0, 0]]])
    i = np.arange(sides)
    j = (i + 1) % sides
    f = np.vstack([np.column_stack([i, j, np.full(sides, sides)]), np.column_stack([j, i, np.full(sides, sides + 1)])])
    return v, f


_TRUNK = _prism(5)
_CONE = _cone(7)
_SPHERE = _icosphere()


def _tree_parts(kind: int, t: Trees, sel: np.ndarray):
    """(template verts, template faces, per-tree xyz scale, per-tree z offset) for trunk and crown."""
    h, r = t.height[sel], t.crown_radius[sel]
    foot = t.ground[sel] - 0.5  # trunks start below ground so slopes leave no gap
    trunk_r = 0.04 * h
    if kind == CONIFER:
        crown_base = 0.25 * h
        trunk = (*_TRUNK, np.column_stack([trunk_r, trunk_r, crown_base + 1.0]), foot)
        crown = (*_CONE, np.column_stack([r, r, 0.75 * h]), t.ground[sel] + crown_base)
    else:
        centre = 0.62 * h
        trunk = (*_TRUNK, np.column_stack([trunk_r, trunk_r, centre + 0.5]), foot)
        crown = (*_SPHERE, np.column_stack([r, r, 0.38 * h]), t.ground[sel] + centre)
    return trunk, crown
