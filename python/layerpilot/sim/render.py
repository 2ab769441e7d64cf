"""Headless OpenGL renderer of the world: a ``CameraFrame`` with ground-truth depth for a camera pose.

API (for the depth estimator and the simulator)::

    from layerpilot.camera import CameraConfig, camera_pose
    from layerpilot.sim import World, WorldConfig, Renderer
    world = World(WorldConfig(seed=1))
    with Renderer(world, CameraConfig()) as r:          # 640x480, 90 deg HFOV, pitch 60 deg down
        pose = camera_pose((0, 0, 30), yaw=0.0, pitch_deg=r.camera.pitch_deg)
        frame = r.render(pose, stamp=0.0)               # or r.render_vehicle((0, 0, 30), yaw=0.0)
    frame.image       # uint8 (H, W, 3) RGB, row 0 = top of the image
    frame.depth       # float32 (H, W) z-depth in metres: distance along the optical axis
                      # (camera-frame z, not the ray length), +inf where the pixel sees sky
    frame.intrinsics  # CameraIntrinsics (pixel centres at integer coordinates)
    frame.pose        # Pose camera -> map (OpenCV camera axes)

A pixel (u, v) with depth d is the map point ``pose.position + pose.rotation @
(d * inv(K) @ [u, v, 1])``. See ``layerpilot.geometry`` for the frame conventions.

The OpenGL context is a moderngl standalone context on EGL: Mesa's llvmpipe
software rasterizer without a GPU, the GPU driver when there is one. The world's
tiles outside the view frustum are skipped. Texture is procedural 3D value noise
of the world position, evaluated per fragment with octaves faded out below the
pixel footprint, so it is sharp close up, free of aliasing far away, and the same
surface point has the same colour from every viewpoint (what stereo matching needs).
"""

from __future__ import annotations

import os

import numpy as np

from layerpilot.geometry import CameraFrame, CameraIntrinsics, Pose
from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.sim.world import World

SKY_RGB = (160, 196, 235)

_VERTEX = """
#version 330
uniform mat4 mvp;
uniform vec4 view_z;
in vec3 in_pos;
in float in_mat;
out vec3 v_pos;
out float v_z;
flat out float v_mat;
void main() {
    v_pos = in_pos;
    v_z = dot(view_z, vec4(in_pos, 1.0));
    v_mat = in_mat;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""

_FRAGMENT = """
#version 330
uniform vec3 eye;
in vec3 v_pos;
in float v_z;
flat in float v_mat;
layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_depth;

float hash(ivec3 q) {
    uvec3 p = uvec3(q);
    uint h = p.x * 73856093u ^ p.y * 19349663u ^ p.z * 83492791u;
    h ^= h >> 13; h *= 0x5bd1e995u; h ^= h >> 15;
    return float(h & 0xffffffu) / 16777215.0;
}

float vnoise(vec3 p) {  // trilinear value noise in [0, 1]
    ivec3 i = ivec3(floor(p));
    vec3 f = fract(p);
    f = f * f * (3.0 - 2.0 * f);
    float a = mix(hash(i), hash(i + ivec3(1, 0, 0)), f.x);
    float b = mix(hash(i + ivec3(0, 1, 0)), hash(i + ivec3(1, 1, 0)), f.x);
    float c = mix(hash(i + ivec3(0, 0, 1)), hash(i + ivec3(1, 0, 1)), f.x);
    float d = mix(hash(i + ivec3(0, 1, 1)), hash(i + ivec3(1, 1, 1)), f.x);
    return mix(mix(a, b, f.y), mix(c, d, f.y), f.z);
}

// Octaves from base_freq (cycles per metre) upward, each faded out once it
// gets finer than about a third of the pixel footprint fw (metres).
float fbm(vec3 p, float base_freq, float fw) {
    float s = 0.0, amp = 0.5, freq = base_freq;
    for (int k = 0; k < 7; k++) {
        float fade = clamp((0.6 - fw * freq) * 4.0, 0.0, 1.0);
        if (fade <= 0.0) break;
        s += amp * fade * (vnoise(p * freq + float(k) * 17.3) - 0.5);
        freq *= 2.0;
        amp *= 0.8;
    }
    return s;
}

void main() {
    vec3 dx = dFdx(v_pos), dy = dFdy(v_pos);
    vec3 n = normalize(cross(dx, dy));
    if (dot(n, eye - v_pos) < 0.0) n = -n;
    float fw = max(length(dx), length(dy));
    int mat = int(floor(v_mat));
    float tint = fract(v_mat) / 0.9;
    vec3 base;
    float detail;
    if (mat == 0) {          // ground: grass and dirt patches
        float patch = vnoise(v_pos * 0.05) + 0.35 * vnoise(v_pos * 0.21);
        float dirt = smoothstep(0.75, 0.95, patch);
        base = mix(vec3(0.30, 0.46, 0.16), vec3(0.47, 0.37, 0.24), dirt);
        detail = fbm(v_pos, 0.5, fw);
    } else if (mat == 1) {   // bark
        base = vec3(0.36, 0.26, 0.17);
        detail = fbm(v_pos * vec3(1.0, 1.0, 0.25), 2.0, fw);
    } else if (mat == 2) {   // conifer needles
        base = mix(vec3(0.09, 0.27, 0.12), vec3(0.15, 0.33, 0.13), tint);
        detail = fbm(v_pos, 1.0, fw);
    } else {                 // broadleaf foliage
        base = mix(vec3(0.22, 0.42, 0.12), vec3(0.38, 0.50, 0.15), tint);
        detail = fbm(v_pos, 1.0, fw);
    }
    float hue = vnoise(v_pos * 0.9 + 31.0) - 0.5;
    vec3 albedo = base * (1.0 + 2.0 * detail) + vec3(0.06, 0.03, -0.02) * hue;
    const vec3 sun = normalize(vec3(0.4, 0.3, 0.85));
    float light = 0.45 + 0.75 * max(dot(n, sun), 0.0);
    f_color = vec4(clamp(albedo * light, 0.0, 1.0), 1.0);
    f_depth = v_z;
}
"""


def _configure_llvmpipe() -> None:
    """Let llvmpipe use every core (it reads this when the driver loads); the user's setting wins."""
    os.environ.setdefault("LP_NUM_THREADS", str(os.cpu_count() or 1))


def create_context():
    """A headless OpenGL 3.3+ context on EGL (GPU if present, else Mesa llvmpipe)."""
    import moderngl

    _configure_llvmpipe()
    try:
        return moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:  # moderngl raises plain Exception when EGL is unusable
        raise RuntimeError(
            f"cannot create a headless OpenGL context through EGL ({exc}); "
            "install Debian packages libegl1 libegl-mesa0 libgl1-mesa-dri") from exc


def projection(intrinsics: CameraIntrinsics, near: float, far: float) -> np.ndarray:
    """4x4 OpenGL clip matrix for OpenCV camera coordinates; image row 0 lands in framebuffer row 0."""
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    width, height = intrinsics.size
    return np.array([
        [2 * fx / width, 0, 2 * (cx + 0.5) / width - 1, 0],
        [0, 2 * fy / height, 2 * (cy + 0.5) / height - 1, 0],
        [0, 0, (far + near) / (far - near), -2 * far * near / (far - near)],
        [0, 0, 1, 0],
    ])


class Renderer:
    """Draws one world from one camera model; reuse it for every frame (the context is costly to make)."""

    def __init__(self, world: World, camera: CameraConfig | None = None, cull: bool = True) -> None:
        import moderngl

        self.world = world
        self.camera = camera or CameraConfig()
        self.cull = cull  # False draws every tile (the reference for `layerpilot bench sim`)
        self.intrinsics = self.camera.intrinsics
        c = self.camera
        self.ctx = create_context()
        self.renderer_name = self.ctx.info["GL_RENDERER"]
        self._prog = self.ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        attrs = np.empty(len(world.vertices), dtype=[("pos", "f4", 3), ("mat", "f4")])
        attrs["pos"] = world.vertices
        attrs["mat"] = world.materials + 0.9 * world.tints
        self._vbo = self.ctx.buffer(attrs.tobytes())
        self._ibo = self.ctx.buffer(world.triangles.astype("u4").tobytes())
        self._vao = self.ctx.vertex_array(self._prog, [(self._vbo, "3f 1f", "in_pos", "in_mat")],
                                          index_buffer=self._ibo, index_element_size=4)
        self._fbo = self.ctx.framebuffer(
            color_attachments=[self.ctx.renderbuffer((c.width, c.height), 4),
                               self.ctx.renderbuffer((c.width, c.height), 1, dtype="f4")],
            depth_attachment=self.ctx.depth_renderbuffer((c.width, c.height)))
        self._proj = projection(self.intrinsics, c.near, c.far)
        self._moderngl = moderngl
        self.last_tiles_drawn = 0

    def render_vehicle(self, position, yaw: float, stamp: float = 0.0) -> CameraFrame:
        """Render from the camera mounted on a vehicle at ``position`` (ENU) with ENU ``yaw``."""
        return self.render(camera_pose(position, yaw, self.camera.pitch_deg), stamp)

    def render(self, pose: Pose, stamp: float = 0.0) -> CameraFrame:
        """Colour and z-depth seen from ``pose`` (camera -> map), stamped ``stamp`` (mission seconds)."""
        if not isinstance(pose, Pose):
            raise ValueError(f"pose: expected a layerpilot.geometry.Pose, got {type(pose).__name__}")
        R, C = pose.rotation, pose.position
        view = np.eye(4)
        view[:3, :3] = R.T
        view[:3, 3] = -R.T @ C
        self._prog["mvp"].write((self._proj @ view).T.astype("f4").tobytes())
        self._prog["view_z"].value = tuple(view[2])
        self._prog["eye"].value = tuple(C)
        ctx = self.ctx
        self._fbo.use()
        ctx.enable(self._moderngl.DEPTH_TEST)
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        visible = self._visible_tiles(view) if self.cull else np.ones(len(self.world.tile_ranges), bool)
        self.last_tiles_drawn = int(visible.sum())
        for start, count in self.world.tile_ranges[visible]:
            self._vao.render(self._moderngl.TRIANGLES, vertices=int(count) * 3, first=int(start) * 3)
        w, h = self.camera.width, self.camera.height
        rgba = np.frombuffer(self._fbo.read(components=4, attachment=0), np.uint8).reshape(h, w, 4)
        depth = np.frombuffer(self._fbo.read(components=1, attachment=1, dtype="f4"), np.float32).reshape(h, w)
        sky = rgba[:, :, 3] == 0
        color = rgba[:, :, :3].copy()
        color[sky] = SKY_RGB
        depth = np.where(sky, np.float32(np.inf), depth)
        return CameraFrame(color, pose, self.intrinsics, stamp, depth)

    def _visible_tiles(self, view: np.ndarray) -> np.ndarray:
        """Tiles whose bounding box is not entirely outside one frustum plane."""
        b = self.world.tile_boxes
        corners = np.stack([b[:, [0 + 3 * ix, 1 + 3 * iy, 2 + 3 * iz]]
                            for ix in (0, 1) for iy in (0, 1) for iz in (0, 1)], axis=1)  # (T, 8, 3)
        p = corners @ view[:3, :3].T + view[:3, 3]
        x, y, z = p[..., 0], p[..., 1], p[..., 2]
        k = self.intrinsics
        fx, fy, cx, cy = k.fx, k.fy, k.cx, k.cy
        w, h = self.camera.width, self.camera.height
        planes = [z - self.camera.near, self.camera.far - z,
                  fx * x + (cx + 0.5) * z, (w - 0.5 - cx) * z - fx * x,
                  fy * y + (cy + 0.5) * z, (h - 0.5 - cy) * z - fy * y]
        outside = np.zeros(len(b), dtype=bool)
        for d in planes:
            outside |= np.all(d < 0, axis=1)
        return ~outside

    def close(self) -> None:
        for obj in (self._vao, self._fbo, self._vbo, self._ibo, self._prog):
            obj.release()
        self.ctx.release()

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
