"""Rasterising renderers on headless OpenGL.

This package owns a small GL toolkit shared by our rasterising renderers --
getting a headless context (:mod:`.platform`: EGL or OSMesa, probed and
checked once per process), rendering into a float RGBA32F framebuffer with
MSAA and reading the pixels back as radiance (:mod:`.framebuffer`), our GLSL
shaders, kept as package data and written out with their constants filled in
(:mod:`.glsl`), and area emitters cut into point lights (:mod:`.lights`) --
and, on top of it, the pyrender adapter (:mod:`.pyrender_adapter`), the
harness's real-time direct-lighting baseline.
"""
