"""Denoising with Intel Open Image Denoise (OIDN): a renderer's low-spp image cleaned by a learned filter.

OIDN's ``RT`` filter (Intel Open Image Denoise 2.5, its documentation's
"RT" and "Denoising with prefiltering" sections; Áfra, "Intel Open Image
Denoise", 2024) is a U-Net trained on path-traced images: it takes the noisy
radiance and, optionally, the albedo and normal of what each pixel sees
(:data:`cornell_harness.adapters.api.AOVS`), and returns a clean estimate. What
it keeps wrong, no number of samples removes: the harness measures that
(``docs/denoising.md``), so a denoised renderer declares itself ``biased``
(:class:`cornell_harness.adapters.api.Declarations`): no per-pixel variance, never a z-test;
the gate gives it budgets and a consistency check.

- ``hdr=True``: our images are linear HDR radiance.
- **Auxiliary images** (setting ``aux``): ``prefiltered``, OIDN's recommended
  mode for the best quality: albedo and normal are first denoised by filters
  of their own, then the beauty is filtered with ``cleanAux``; ``noisy``
  passes them as rendered (``cleanAux`` off: OIDN denoises them jointly);
  ``none`` passes the beauty alone. pyoidn's one-call ``denoise(...,
  clean_aux=True)`` does not prefilter, hence the Device/Filter calls here.
- **Quality** (setting ``quality``): OIDN's ``high``, ``balanced`` or ``fast``
  network.
- **Time**: a render's time is the wrapped renderer's plus the denoise of its
  image (a checkpoint's, the denoise of that checkpoint alone). The device is
  created and run once on a small image before any timing, as a renderer's
  JIT warm-up is left out.
- **Threads**: OIDN's CPU device gets ``numThreads`` from ``CBOX_THREADS`` (or
  the adapter's ``threads``), like our renderers.
- **Determinism**: measured here (``tests/renderers/test_oidn.py``): OIDN 2.5.1's CPU
  output was bit-identical across runs and across 1 and 2 threads on this
  machine (x86-64, AVX2); :data:`DETERMINISM` says so in every result's info.
  OIDN does not promise it across CPUs with other instruction sets.
"""

from __future__ import annotations

import threading
from functools import cache
from typing import Any, Mapping, Sequence

import numpy as np

from cornell_harness.adapters.api import AOVS, Checkpoint, RenderResult, Setting, Stopwatch, attribute, default_threads
from cornell_harness.scenes.model import Scene

QUALITIES = ("high", "balanced", "fast")
AUX_MODES = ("prefiltered", "noisy", "none")
OWN_SETTINGS = (
    Setting("quality", str, "high", "OIDN's network: high, balanced or fast", choices=QUALITIES),
    Setting("aux", str, "prefiltered", "albedo and normal: prefiltered (OIDN's recommended mode), noisy "
            "(passed as rendered) or none (the beauty alone)", choices=AUX_MODES),
)
#: Measured, not promised by OIDN (module docstring); recorded in every result's info.
DETERMINISM = "bit-identical across runs and thread counts on the machine measured (tests/renderers/test_oidn.py)"
OIDN_MINOR = (2, 5)

_LOCK = threading.Lock()  # one filter execution at a time per process: the device is shared


def _check(device, what: str) -> None:
    if (message := device.get_error()) is not None:
        raise RuntimeError(f"OIDN {what} failed: {message}")


@cache
def _device(threads: int):
    """A committed CPU device with ``threads`` threads (0: OIDN's choice), warmed up on a small image."""
    import pyoidn

    device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
    if threads:
        device.set_int("numThreads", threads)
    device.commit()
    _check(device, "device creation")
    small = np.full((16, 16, 3), 0.5, dtype=np.float32)
    _run(device, small, small, small, "high", "prefiltered")
    return device


def _filter(device, images: dict, quality: str, **flags) -> None:
    """Run one ``RT`` filter on ``images`` (slot name -> contiguous float32 (H, W, 3)), in place into 'output'."""
    import pyoidn

    f = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT)
    try:
        for name, image in images.items():
            f.set_image(name, image, pyoidn.OIDN_FORMAT_FLOAT3)
        for name, value in flags.items():
            f.set_bool(name, value)
        f.set_quality({"high": pyoidn.OIDN_QUALITY_HIGH, "balanced": pyoidn.OIDN_QUALITY_BALANCED,
                       "fast": pyoidn.OIDN_QUALITY_FAST}[quality])
        f.commit()
        f.execute()
        _check(device, "filter")
    finally:
        f.release()


def _run(device, color, albedo, normal, quality: str, aux: str) -> np.ndarray:
    color = np.ascontiguousarray(color, dtype=np.float32)
    out = np.empty_like(color)
    images = {"color": color, "output": out}
    if aux != "none":
        # Copies: prefiltering writes in place, and the caller's images must not change.
        albedo = np.array(albedo, dtype=np.float32, order="C")
        normal = np.array(normal, dtype=np.float32, order="C")
        if aux == "prefiltered":
            _filter(device, {"albedo": albedo, "output": albedo}, quality)
            _filter(device, {"normal": normal, "output": normal}, quality)
        images.update(albedo=albedo, normal=normal)
    _filter(device, images, quality, hdr=True, cleanAux=aux == "prefiltered")
    return out


def denoise(color: np.ndarray, albedo: np.ndarray | None = None, normal: np.ndarray | None = None, *,
            quality: str = "high", aux: str = "prefiltered", threads: int = 0) -> np.ndarray:
    """``color`` (linear HDR radiance, (H, W, 3)) denoised by OIDN's RT filter, float32 (H, W, 3).

    ``albedo`` and ``normal`` (:data:`cornell_harness.adapters.api.AOVS`) are used
    as ``aux`` says (module docstring); both are needed unless ``aux`` is
    ``none``. ``threads`` is the CPU device's thread count (0: OIDN's choice).
    """
    if quality not in QUALITIES or aux not in AUX_MODES:
        raise ValueError(f"quality must be one of {QUALITIES} and aux one of {AUX_MODES}")
    if aux != "none" and (albedo is None or normal is None):
        raise ValueError(f"aux={aux!r} needs both albedo and normal")
    with _LOCK:
        return _run(_device(int(threads)), color, albedo, normal, quality, aux)


def unavailable_reason() -> str | None:
    """None if OIDN 2.5 runs here on the CPU, else why not."""
    try:
        import pyoidn
        from pyoidn.version import oidn_version
    except ImportError as e:
        return f"pyoidn is not installed ({e}); pip install 'pyoidn>=2.5,<2.6'"
    if tuple(int(x) for x in oidn_version.split(".")[:2]) != OIDN_MINOR:
        return f"pyoidn bundles OIDN {oidn_version}; this adapter is written for OIDN 2.5"
    if not pyoidn.Device.is_cpu_available():
        return "OIDN's CPU device is not supported on this machine (it needs SSE4.1 or NEON)"
    return None


class Denoised:
    """A renderer that gives albedo and normal AOVs (``aovs`` attribute), its images denoised by OIDN.

    Named ``<renderer>+oidn``; its settings are the wrapped renderer's plus
    ``quality`` and ``aux`` (:data:`OWN_SETTINGS`).
    """

    estimator = "biased"
    quantities = ("radiance",)
    citations = ('Áfra 2024, "Intel Open Image Denoise", https://www.openimagedenoise.org',)

    def __init__(self, base, threads: int | None = None):
        self.base = base
        self.threads = threads
        self.name = f"{base.name}+oidn"
        self.features = base.features
        self.approximations = tuple(base.approximations) + (
            "denoised by Intel Open Image Denoise (a learned filter): biased, no per-pixel variance",)
        self.settings = attribute(base, "settings") + OWN_SETTINGS
        self.citations = attribute(base, "citations") + Denoised.citations

    def unavailable_reason(self) -> str | None:
        if not set(AOVS) <= set(attribute(self.base, "aovs")):
            return f"{self.base.name} gives no albedo and normal AOVs"
        return self.base.unavailable_reason() or unavailable_reason()

    def version(self) -> str:
        from importlib.metadata import version
        from pyoidn.version import oidn_version

        return f"{self.base.version()} + OIDN {oidn_version} (pyoidn {version('pyoidn')})"

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (), *,
               settings: Mapping[str, Any]) -> RenderResult:
        """The wrapped renderer's render with ``settings`` but quality and aux (all of them, resolved by the
        render path), its image and each checkpoint's denoised."""
        own = {s.name for s in OWN_SETTINGS}
        quality, aux = settings["quality"], settings["aux"]
        base_settings = {k: v for k, v in settings.items() if k not in own}
        kwargs = {"settings": base_settings} if attribute(self.base, "settings") else {}
        threads = self.threads or default_threads()
        warm = Stopwatch()
        _device(threads)  # created and warmed before any timing
        device_s = warm.wall()
        result = self.base.render(scene, spp, seed, checkpoints, aovs=AOVS if aux != "none" else (), **kwargs)

        def cleaned(image: np.ndarray, aovs: dict) -> tuple[np.ndarray, float, float]:
            clock = Stopwatch()
            out = denoise(image, aovs.get("albedo"), aovs.get("normal"), quality=quality, aux=aux, threads=threads)
            return out, *clock.read()

        def plus(cpu: float | None, more: float) -> float | None:
            return None if cpu is None else cpu + more

        shots = []
        for c in result.checkpoints:
            image, dt, dcpu = cleaned(c.image, c.aovs)
            shots.append(Checkpoint(c.spp, image, c.time_s + dt, c.aovs, plus(c.cpu_time_s, dcpu)))
        if shots and shots[-1].spp == spp:
            image, dt = shots[-1].image, shots[-1].time_s - result.checkpoints[-1].time_s
            dcpu = (shots[-1].cpu_time_s or 0.0) - (result.checkpoints[-1].cpu_time_s or 0.0)
        else:
            image, dt, dcpu = cleaned(result.image, result.aovs)
        info = {**result.info, "denoiser": f"OIDN (quality {quality}, aux {aux})", "denoise_s": round(dt, 4),
                "denoise_threads": threads, "denoise_determinism": DETERMINISM,
                "setup_s": round(float(result.info.get("setup_s") or 0.0) + device_s, 3)}
        return RenderResult(image, result.time_s + dt, spp, seed, shots, info, None, result.aovs,
                            plus(result.cpu_time_s, dcpu))


class PathTracerOIDN(Denoised):
    """``pathtracer+oidn``: our path tracer (:mod:`cornell_harness.renderers.pathtracer`), denoised."""

    def __init__(self, threads: int | None = None):
        from cornell_harness.renderers.pathtracer import PathTracer

        super().__init__(PathTracer(threads), threads)


class MitsubaOIDN(Denoised):
    """``mitsuba+oidn``: Mitsuba 3 (:mod:`cornell_harness.renderers.mitsuba3`), denoised the same way."""

    def __init__(self, threads: int | None = None):
        from cornell_harness.renderers.mitsuba3 import Mitsuba3

        super().__init__(Mitsuba3(), threads)
