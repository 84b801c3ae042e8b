"""Renderers a user might write, loaded by the tests as ``tests.user_renderers:ClassName``.

They implement the adapter interface without importing anything from the
harness but its result type, exactly as a third-party package would.
"""

from __future__ import annotations

import os

import numpy as np

from cornell_harness.adapters.api import RenderResult
from cornell_harness.adapters.settings import Setting

ALL = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})


class FlatGrey:
    """Every pixel the same grey: a valid, deterministic, very wrong renderer."""

    name = "flat-grey"
    features = ALL
    approximations = ("everything is grey",)
    calls = 0

    def unavailable_reason(self):
        return None

    def version(self):
        return "1.0"

    def render(self, scene, spp, seed, checkpoints=()):
        type(self).calls += 1
        img = np.full((scene.camera.height, scene.camera.width, 3), 0.25, dtype=np.float32)
        return RenderResult(img, 0.001, spp, seed)


class MeshOnly(FlatGrey):
    """Models geometry only: must be skipped on any lit scene, never run."""

    name = "mesh-only"
    features = frozenset({"triangle_mesh", "pinhole_camera"})

    def render(self, scene, spp, seed, checkpoints=()):
        raise AssertionError("a renderer that lacks a feature must not be run")


class NeedsGPU(FlatGrey):
    name = "needs-gpu"

    def unavailable_reason(self):
        return "no CUDA device found"


class Crashes(FlatGrey):
    name = "crashes"

    def render(self, scene, spp, seed, checkpoints=()):
        raise RuntimeError("segfault simulator")


class WrongShape(FlatGrey):
    name = "wrong-shape"

    def render(self, scene, spp, seed, checkpoints=()):
        return RenderResult(np.zeros((2, 2, 3), np.float32), 0.0, spp, seed)


class SeededNoise(FlatGrey):
    """Grey plus unit Gaussian noise drawn from the seed: independent across seeds."""

    name = "seeded-noise"

    def render(self, scene, spp, seed, checkpoints=()):
        rng = np.random.default_rng(seed)
        shape = (scene.camera.height, scene.camera.width, 3)
        img = 0.25 + rng.standard_normal(shape) / np.sqrt(spp)
        return RenderResult(img.astype(np.float32), 0.001, spp, seed)


class CountingNoise(SeededNoise):
    """Seeded noise that logs each render to $CBOX_TEST_RENDER_LOG and takes a little time.

    Lets a test kill a run midway and see which cells were rendered again. With
    $CBOX_TEST_RENDER_HOLD_AFTER = N, a render that finds N renders logged already waits HOLD_S
    (unlogged) instead: the run stops after exactly those N, however busy the machine, until it is killed.
    """

    name = "counting-noise"
    HOLD_S = 600.0

    def render(self, scene, spp, seed, checkpoints=()):
        import os
        import time

        log = os.environ["CBOX_TEST_RENDER_LOG"]
        hold = os.environ.get("CBOX_TEST_RENDER_HOLD_AFTER")
        if hold is not None and os.path.exists(log) and len(open(log).read().splitlines()) >= int(hold):
            time.sleep(self.HOLD_S)
        time.sleep(float(os.environ.get("CBOX_TEST_RENDER_SLEEP", "0")))
        with open(log, "a") as f:
            f.write(f"{seed} {spp}\n")
        return super().render(scene, spp, seed, checkpoints)


class Clocked(SeededNoise):
    """Seeded noise that reports a clock of its own, not the wall's: OVERHEAD_S of set-up plus PER_SPP_S per
    sample (both exact in binary). The spp a time budget buys is then exact whatever the machine's load."""

    name = "clocked"
    OVERHEAD_S, PER_SPP_S = 0.25, 0.0625

    def render(self, scene, spp, seed, checkpoints=()):
        result = super().render(scene, spp, seed, checkpoints)
        result.time_s = self.OVERHEAD_S + self.PER_SPP_S * spp
        return result


class Stalled(SeededNoise):
    """Reports a 1-spp render as slower than a 4-spp one (1 s against 0.5 s), as a render stalled by a busy
    machine reads: a time budget's calibration must not take the difference for the per-sample cost."""

    name = "stalled"

    def render(self, scene, spp, seed, checkpoints=()):
        result = super().render(scene, spp, seed, checkpoints)
        result.time_s = 1.0 if spp == 1 else 0.125 * spp
        return result


class ScaledMitsubaNoise(FlatGrey):
    """The stored reference plus noise of the reference's own model, times SCALE: unbiased when SCALE is 1.

    Lets the gate be tested without rendering: its noise is exactly what the
    agreement test assumes, and SCALE != 1 is a known bias.
    """

    name = "reference-noise"
    SCALE = 1.0

    def render(self, scene, spp, seed, checkpoints=()):
        from cornell_harness.store.references import load_reference

        ref = load_reference(scene)
        rng = np.random.default_rng(seed)
        var = ref.variance.astype(np.float64) * ref.spp / spp
        img = (ref.image + np.sqrt(var) * rng.standard_normal(ref.image.shape)) * self.SCALE
        return RenderResult(img.astype(np.float32), 0.01, spp, seed, variance=var.astype(np.float32))


class Biased1Percent(ScaledMitsubaNoise):
    name = "biased-1pct"
    SCALE = 0.99


class RegionScaledNoise(ScaledMitsubaNoise):
    """The reference plus its own model's noise, with one named region (REGION) times REGION_SCALE: a bias
    confined to a region, as a correct renderer with one wrong light path has. SCALE_ENV, when set in the
    environment, replaces REGION_SCALE (for a command-line test)."""

    name = "region-scaled-noise"
    features = ALL | {"sphere", "mirror", "dielectric"}
    REGION, REGION_SCALE = "glass-shadow", 1.10
    SCALE_ENV = "CBOX_TEST_REGION_SCALE"

    def render(self, scene, spp, seed, checkpoints=()):
        from cornell_harness.evaluate.regions import region_masks

        result = super().render(scene, spp, seed, checkpoints)
        scale = float(os.environ.get(self.SCALE_ENV, self.REGION_SCALE))
        mask = region_masks(scene)[self.REGION]
        result.image[mask] *= scale
        result.variance[mask] *= scale * scale
        return result


class ProgressiveNoise(ScaledMitsubaNoise):
    """The reference plus its own model's noise, rendered progressively: each pass (doubling, cut at the
    checkpoints) adds independent noise, so a checkpoint is the mean so far, as a real progressive renderer's.
    It ``stops_early``: ``stop`` sees each checkpoint and may end the render there. REGION (None: the whole
    image) is scaled by 1 + BIAS (BIAS_ENV, when set in the environment, replaces it). ``samples`` counts the
    samples per pixel rendered, over all calls, so a test can see what a stop saved."""

    name = "progressive-noise"
    features = ALL | {"sphere", "mirror", "dielectric"}
    stops_early = True
    REGION, BIAS, BIAS_ENV = None, 0.0, "CBOX_TEST_BIAS"
    samples = 0

    def render(self, scene, spp, seed, checkpoints=(), stop=None):
        from cornell_harness.adapters.api import Checkpoint, spp_passes
        from cornell_harness.evaluate.regions import region_masks
        from cornell_harness.store.references import load_reference

        ref = load_reference(scene)
        scale = np.ones(ref.image.shape[:2])
        bias = float(os.environ.get(self.BIAS_ENV, self.BIAS))
        scale[region_masks(scene)[self.REGION] if self.REGION else slice(None)] += bias
        rng = np.random.default_rng(seed)
        total, done, shots = np.zeros(ref.image.shape), 0, []
        sd = np.sqrt(ref.variance.astype(np.float64) * ref.spp)  # one sample's spread
        for n in spp_passes(spp, spp, checkpoints):
            total += n * ref.image + np.sqrt(n) * sd * rng.standard_normal(ref.image.shape)
            done += n
            type(self).samples += n
            image = (total / done * scale[..., None]).astype(np.float32)
            if done in checkpoints:
                shots.append(Checkpoint(done, image, 0.01 * done, cpu_time_s=0.01 * done))
                if stop is not None and done < spp and stop(shots[-1]):
                    break
        var = (sd ** 2 / done * scale[..., None] ** 2).astype(np.float32)
        return RenderResult(image, 0.01 * done, done, seed, shots, variance=var, cpu_time_s=0.01 * done)


class RegionProgressiveNoise(ProgressiveNoise):
    """:class:`ProgressiveNoise` with ``glass-shadow`` biased by 10% (the caustic scene's hardest region)."""

    name = "region-progressive-noise"
    REGION, BIAS = "glass-shadow", 0.10


class StopsNever(ProgressiveNoise):
    """:class:`ProgressiveNoise` that cannot stop early (declares nothing): renders its whole budget."""

    name = "stops-never"
    stops_early = False

    def render(self, scene, spp, seed, checkpoints=()):
        return super().render(scene, spp, seed, checkpoints)


class UnderstatesItsResult(ProgressiveNoise):
    """:class:`ProgressiveNoise` whose returned result reports a variance 4 times too small; its checkpoints
    carry none, so only the result's variance can tell."""

    name = "understates-its-result"

    def render(self, scene, spp, seed, checkpoints=(), stop=None):
        result = super().render(scene, spp, seed, checkpoints, stop)
        result.variance = result.variance / 4
        return result


class BrokenPixels(FlatGrey):
    """Grey with one NaN, one +Inf and one negative pixel: what ``cbox stress`` must catch."""

    name = "broken-pixels"

    def render(self, scene, spp, seed, checkpoints=()):
        img = np.full((scene.camera.height, scene.camera.width, 3), 0.25, dtype=np.float32)
        flat = img.reshape(-1, 3)
        flat[0, 0] = np.nan
        flat[-1, 1] = -0.5
        if len(flat) > 2:
            flat[1, 2] = np.inf
        return RenderResult(img, 0.001, spp, seed)


class Slow(FlatGrey):
    """Sleeps far past any stress time bound before it returns."""

    name = "slow"

    def render(self, scene, spp, seed, checkpoints=()):
        import time

        time.sleep(120)
        return super().render(scene, spp, seed, checkpoints)


class MemoryHog(FlatGrey):
    """Touches 1 GiB of memory before it returns: over a lowered stress memory bound."""

    name = "memory-hog"
    #: Seconds it holds the memory: far past any load's delay, so a kill before it ends is the memory bound's.
    SLEEP_S = 300.0

    def render(self, scene, spp, seed, checkpoints=()):
        import time

        hog = np.ones(1 << 27)  # 1 GiB of float64, every page touched
        time.sleep(self.SLEEP_S)
        del hog
        return super().render(scene, spp, seed, checkpoints)


class Tunable(SeededNoise):
    """Seeded noise around ``level`` (a declared setting), records the settings it was handed."""

    name = "tunable"
    settings = (Setting("level", float, 0.25, "mean radiance of the image", low=0.0, high=10.0),
                Setting("mode", str, "plain", "a word setting", choices=("plain", "fancy")))

    def render(self, scene, spp, seed, checkpoints=(), settings=None):
        result = super().render(scene, spp, seed, checkpoints)
        result.image = result.image - 0.25 + settings["level"]
        result.info["seen_settings"] = dict(settings)
        return result


class LyingVariance(FlatGrey):
    """The reference plus noise of its own model, times ``scale``, reporting ``variance_factor`` × its variance.

    The defaults are issue 9's case: 1% too dark and claiming 100 times the
    variance it has, which hides the bias from the agreement test (its z-scores
    shrink tenfold); the variance check must catch it. ``variance_factor = 1``
    is an honest renderer.
    """

    name = "lying-variance"
    settings = (Setting("scale", float, 0.99, "factor on the image (1: unbiased)", low=0.0, high=10.0),
                Setting("variance_factor", float, 100.0, "reported variance / true variance", low=1e-6, high=1e6))

    def render(self, scene, spp, seed, checkpoints=(), settings=None):
        from cornell_harness.store.references import load_reference

        ref = load_reference(scene)
        rng = np.random.default_rng(seed)
        var = ref.variance.astype(np.float64) * ref.spp / spp
        img = (ref.image + np.sqrt(var) * rng.standard_normal(ref.image.shape)) * settings["scale"]
        reported = var * settings["scale"] ** 2 * settings["variance_factor"]
        return RenderResult(img.astype(np.float32), 0.01, spp, seed, variance=reported.astype(np.float32))


class HotPixel(FlatGrey):
    """The reference plus noise of its own model, with pixel (``x``, ``y``) times ``factor`` in every channel.

    A bug after the film's statistics (e.g. a pixel written twice in a
    post-process): the reported variance is the noise's, unchanged at that
    pixel. ``factor = 1`` is an honest renderer.
    """

    name = "hot-pixel"
    settings = (Setting("x", int, 20, "column of the hot pixel", low=0),
                Setting("y", int, 128, "row of the hot pixel", low=0),
                Setting("factor", float, 2.0, "factor on that pixel", low=0.0, high=1e6))

    def render(self, scene, spp, seed, checkpoints=(), settings=None):
        from cornell_harness.store.references import load_reference

        ref = load_reference(scene)
        rng = np.random.default_rng(seed)
        var = ref.variance.astype(np.float64) * ref.spp / spp
        img = ref.image + np.sqrt(var) * rng.standard_normal(ref.image.shape)
        img[settings["y"], settings["x"]] *= settings["factor"]
        return RenderResult(img.astype(np.float32), 0.01, spp, seed, variance=var.astype(np.float32))


class ShrinkingBias(FlatGrey):
    """The stored reference times 1 + 1/√``photons``: consistent, its error falls with its photon count only.

    As photon mapping's: more spp at a fixed photon count leaves the bias
    where it is (MSE ∝ 1/photons, independent of spp).
    """

    name = "shrinking-bias"
    estimator = "consistent"
    settings = (Setting("photons", int, 100, "photons: the relative bias is 1/√photons", low=1),)

    def render(self, scene, spp, seed, checkpoints=(), settings=None):
        from cornell_harness.store.references import load_reference

        img = load_reference(scene).image * (1.0 + 1.0 / np.sqrt(settings["photons"]))
        return RenderResult(img.astype(np.float32), 0.01, spp, seed)


class BadEstimator(FlatGrey):
    """Declares an estimator that is not one of the three: refused when loaded."""

    name = "bad-estimator"
    estimator = "unbaised"


class LoggedNoise(SeededNoise):
    """Seeded noise that logs ``start PID SEED`` and ``end PID SEED`` to $CBOX_TEST_RENDER_LOG around a sleep of
    $CBOX_TEST_RENDER_SLEEP seconds: a test can kill the process rendering a cell while it renders. A process
    whose PID is a line of the file $CBOX_TEST_RENDER_HOLD_PIDS sleeps HOLD_S instead: held mid-cell until killed,
    however late the kill."""

    name = "logged-noise"
    HOLD_S = 600.0

    def render(self, scene, spp, seed, checkpoints=()):
        import os
        import time

        def log(what):
            with open(os.environ["CBOX_TEST_RENDER_LOG"], "a") as f:
                f.write(f"{what} {os.getpid()} {seed}\n")

        log("start")
        hold = os.environ.get("CBOX_TEST_RENDER_HOLD_PIDS", "")
        held = bool(hold) and os.path.exists(hold) and str(os.getpid()) in open(hold).read().split()
        time.sleep(self.HOLD_S if held else float(os.environ.get("CBOX_TEST_RENDER_SLEEP", "0")))
        log("end")
        return super().render(scene, spp, seed, checkpoints)


class SeededShrinkingBias(FlatGrey):
    """The stored reference times 1 + ``offset`` + 1/``photons`` + noise: consistent for ``offset`` = 0, with a
    bias that does not vanish otherwise.

    The noise is a per-seed factor shared by every photon count (as a photon
    mapper's camera samples are: one seed's efforts share them) of standard
    deviation 0.003, plus 0.001 drawn anew per (seed, photons): what the gate's
    bias limit t-tests over seeds.
    """

    name = "seeded-shrinking-bias"
    estimator = "consistent"
    settings = (Setting("photons", int, 100, "photons: the relative bias is 1/photons", low=1),
                Setting("offset", float, 0.0, "a relative bias that more photons do not remove", low=-0.5, high=0.5))

    def render(self, scene, spp, seed, checkpoints=(), settings=None):
        from cornell_harness.store.references import load_reference

        shared = np.random.default_rng(seed).normal(0.0, 0.003)
        own = np.random.default_rng([seed, settings["photons"]]).normal(0.0, 0.001)
        scale = 1.0 + settings["offset"] + 1.0 / settings["photons"] + shared + own
        return RenderResult((load_reference(scene).image * scale).astype(np.float32), 0.01, spp, seed)


class Jittery(Clocked):
    """Clocked whose clock runs slow or fast by turns: each pair of renders (a time budget's 1-spp and 4-spp
    calibration) reads FACTORS[k % 3] times Clocked's time, k counting pairs; the image is Clocked's, the same
    for the same seed. Each render appends "NAME SPP SEED" to $CBOX_TEST_RENDER_LOG when it is set (the order
    renderers ran in). Repeated timings then spread, exactly, whatever the machine's load. ``calls`` counts
    renders per class (reset it in an in-process test)."""

    name = "jittery"
    FACTORS = (1.0, 1.25, 0.8)
    calls = 0

    def render(self, scene, spp, seed, checkpoints=()):
        import os

        result = super().render(scene, spp, seed, checkpoints)
        result.time_s *= self.FACTORS[(type(self).calls // 2) % 3]
        type(self).calls += 1
        if log := os.environ.get("CBOX_TEST_RENDER_LOG"):
            with open(log, "a") as f:
                f.write(f"{self.name} {spp} {seed}\n")
        return result


class JitteryToo(Jittery):
    """A second Jittery, with a count of its own: two renderers whose interleaving a test can read."""

    name = "jittery-too"
    calls = 0


class Unrepeatable(SeededNoise):
    """Seeded noise that is not repeatable: each render draws from a new seed (the seed plus a call count)."""

    name = "unrepeatable"
    calls = 0

    def render(self, scene, spp, seed, checkpoints=()):
        type(self).calls += 1
        result = super().render(scene, spp, seed + 1000 * type(self).calls, checkpoints)
        result.seed = seed
        return result
