"""The preview pass: meshes rasterised to depth (optionally flat-shaded), then debug lines depth-tested on them.

Aberration boxes (12 edges) and portal quads (4 edges) are drawn in their
own colour where ``debug_draw`` is on, the selection in white, the scene
camera as a small frustum. Lines are drawn straight in undeformed space:
they show where an entity *is*, whatever the tracer makes it look like.
Over a traced frame only the lines are visible (the meshes write depth
only); in "raster" mode the meshes are flat-shaded too, which is fast
enough to use while dragging when the tracer is not.

:func:`preview_lines` and :func:`thick_lines` are plain NumPy (tested
without a GL context); :class:`PreviewRenderer` does the GL work.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from components import Aberration, Camera, Mesh, Portal, Transform
from editor.view import perspective, view_matrix
from engine.camera_view import CameraView
from engine.errors import AberrantError
from engine.maths import trs_matrix
from engine.scene import Scene

if TYPE_CHECKING:
    import moderngl

#: Line width in pixels.
LINE_WIDTH = 2.0
SELECTION_COLOR = (1.0, 1.0, 1.0)
CAMERA_COLOR = (0.85, 0.85, 0.85)
#: Inert portals (no target) are drawn at this fraction of their colour.
INERT_DIM = 0.45

_BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
_QUAD_CORNERS = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])


def _edges(corners: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    return np.array([[corners[a], corners[b]] for a, b in pairs])


def _placed(transform: Transform, local: np.ndarray) -> np.ndarray:
    m = trs_matrix(transform.position, transform.rotation, transform.scale)
    return local @ m[:3, :3].T + m[:3, 3]


def box_edges(transform: Transform, lo: np.ndarray | None = None, hi: np.ndarray | None = None) -> np.ndarray:
    """The 12 world edges (12, 2, 3) of the unit box, or of the local box ``[lo, hi]``, placed by ``transform``."""
    corners = _BOX_CORNERS
    if lo is not None and hi is not None:
        corners = (corners + 0.5) * (hi - lo) + lo
    return _placed(transform, _edges(corners, _BOX_EDGES).reshape(-1, 3)).reshape(-1, 2, 3)


def quad_edges(transform: Transform) -> np.ndarray:
    """The 4 world edges (4, 2, 3) of a portal quad."""
    pairs = [(0, 1), (1, 2), (2, 3), (3, 0)]
    return _placed(transform, _edges(_QUAD_CORNERS, pairs).reshape(-1, 3)).reshape(-1, 2, 3)


def camera_edges(transform: Transform, camera: Camera, aspect: float = 4 / 3, depth: float = 0.6) -> np.ndarray:
    """A small frustum (8 edges) showing where the scene camera stands and looks."""
    t = math.tan(math.radians(camera.fov_deg) / 2.0) * depth
    far = np.array(
        [[-aspect * t, -t, -depth], [aspect * t, -t, -depth], [aspect * t, t, -depth], [-aspect * t, t, -depth]]
    )
    pts = np.vstack([np.zeros((1, 3)), far])
    pairs = [(0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1)]
    rigid = Transform(transform.position, transform.rotation)
    return _placed(rigid, _edges(pts, pairs).reshape(-1, 3)).reshape(-1, 2, 3)


def preview_lines(
    scene: Scene, selected: int | None = None, *, show_camera: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """World segments ``(N, 2, 3)`` and their colours ``(N, 3)`` for the debug overlay."""
    segments: list[np.ndarray] = []
    colors: list[np.ndarray] = []

    def add(edges: np.ndarray, color: tuple[float, float, float]) -> None:
        segments.append(edges)
        colors.append(np.tile(np.asarray(color, dtype=np.float64), (len(edges), 1)))

    for entity, (transform, aberration) in scene.query(Transform, Aberration):
        if aberration.debug_draw and entity != selected:
            add(box_edges(transform), aberration.color)
    for entity, (transform, portal) in scene.query(Transform, Portal):
        if portal.debug_draw and entity != selected:
            dim = 1.0 if portal.target is not None else INERT_DIM
            add(quad_edges(transform), tuple(c * dim for c in portal.color))
    camera = scene.camera_entity
    if show_camera and camera is not None and camera != selected:
        add(camera_edges(scene.get(camera, Transform), scene.get(camera, Camera)), CAMERA_COLOR)
    if selected is not None:
        segments.extend(selection_edges(scene, selected))
        colors.extend(np.tile(SELECTION_COLOR, (len(e), 1)) for e in segments[len(colors) :])
    if not segments:
        return np.zeros((0, 2, 3)), np.zeros((0, 3))
    return np.concatenate(segments), np.concatenate(colors)


def selection_edges(scene: Scene, entity: int) -> list[np.ndarray]:
    """The outline of the selected entity: its box, quad, frustum or mesh bounds."""
    transform = scene.try_get(entity, Transform)
    if transform is None:
        return []
    out = []
    if scene.has(entity, Aberration):
        out.append(box_edges(transform))
    if scene.has(entity, Portal):
        out.append(quad_edges(transform))
    camera = scene.try_get(entity, Camera)
    if camera is not None:
        out.append(camera_edges(transform, camera))
    mesh = scene.try_get(entity, Mesh)
    if mesh is not None:
        try:
            lo, hi = scene.asset(mesh.asset).bounds()
        except AberrantError:
            return out
        pad = 0.01 * np.maximum(hi - lo, 1e-3)
        out.append(box_edges(transform, lo.astype(np.float64) - pad, hi.astype(np.float64) + pad))
    return out


def thick_lines(
    segments: np.ndarray, colors: np.ndarray, view_proj: np.ndarray, size: tuple[int, int], width: float = LINE_WIDTH
) -> np.ndarray:
    """Screen-space quads for the segments: ``(6 * N, 7)`` float32 rows of clip position and colour.

    Each segment is clipped against the near plane first (the view is often
    inside an aberration box), then widened by ``width`` pixels on screen.
    """
    if len(segments) == 0:
        return np.zeros((0, 7), np.float32)
    ones = np.ones((len(segments), 2, 1))
    clip = np.concatenate([segments, ones], axis=2) @ view_proj.T  # (N, 2, 4)
    d = clip[:, :, 2] + clip[:, :, 3]  # >= 0 in front of the near plane
    keep = (d[:, 0] > 0) | (d[:, 1] > 0)
    clip, d, colors = clip[keep], d[keep], colors[keep]
    for a, b in ((0, 1), (1, 0)):
        behind = d[:, a] <= 0
        t = d[behind, a] / (d[behind, a] - d[behind, b])
        clip[behind, a] = clip[behind, a] + t[:, None] * (clip[behind, b] - clip[behind, a])
    w = np.maximum(clip[:, :, 3], 1e-9)
    ndc = clip[:, :, :2] / w[:, :, None]
    px = np.array([size[0] / 2.0, size[1] / 2.0])
    direction = (ndc[:, 1] - ndc[:, 0]) * px
    length = np.linalg.norm(direction, axis=1)
    ok = length > 1e-9
    clip, colors, direction, length, w = clip[ok], colors[ok], direction[ok], length[ok], w[ok]
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1) / length[:, None]
    offset = normal * (width / 2.0) / px  # NDC units
    corners = []
    for end, side in ((0, -1), (0, 1), (1, 1), (0, -1), (1, 1), (1, -1)):
        c = clip[:, end].copy()
        c[:, :2] += side * offset * w[:, end, None]
        corners.append(np.concatenate([c, colors], axis=1))
    return np.stack(corners, axis=1).reshape(-1, 7).astype(np.float32)


_MESH_VS = """
#version 330
uniform mat4 u_mvp;
uniform mat3 u_normal;
in vec3 in_pos;
in vec3 in_normal;
out vec3 v_normal;
void main() { v_normal = u_normal * in_normal; gl_Position = u_mvp * vec4(in_pos, 1.0); }
"""
_MESH_FS = """
#version 330
uniform vec3 u_color;
uniform vec3 u_light;
uniform float u_ambient;
in vec3 v_normal;
out vec4 f_color;
void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    float lambert = max(dot(n, u_light), 0.0);
    f_color = vec4(u_color * (u_ambient + (1.0 - u_ambient) * lambert), 1.0);
}
"""
_LINE_VS = """
#version 330
in vec4 in_clip;
in vec3 in_color;
out vec3 v_color;
void main() { v_color = in_color; gl_Position = in_clip; }
"""
_LINE_FS = """
#version 330
uniform float u_alpha;
in vec3 v_color;
out vec4 f_color;
void main() { f_color = vec4(v_color, u_alpha); }
"""


def _uniform(program: moderngl.Program, name: str) -> moderngl.Uniform:
    """A uniform of ``program`` (``program[name]`` may also name a block, an attribute or a varying)."""
    import moderngl

    member = program[name]
    assert isinstance(member, moderngl.Uniform)
    return member


def _color_texture(fbo: moderngl.Framebuffer) -> moderngl.Texture:
    """The colour attachment of a preview framebuffer: always a texture (imgui draws it), never a renderbuffer."""
    import moderngl

    color = fbo.color_attachments[0]
    assert isinstance(color, moderngl.Texture)
    return color


class PreviewRenderer:
    """Draws the preview pass into its own framebuffer; :meth:`render` returns the colour texture."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.mesh_program = ctx.program(vertex_shader=_MESH_VS, fragment_shader=_MESH_FS)
        self.line_program = ctx.program(vertex_shader=_LINE_VS, fragment_shader=_LINE_FS)
        self._meshes: dict[str, tuple[moderngl.Buffer, moderngl.VertexArray, int]] = {}
        self._fbo: moderngl.Framebuffer | None = None
        self._line_buffer: moderngl.Buffer | None = None
        self.size = (0, 0)
        #: What the framebuffer holds (scene, journal position, view, size, shading, selection): unchanged, no redraw.
        self._key: tuple[object, ...] | None = None
        #: Preview passes drawn (a still scene draws one).
        self.renders = 0

    def _target(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        if self._fbo is None or self.size != size:
            if self._fbo is not None:
                for attachment in (*self._fbo.color_attachments, self._fbo.depth_attachment):
                    attachment.release()
                self._fbo.release()
            self._key = None
            color = self.ctx.texture(size, 4)
            depth = self.ctx.depth_renderbuffer(size)
            self._fbo = self.ctx.framebuffer([color], depth)
            self.size = size
        return self._fbo

    @property
    def texture(self) -> moderngl.Texture | None:
        """The last preview (GL convention: texel row 0 is the image's bottom row)."""
        return None if self._fbo is None else _color_texture(self._fbo)

    def _mesh(self, scene: Scene, asset_name: str) -> tuple[moderngl.VertexArray, int] | None:
        try:
            asset = scene.asset(asset_name)
        except AberrantError:
            return None
        cached = self._meshes.get(asset.content_hash)
        if cached is None:
            tri = asset.vertices[asset.faces].astype(np.float64)  # (M, 3, 3)
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
            data = np.concatenate([tri, np.repeat(n[:, None], 3, axis=1)], axis=2).astype(np.float32)
            buffer = self.ctx.buffer(data.tobytes())
            vao = self.ctx.vertex_array(self.mesh_program, [(buffer, "3f 3f", "in_pos", "in_normal")])
            cached = self._meshes[asset.content_hash] = (buffer, vao, len(tri) * 3)
        return cached[1], cached[2]

    def render(
        self, scene: Scene, view: CameraView, size: tuple[int, int], *, shaded: bool, selected: int | None = None
    ) -> moderngl.Texture:
        """Meshes (depth only, or flat-shaded), then the depth-tested debug lines; transparent where empty.

        The framebuffer is drawn again only when something it shows changed, so a still scene costs nothing.
        """
        import moderngl

        ctx = self.ctx
        fbo = self._target(size)
        key = (scene.world, scene.cursor, *view.position, *view.rotation.ravel(), view.fov_deg, size, shaded, selected)
        if key == self._key:
            return _color_texture(fbo)
        self._key = key
        self.renders += 1
        fbo.color_mask = (True,) * 4
        fbo.depth_mask = True
        fbo.use()  # moderngl applies a framebuffer's masks when it is bound
        ctx.viewport = (0, 0, *size)
        if shaded:
            fbo.clear(*scene.settings.background, 1.0)
        else:
            fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        fbo.color_mask = (shaded,) * 4
        fbo.use()
        proj = perspective(view.fov_deg, size[0] / size[1])
        world_to_view = view_matrix(view)
        ctx.polygon_offset = (1.0, 1.0)
        light = np.asarray(scene.settings.light_dir, dtype=np.float64)
        _uniform(self.mesh_program, "u_light").value = tuple(light / np.linalg.norm(light))
        _uniform(self.mesh_program, "u_ambient").value = float(scene.settings.ambient)
        for _, (transform, mesh) in scene.query(Transform, Mesh):
            drawn = self._mesh(scene, mesh.asset)
            if drawn is None:
                continue
            model = trs_matrix(transform.position, transform.rotation, transform.scale)
            mvp = proj @ (world_to_view @ model)
            normal = np.linalg.inv(model[:3, :3]).T
            _uniform(self.mesh_program, "u_mvp").write(mvp.T.astype("f4").tobytes())
            _uniform(self.mesh_program, "u_normal").write(normal.T.astype("f4").tobytes())
            _uniform(self.mesh_program, "u_color").value = tuple(mesh.color)
            drawn[0].render(moderngl.TRIANGLES, vertices=drawn[1])
        ctx.polygon_offset = (0.0, 0.0)
        fbo.color_mask = (True,) * 4
        fbo.depth_mask = False
        fbo.use()
        view_proj = proj @ world_to_view
        segments, colors = preview_lines(scene, selected)
        self._draw_lines(thick_lines(segments, colors, view_proj, size), 1.0)
        if selected is not None:  # the hidden part of the selection, faintly: where it is behind a wall
            hidden = selection_edges(scene, selected)
            if hidden:
                edges = np.concatenate(hidden)
                ctx.depth_func = ">"
                if shaded:  # mix into the opaque raster image; over a traced frame imgui does the mixing
                    ctx.enable(moderngl.BLEND)
                    # moderngl's stub allows only the 2-value form; its docs and C code take 4 (colour, alpha).
                    ctx.blend_func = (  # type: ignore[assignment]
                        moderngl.SRC_ALPHA,
                        moderngl.ONE_MINUS_SRC_ALPHA,
                        moderngl.ONE,
                        moderngl.ONE,
                    )
                self._draw_lines(thick_lines(edges, np.tile(SELECTION_COLOR, (len(edges), 1)), view_proj, size), 0.3)
                ctx.disable(moderngl.BLEND)
                ctx.depth_func = "<"
        fbo.depth_mask = True
        fbo.use()
        ctx.disable(moderngl.DEPTH_TEST)
        return _color_texture(fbo)

    def _draw_lines(self, vertices: np.ndarray, alpha: float) -> None:
        import moderngl

        if not len(vertices):
            return
        ctx = self.ctx
        if self._line_buffer is None or self._line_buffer.size < vertices.nbytes:
            if self._line_buffer is not None:
                self._line_buffer.release()
            self._line_buffer = ctx.buffer(reserve=max(vertices.nbytes, 4096) * 2)
        self._line_buffer.write(vertices.tobytes())
        _uniform(self.line_program, "u_alpha").value = alpha
        vao = ctx.vertex_array(self.line_program, [(self._line_buffer, "4f 3f", "in_clip", "in_color")])
        vao.render(moderngl.TRIANGLES, vertices=len(vertices))
        vao.release()

    def release(self) -> None:
        for buffer, vao, _ in self._meshes.values():
            vao.release()
            buffer.release()
        self._meshes.clear()
        if self._fbo is not None:
            for attachment in (*self._fbo.color_attachments, self._fbo.depth_attachment):
                attachment.release()
            self._fbo.release()
            self._fbo = None
        if self._line_buffer is not None:
            self._line_buffer.release()
        self.mesh_program.release()
        self.line_program.release()
