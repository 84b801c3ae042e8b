"""The colour error each export format's own rendering model implies, as ΔE00 on the stored references' surfaces.

An exported scene is rendered by another renderer's colour model, which may not be ours. This script computes,
per surface (material) of a stored scene, the colour that model gives light reflected once off the surface, the
light seen directly included, against the colour our model gives (what the stored reference holds):

- ``pbrt-v4`` on an RGB scene: pbrt-v4 is spectral. It turns an RGB reflectance into a spectrum by Jakob and
  Hanika's sigmoid fit (2019; ``RGBAlbedoSpectrum``, fitted under the colour space's illuminant, D65 for sRGB)
  and an RGB emission L into ``2 max(L) · sigmoid(L / (2 max(L))) · D65``, normalised to luminance 1 and back
  (``RGBIlluminantSpectrum``; ``DiffuseAreaLight::Create``). The fit here is colour-science's
  ``XYZ_to_sd_Jakob2019`` (the same fit at each colour; pbrt-v4 interpolates a 64³ table of them). Its film is
  CIE 1931 XYZ (its ``cie1931`` sensor), to linear sRGB.
- ``mitsuba`` on a spectral scene: the spectra exactly, but Mitsuba's CIE 1931 table (``mi.cie1931_xyz``)
  differs from colour-science's per wavelength (``CIE_TABLE_NOTE`` in ``src/cornell_harness/renderers/mitsuba3.py``;
  the sums are rescaled in the file).
- ``pbrt-v4`` on a spectral scene and ``mitsuba`` on an RGB scene: our model exactly (pbrt-v4's CIE tables,
  ``CIE_X``/``CIE_Y``/``CIE_Z`` in its ``src/pbrt/util/spectrum.cpp``, equal colour-science's to 5e-13), so not
  computed.

Each surface's colour ratio (theirs / ours, per channel) is applied to the reference's pixels that see that
surface (masks from the scene's geometry, :func:`cornell_harness.evaluate.regions.region_masks`), and the ΔE00
is the harness's (:func:`cornell_harness.evaluate.metrics.delta_e2000`, at the reference's display exposure):
the mean over those pixels. Light reflected more than once is left at our colour, so this is the error of the
first bounce alone, the largest part on a directly lit wall.

    .venv/bin/python benchmarks/export_colour.py --markdown docs/export.md     # the table in its block there
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from pathlib import Path

import numpy as np

from benchmarks import markdown_blocks
from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.materials import Diffuse
from cornell_harness.scenes.model import Region, Scene
from cornell_harness.scenes.spectra import observer, xyz_to_linear_srgb
from cornell_harness.store.references import load_reference


def _colour():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message='"Matplotlib" related API features are not available')
        import colour
    return colour


def d65() -> np.ndarray:
    """CIE D65 on the observer's 1 nm grid (360-830 nm)."""
    colour = _colour()
    grid, _ = observer()
    return colour.SDS_ILLUMINANTS["D65"].copy().align(colour.SpectralShape(grid[0], grid[-1], 1)).values


def _rgb(spectrum: np.ndarray) -> np.ndarray:
    """M · Σ S x̄ / Σ ȳ, our projection (:mod:`cornell_harness.scenes.spectra`)."""
    _, xyz_bar = observer()
    return xyz_to_linear_srgb() @ (spectrum @ xyz_bar) / xyz_bar[:, 1].sum()


def jakob_hanika(rgb) -> np.ndarray:
    """The sigmoid spectrum pbrt-v4 gives a linear-sRGB reflectance, on the observer's grid: the one whose colour
    under D65 (Y of a perfect white 1) is ``rgb``; grey values are constant, as pbrt-v4 makes them."""
    colour = _colour()
    grid, xyz_bar = observer()
    rgb = np.asarray(rgb, dtype=np.float64)
    if np.ptp(rgb) == 0.0:
        return np.full(grid.shape, rgb[0])
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    illuminant = colour.SDS_ILLUMINANTS["D65"].copy().align(cmfs.shape)
    xyz = np.linalg.solve(xyz_to_linear_srgb(), rgb)
    sd = colour.recovery.XYZ_to_sd_Jakob2019(xyz, cmfs, illuminant)
    return np.asarray(sd.align(cmfs.shape).values, dtype=np.float64)


def pbrt_emission(rgb) -> np.ndarray:
    """pbrt-v4's spectrum of an RGB emission, after its normalisation: 2m · sigmoid(rgb / 2m) · D65 / Y(D65)."""
    m = 2.0 * max(rgb)
    light = d65()
    return m * jakob_hanika(np.asarray(rgb) / m) * light / (light @ observer()[1][:, 1] / observer()[1][:, 1].sum())


def pbrt_rgb_ratios(scene: Scene) -> dict[str, np.ndarray]:
    """{material: pbrt-v4's colour of light reflected once / ours}, per channel, and {"light": its colour / ours}."""
    (emitter,) = [m for m in scene.meshes if m.is_emitter]
    light = pbrt_emission(emitter.radiance)
    out = {"light": _rgb(light) / np.asarray(emitter.radiance)}
    for name, material in scene.materials.items():
        if isinstance(material, Diffuse):
            rho = np.asarray(material.reflectance)
            out[name] = _rgb(jakob_hanika(rho) * light) / (rho * np.asarray(emitter.radiance))
    return out


def mitsuba_spectral_ratios(scene: Scene) -> dict[str, np.ndarray]:
    """{material: Mitsuba's colour of light reflected once / ours} under its CIE table, and the light's."""
    from cornell_harness.renderers.mitsuba3 import Mitsuba3

    Mitsuba3().variant("spectral")
    import mitsuba as mi

    grid, xyz_bar = observer()
    table = np.array(mi.cie1931_xyz(mi.Float(grid)), dtype=np.float64).reshape(3, -1).T

    def film(s: np.ndarray) -> np.ndarray:  # the sums rescaled to ours, as the export does
        return xyz_to_linear_srgb() @ (s @ table) / xyz_bar[:, 1].sum()

    sp = scene.spectral
    (emitter,) = [m for m in scene.meshes if m.is_emitter]
    light = sp.emission(emitter.name).at(grid)
    out = {"light": film(light) / _rgb(light)}
    for name in scene.materials:
        if (rho := sp.reflectance(name)) is not None:
            s = rho.at(grid) * light
            out[name] = film(s) / _rgb(s)
    return out


def surface_delta_e(scene: Scene, ratios: dict[str, np.ndarray]) -> dict[str, float]:
    """Mean ΔE00 over the reference's pixels of each surface, their colour multiplied by that surface's ratio."""
    ref = load_reference(scene).image.astype(np.float64)
    objects = {name: tuple(m.name for m in scene.meshes if m.material == name and not m.is_emitter)
               for name in ratios if name != "light"}
    objects["light"] = tuple(m.name for m in scene.meshes if m.is_emitter)
    regions = {name: Region(name, objects=objs) for name, objs in objects.items() if objs}
    masks = region_masks(dataclasses.replace(scene, regions=regions))
    exposure = metrics.display_exposure(ref)
    out = {}
    for name, mask in masks.items():
        theirs = ref.copy()
        theirs[mask] *= ratios[name]
        _, de = metrics.delta_e2000(theirs, ref, exposure=exposure, full=True)
        out[name] = float(de[mask].mean())
    return out


#: The block of docs/export.md this script writes (benchmarks/markdown_blocks.py).
BLOCK = "export_colour.py"


def table() -> str:
    """Every computed format and scene, surface by surface, as Markdown."""
    rows = [("pbrt-v4", "cornell-box", pbrt_rgb_ratios), ("mitsuba", "cornell-box-measured", mitsuba_spectral_ratios)]
    lines = ["| format | scene | surface | their colour / ours (R, G, B), light reflected once | ΔE00 |",
             "| --- | --- | --- | --- | --- |"]
    for fmt, name, ratios_of in rows:
        scene = resolve_scene(name)
        ratios = ratios_of(scene)
        for surface, de in surface_delta_e(scene, ratios).items():
            r = ", ".join(f"{x:.4f}" for x in ratios[surface])
            lines.append(f"| {fmt} | {name} | {surface}{' (seen directly)' * (surface == 'light')} | {r} | {de:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="append", default=[], help="write the table into this file (repeatable)")
    args = ap.parse_args(argv)
    body = table()
    if not args.markdown:
        print(body)
    markdown_blocks.write_blocks([Path(p) for p in args.markdown], {BLOCK: body})


if __name__ == "__main__":
    main()
