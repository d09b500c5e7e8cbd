"""The preview pass: meshes rasterised to depth (optionally flat-shaded), then debug lines depth-tested on them.

The lines are :mod:`editor.overlay`'s: only what the view's frustum holds, each
entity's outline kept until it changes. Over a traced frame only the lines are
visible (the meshes write depth only); in "raster" mode the meshes are
flat-shaded too, which is fast enough to use while dragging when the tracer is not.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from components import Mesh, Transform
from editor.overlay import SELECTION_COLOR, Outlines, selection_edges, thick_lines, view_planes
from editor.view import perspective, view_matrix
from engine.camera_view import CameraView
from engine.errors import AberrantError
from engine.maths import trs_matrix
from engine.scene import Scene

if TYPE_CHECKING:
    import moderngl

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
        #: The boxes' and portals' outlines, kept per entity version; a frame looks only at what its view shows.
        self.outlines = Outlines()

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
        segments, colors = self.outlines.lines(scene, selected, planes=view_planes(view_proj, size))
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
