"""Rendering into float colour buffers and reading the pixels back as radiance.

pyrender renders into an 8-bit colour buffer, clamped to [0, 1] and
gamma-encoded. :func:`float_renderer` gives a pyrender ``Renderer`` whose
pair of framebuffers (4x MSAA, then a resolve target, as pyrender's) are
RGBA32F, with our shaders (from a folder, through pyrender's
``ShaderProgramCache``) and a fixed mesh draw order, and which returns the
image as linear float radiance, top row first, with no clamping or
quantisation.

Nothing here imports pyrender or PyOpenGL at module level: the headless
platform must be chosen first (:mod:`cornell_harness.renderers.raster.platform`).
"""

from __future__ import annotations

import numpy as np

#: MSAA samples per (sub)pixel of the colour buffer (OpenGL 3 guarantees 4).
MSAA_SAMPLES = 4
#: Set to True on a pyrender ``Primitive`` that is the back-side copy of a
#: mesh: it is drawn with a polygon offset so that it loses depth ties.
BACK_SIDE_ATTR = "cbox_back_side"


def float_renderer(width: int, height: int, shader_dir: str):
    """A pyrender Renderer with the shaders in ``shader_dir`` and an RGBA32F colour buffer."""
    import pyrender
    from OpenGL import GL
    from pyrender.shader_program import ShaderProgramCache

    class FloatRenderer(pyrender.Renderer):
        def __init__(self):
            super().__init__(width, height)
            self._program_cache = ShaderProgramCache(shader_dir=shader_dir)

        def _sorted_mesh_nodes(self, scene):
            # pyrender draws in a set's order, which changes from run to run; with
            # MSAA, llvmpipe's silhouette pixels depend on the draw order. Fix it.
            return sorted(scene.mesh_nodes, key=lambda node: node.mesh.name)

        def _configure_main_framebuffer(self):
            dims = (self.viewport_width, self.viewport_height)
            if self._main_fb is not None and self._main_fb_dims != dims:
                self._delete_main_framebuffer()
            if self._main_fb is not None:
                return
            (self._main_fb, self._main_cb, self._main_db,
             self._main_fb_ms, self._main_cb_ms, self._main_db_ms) = float_framebuffers(*dims)
            self._main_fb_dims = dims

        def _bind_and_draw_primitive(self, primitive, pose, program, flags):
            # Back-side copies lose depth ties to front sides (at a closed mesh's
            # silhouette both meet at the same depth; the draw order is a set's order).
            back = getattr(primitive, BACK_SIDE_ATTR, False)
            if back:
                GL.glEnable(GL.GL_POLYGON_OFFSET_FILL)
                GL.glPolygonOffset(1.0, 4.0)
            try:
                super()._bind_and_draw_primitive(primitive, pose, program, flags)
            finally:
                if back:
                    GL.glDisable(GL.GL_POLYGON_OFFSET_FILL)

        def _read_main_framebuffer(self, scene, flags):
            w, h = self._main_fb_dims
            return read_float_pixels(self._main_fb_ms, self._main_fb, w, h), None

    return FloatRenderer()


def float_framebuffers(width: int, height: int) -> tuple[int, int, int, int, int, int]:
    """(fb, colour, depth, fb_ms, colour_ms, depth_ms): a resolve framebuffer and an MSAA
    one, each with an RGBA32F colour and a 24-bit depth renderbuffer (pyrender's layout)."""
    from OpenGL import GL

    samples = min(MSAA_SAMPLES, int(GL.glGetIntegerv(GL.GL_MAX_SAMPLES)))
    cb, db, cb_ms, db_ms = GL.glGenRenderbuffers(4)
    for rb, fmt, n in ((cb, GL.GL_RGBA32F, 0), (db, GL.GL_DEPTH_COMPONENT24, 0),
                       (cb_ms, GL.GL_RGBA32F, samples), (db_ms, GL.GL_DEPTH_COMPONENT24, samples)):
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
        GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, n, fmt, width, height)
    fb, fb_ms = GL.glGenFramebuffers(2)
    for f, c, d in ((fb, cb, db), (fb_ms, cb_ms, db_ms)):
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, f)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, c)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, d)
        status = GL.glCheckFramebufferStatus(GL.GL_DRAW_FRAMEBUFFER)
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            GL.glDeleteFramebuffers(2, [fb, fb_ms])
            GL.glDeleteRenderbuffers(4, [cb, db, cb_ms, db_ms])
            raise RuntimeError(f"the RGBA32F framebuffer is incomplete (status 0x{int(status):x})")
    return fb, cb, db, fb_ms, cb_ms, db_ms


def read_float_pixels(fb_ms: int, fb: int, width: int, height: int) -> np.ndarray:
    """The (height, width, 3) float32 image drawn into ``fb_ms``, resolved into ``fb``."""
    from OpenGL import GL

    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fb_ms)
    GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb)
    # The blit resolves the MSAA samples.
    GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fb)
    GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT0)
    GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 4)
    buf = GL.glReadPixels(0, 0, width, height, GL.GL_RGBA, GL.GL_FLOAT)
    if isinstance(buf, (bytes, bytearray)):
        img = np.frombuffer(buf, dtype=np.float32)
    else:
        img = np.asarray(buf, dtype=np.float32).ravel()
    # GL's row 0 is the bottom; the harness's is the top.
    return img.reshape(height, width, 4)[::-1, :, :3].copy()
