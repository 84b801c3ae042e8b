"""Mitsuba 3 adapter: the harness's reference renderer.

Scenes are converted to ``mi.load_dict`` with in-memory meshes (the plugins of
:mod:`cornell_harness.scenes.export.mitsuba`, which ``cbox export`` writes as XML), rendered with
Mitsuba's unidirectional ``path`` integrator (next-event estimation + BSDF
sampling with MIS, Russian roulette from depth 5), an ``independent`` sampler
and a ``box`` reconstruction filter.

Variant: ``llvm_ad_rgb`` when an LLVM shared library of version 17 or newer is
found (``DRJIT_LIBLLVM_PATH`` first, then the usual system locations),
otherwise ``scalar_rgb`` (same images in expectation, about 4x slower). The
variant used is reported in ``RenderResult.info`` and in ``version()``.

Spectral scenes (:mod:`cornell_harness.scenes.spectral_scene`): with the setting ``spectral = auto``
(the default) a scene that gives any reflectance or emission as a spectrum is rendered by
``llvm_ad_spectral`` (else ``scalar_spectral``) on those sampled spectra
(:func:`cornell_harness.scenes.export.mitsuba.spectrum_dict`); ``spectral = rgb`` renders its RGB
projection (the scene's ``rgb_convention``) with the RGB variant. A spectral render says so in
``info["spectral"]`` (:data:`cornell_harness.scenes.spectral_scene.SPECTRAL_INFO`: the variant), which
the results' ``rgb_convention`` column reads. Its film is the same ``hdrfilm``: Mitsuba turns
each wavelength sample into XYZ with its CIE 1931 2° table, divides by its ``∫ȳ``
(``1 / MI_CIE_Y_NORMALIZATION``) and converts to linear sRGB; every emitter's radiance is multiplied by
:func:`spectral_scale` (as ``cbox export`` writes it), which puts that on colour-science's Σȳ, so an
emitter of spectrum L seen directly gives :func:`cornell_harness.scenes.spectra.emission_rgb` (L) up to the
tables' difference (:data:`CIE_TABLE_NOTE`).

Renders are split into passes of at most :data:`MAX_SAMPLES_PER_PASS` samples
so memory stays bounded at any spp (the LLVM variant keeps a whole wavefront
in memory); each pass has its own seed, derived from the user's seed.

Auxiliary images (albedo, normal: :data:`cornell_harness.adapters.api.AOVS`)
come from Mitsuba's ``aov`` integrator wrapped around ``path``, in the same
render: same samples, same box filter. They are Mitsuba's definition, the
first surface hit (mirrors and glass not followed, unlike our path tracer's;
Open Image Denoise accepts either), and its normals are not turned towards
the camera.

Scenes of quantity ``ambient_occlusion`` are rendered by a Python AO
integrator on the same scene, passes and seeds (:mod:`cornell_harness.renderers.mitsuba_ao`;
Mitsuba 3.9 has none of its own), in the LLVM variant only.
"""

from __future__ import annotations

import ctypes.util
import glob
import os
import re
from functools import cache
from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import AOVS, Checkpoint, RenderResult, Setting, Stopwatch, pass_seed, spp_passes
from cornell_harness.scenes.export import mitsuba as mitsuba_plugins
from cornell_harness.scenes.export.mitsuba import (bsdf_dict, emission_spectrum, has_spectra, material_spectra,
                                                   spectral_scale)
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.spectral_scene import SPECTRAL_INFO
from cornell_harness.scenes.transforms import unit_frame
from cornell_harness.renderers import mitsuba_ao

MIN_LLVM_MAJOR = 17
#: Upper bound on width × height × spp of one ``mi.render`` call (~1.5 GB of wavefront state).
MAX_SAMPLES_PER_PASS = 1 << 23

_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
)


def _llvm_major(path: str) -> int | None:
    """LLVM major version from a library file name (libLLVM.so.19.1, libLLVM-19.so)."""
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


@cache
def find_llvm() -> tuple[str | None, str]:
    """(path to a usable libLLVM, or None; a sentence saying what was found)."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env:
        major = _llvm_major(env)
        if not os.path.exists(env):
            return None, f"DRJIT_LIBLLVM_PATH={env} does not exist"
        if major is not None and major < MIN_LLVM_MAJOR:
            return None, f"DRJIT_LIBLLVM_PATH={env} is LLVM {major}; Mitsuba 3.9 needs {MIN_LLVM_MAJOR} or newer"
        return env, f"LLVM from DRJIT_LIBLLVM_PATH={env}"
    candidates = [p for g in _LLVM_GLOBS for p in glob.glob(g)]
    found = ctypes.util.find_library("LLVM")
    if found:
        candidates.append(found)
    versioned = [(v, p) for p in candidates if (v := _llvm_major(p)) is not None and os.path.exists(p)]
    good = sorted((v, p) for v, p in versioned if v >= MIN_LLVM_MAJOR)
    if good:
        major, path = good[-1]
        return path, f"LLVM {major} at {path}"
    seen = ", ".join(sorted({str(v) for v, _ in versioned})) or "none"
    return None, (
        f"no LLVM >= {MIN_LLVM_MAJOR} found (versions seen: {seen}); install Debian's libllvm19 "
        "or set DRJIT_LIBLLVM_PATH"
    )


#: How Mitsuba 3.9.1's CIE 1931 2° table (``mi.cie1931_xyz``, 360-830 nm at 1 nm) and its film's normalisation
#: compare with colour-science's, which :mod:`cornell_harness.scenes.spectra` uses (measured in
#: ``tests/renderers/test_mitsuba_spectral.py``). The tables' sums agree to 1.4e-6, but single wavelengths differ
#: by up to 11% of x̄, 5% of z̄ and 1.6% of ȳ (largest near 418 nm: another edition of the table). The film
#: divides by ``1 / MI_CIE_Y_NORMALIZATION`` = 106.7503 where both tables' Σȳ = 106.857, which would make a
#: spectral image 0.100% brighter than :func:`~cornell_harness.scenes.spectra.emission_rgb`: the adapter multiplies
#: the emitters by :func:`spectral_scale` to remove that. What remains is the tables' shapes: on the Cornell spectra
#: (light L, and white, green, red × L) the linear sRGB differs by at most 1.5e-4 for L and white, and
#: 0.1% (green's R), 0.8% (red's G), 2.3% (green's B) and -1.1% (red's B) in the small channels of the
#: coloured products.
CIE_TABLE_NOTE = ("Mitsuba's CIE table differs from colour-science's per wavelength (sums equal); its film's "
                  "1/106.7503 normalisation is rescaled to colour-science's Σȳ (src/cornell_harness/renderers/mitsuba3.py)")


@cache
def _select_variant(colour: str = "rgb") -> tuple[str, str]:
    """Set and return Mitsuba's variant for ``colour`` (``rgb`` or ``spectral``), with a note on why it was chosen."""
    llvm, note = find_llvm()
    if llvm and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        os.environ["DRJIT_LIBLLVM_PATH"] = llvm  # drjit reads it at first use
    import mitsuba as mi

    if llvm:
        try:
            mi.set_variant(f"llvm_ad_{colour}")
            import drjit as dr

            dr.eval(dr.arange(mi.Float, 4) + 1)  # forces LLVM to load now, not mid-render
            return f"llvm_ad_{colour}", note
        except Exception as e:  # a broken LLVM must degrade, not crash
            note = f"llvm_ad_{colour} failed ({type(e).__name__}: {e}); falling back"
    mi.set_variant(f"scalar_{colour}")
    return f"scalar_{colour}", f"{note}; using scalar_{colour} (about 4x slower)"


def _use_variant(colour: str) -> tuple[str, str]:
    """Make ``colour``'s variant (``rgb``, ``spectral``) Mitsuba's current one; one process may render both."""
    variant, note = _select_variant(colour)
    import mitsuba as mi

    if mi.variant() != variant:
        mi.set_variant(variant)
    return variant, note


def scene_dict(scene: Scene, spp: int, sampler: str = "independent", aovs: bool = False,
               spectral: bool = False) -> dict:
    """The scene as a ``mi.load_dict`` dictionary (Mitsuba must be imported, in a spectral variant if
    ``spectral``: then materials and emitters given as spectra get those spectra, not their RGB projection, and
    every emitter's radiance is multiplied by :func:`spectral_scale`).

    The plugins are :mod:`cornell_harness.scenes.export.mitsuba`'s, the ones ``cbox export --format mitsuba``
    writes as XML; here the meshes are built in memory. ``sampler`` is a Mitsuba sampler plugin (the
    adapter renders with ``independent``; ``benchmarks/pathtracer.py`` compares ``multijitter`` and
    ``ldsampler``, which round spp up to a square or a power of two).

    Geometry and camera are first moved and scaled so the scene's bounding
    box is centred on the origin with a diagonal of 1 (:func:`unit_frame`). With ``aovs`` the
    integrator is wrapped in ``aov`` (albedo, then shading normal, after RGB). Mitsuba offsets new
    rays by about 1e-4·(1 + |p|) scene units whatever the scene's size, which
    lets light leak through the walls of a box 1e-3 units wide (cbox stress
    found this: +1.2% mean, +60% in some tiles). A uniform change of units
    leaves radiance images unchanged, so this costs nothing in exactness.
    """
    import mitsuba as mi

    look = mitsuba_plugins.camera_look_at(scene)
    d: dict = {
        "type": "scene",
        "integrator": mitsuba_plugins.integrator_dict(scene),
        "sensor": mitsuba_plugins.sensor_dict(
            scene, spp, mi.ScalarTransform4f().look_at(origin=look.origin, target=look.target, up=look.up), sampler),
    }
    if aovs:
        d["integrator"] = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal", "integrator": d["integrator"]}
    spectra = material_spectra(scene, spectral)
    scale = spectral_scale() if spectral else 1.0
    bsdfs = {name: mi.load_dict(bsdf_dict(m, spectra.get(name))) for name, m in scene.materials.items()}
    for i, s in enumerate(scene.spheres):
        d[f"sphere_{i}"] = mitsuba_plugins.sphere_dict(scene, s) | {"bsdf": bsdfs[s.material]}
    for i, m in enumerate(scene.meshes):
        props = mi.Properties()
        props["bsdf"] = bsdfs[m.material]
        if m.is_emitter:
            props["emitter"] = mi.load_dict(mitsuba_plugins.emitter_dict(m.radiance,
                                                                         emission_spectrum(scene, m, spectral), scale))
        mesh = mi.Mesh(m.name, len(m.vertices), len(m.triangles), has_vertex_normals=False,
                       has_vertex_texcoords=False, props=props)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(mitsuba_plugins.unit_vertices(scene, m).ravel())
        params["faces"] = mi.UInt32(m.triangles.astype(np.uint32).ravel())
        params.update()
        d[f"mesh_{i}"] = mesh
    return d


def run_passes(spp: int, seed: int, per_pass: int, checkpoints: Sequence[int], sums, image, aovs=None, stop=None,
               variance=None):
    """Accumulate ``sums(n, pass_seed)`` (a tuple of per-pixel sums over n samples) over the passes of a render.

    Returns (sums over all spp, ``image(sums, spp)``, checkpoints, wall seconds spent in ``sums``, CPU seconds
    spent in ``sums``, Mitsuba's threads included, the spp rendered); a checkpoint's image is
    ``image(sums so far, done)``, its auxiliary images ``aovs(sums so far, done)`` (none if None), its variance
    ``variance(sums so far, done)`` (none if None). When
    ``stop`` (``stops_early``) returns True for a checkpoint, the render ends there: its spp is the checkpoint's.
    """
    acc, done, elapsed, cpu, shots = None, 0, 0.0, 0.0, []
    for k, n in enumerate(spp_passes(spp, per_pass, checkpoints)):
        clock = Stopwatch()
        part = sums(n, pass_seed(seed, k))
        wall_k, cpu_k = clock.read()
        elapsed, cpu = elapsed + wall_k, cpu + cpu_k
        acc = part if acc is None else tuple(a + p for a, p in zip(acc, part))
        done += n
        if done in checkpoints and done < spp:
            shots.append(Checkpoint(done, image(acc, done), elapsed, aovs(acc, done) if aovs else {}, cpu,
                                    variance(acc, done) if variance else None))
            if stop is not None and stop(shots[-1]):
                return acc, shots[-1].image, shots, elapsed, cpu, done
    final = image(acc, spp)
    if spp in checkpoints:
        shots.append(Checkpoint(spp, final, elapsed, aovs(acc, spp) if aovs else {}, cpu,
                                variance(acc, spp) if variance else None))
    return acc, final, shots, elapsed, cpu, spp


#: The kernels this process has compiled (or loaded from Dr.Jit's cache), by (scene content hash, what else
#: changes the kernel): a render of one of these needs no warm-up.
_WARM: set = set()


def _warm_up(key, sums) -> None:
    """A 1-spp pass (``sums(1, seed 0)``, thrown away) the first time this process renders ``key``, so that
    Dr.Jit's tracing and LLVM compilation (or the load from its disk cache: measured 0.24 s for the Cornell
    box's first 1-spp pass with a cold cache, 0.03 s with a warm one) are set-up, not the render's time."""
    if key not in _WARM:
        sums(1, 0)
        _WARM.add(key)


def _threads() -> int:
    """Threads of Dr.Jit's pool, which renders the LLVM variant (all cores unless set otherwise)."""
    import drjit as dr

    return int(dr.thread_count())


class Mitsuba3:
    """Mitsuba 3 path tracer (``path`` integrator); ambient occlusion by :mod:`cornell_harness.renderers.mitsuba_ao`."""

    name = "mitsuba"
    citations = (
        'Jakob et al. 2022, "Mitsuba 3 renderer", https://mitsuba-renderer.org',
        'Veach 1997, "Robust Monte Carlo Methods for Light Transport Simulation" (PhD thesis), §9.2')
    features = mitsuba_plugins.FEATURES  # what the translation into Mitsuba's plugins expresses
    quantities = ("radiance", "ambient_occlusion")
    approximations: tuple[str, ...] = ()
    aovs = AOVS
    stops_early = True
    settings = (Setting("spectral", str, "auto", "auto: a scene with spectra renders them with the spectral variant "
                        "(llvm_ad_spectral, else scalar_spectral), any other scene with the RGB one; rgb: always "
                        "the RGB variant, on the scene's RGB projection (its rgb_convention)",
                        choices=("auto", "rgb")),)

    def unavailable_reason(self) -> str | None:
        try:
            import mitsuba  # noqa: F401
        except ImportError as e:
            return f"mitsuba is not installed ({e}); pip install mitsuba"
        return None

    def variant(self, colour: str = "rgb") -> tuple[str, str]:
        """(the variant for ``colour``, rgb or spectral; why it was chosen), made Mitsuba's current one."""
        return _use_variant(colour)

    def version(self) -> str:
        import mitsuba as mi

        return f"{mi.__version__} ({_select_variant('rgb')[0]})"  # a spectral run's variant: info["variant"]

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               aovs: Sequence[str] = (), settings: dict | None = None, stop=None) -> RenderResult:
        spectral = (settings or {}).get("spectral", "auto") == "auto" and has_spectra(scene)
        variant, note = _use_variant("spectral" if spectral else "rgb")
        import mitsuba as mi

        clock = Stopwatch()
        info = {"variant": variant, "variant_note": note, "threads": _threads()}
        if spectral:
            info[SPECTRAL_INFO] = variant
            info["cie_note"] = CIE_TABLE_NOTE
        cam = scene.camera
        per_pass = max(1, MAX_SAMPLES_PER_PASS // (cam.width * cam.height))
        if unknown := set(aovs) - set(AOVS):
            raise ValueError(f"unknown AOVs {sorted(unknown)}; this renderer gives {', '.join(AOVS)}")
        if aovs and scene.quantity != "radiance":
            raise ValueError(f"AOVs are for radiance images; scene {scene.name!r} is {scene.quantity}")
        mi_scene = mi.load_dict(scene_dict(scene, per_pass, aovs=bool(aovs), spectral=spectral))
        if scene.quantity == "ambient_occlusion":
            return self._render_ao(mi_scene, scene, spp, seed, checkpoints, per_pass, info, clock, stop)

        if spectral:  # folded into the emitters (scene_dict)
            info["spectral_scale"] = round(spectral_scale(), 9)

        def sums(n: int, s: int) -> tuple[np.ndarray]:
            return (np.asarray(mi.render(mi_scene, spp=n, seed=s), dtype=np.float64) * n,)

        _warm_up((scene.content_hash(), bool(aovs), variant), sums)
        info["setup_s"] = round(clock.wall(), 3)  # scene load and warm-up, outside time_s

        def aux(acc, n: int) -> dict:
            return {name: (acc[0][..., 3 + 3 * j:6 + 3 * j] / n).astype(np.float32) for j, name in enumerate(AOVS)}

        acc, image, shots, elapsed, cpu, spp = run_passes(spp, seed, per_pass, checkpoints, sums,
                                                          lambda acc, n: (acc[0][..., :3] / n).astype(np.float32),
                                                          aux if aovs else None, stop)
        return RenderResult(image, elapsed, spp, seed, shots, info, aovs=aux(acc, spp) if aovs else {},
                            cpu_time_s=cpu)

    def _render_ao(self, mi_scene, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int], per_pass: int,
                   info: dict, clock: Stopwatch, stop=None) -> RenderResult:
        """Ambient occlusion (:mod:`cornell_harness.renderers.mitsuba_ao`): grey image and the variance of its mean."""
        if info["variant"] == "scalar_rgb":
            raise RuntimeError(f"ambient occlusion needs Mitsuba's llvm_ad_rgb variant: {info['variant_note']}")
        maxt = mitsuba_ao.unit_max_distance(scene, unit_frame(scene)[1])
        shape = (scene.camera.height, scene.camera.width)

        def sums(n: int, s: int) -> tuple[np.ndarray, np.ndarray]:
            return mitsuba_ao.ao_pass(mi_scene, scene, maxt, n, s)

        _warm_up((scene.content_hash(), "ao", info["variant"]), sums)
        info["setup_s"] = round(clock.wall(), 3)

        (s1, s2), image, shots, elapsed, cpu, spp = run_passes(
            spp, seed, per_pass, checkpoints, sums,
            lambda acc, n: mitsuba_ao.mean_and_variance(acc[0], acc[1], n, shape)[0], stop=stop,
            variance=lambda acc, n: mitsuba_ao.mean_and_variance(acc[0], acc[1], n, shape)[1])
        variance = mitsuba_ao.mean_and_variance(s1, s2, spp, shape)[1]
        return RenderResult(image, elapsed, spp, seed, shots, info, variance, cpu_time_s=cpu)
