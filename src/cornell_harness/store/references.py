"""The reference store: trusted images of each scene, with their variance.

``src/cornell_harness/references/<scene>/`` holds

- ``scene.toml``: the scene;
- ``reference.exr``: the reference, the mean of ``batches`` independent
  Mitsuba renders of ``batch_spp`` samples each (float32 linear sRGB);
- ``variance.exr``: per-pixel, per-channel variance *of that mean*, i.e. the
  unbiased sample variance of the batch images divided by ``batches``;
- ``noise.exr``: one more batch, independent of the reference (seed
  ``noise_seed``), kept as a sample of the renderer's real noise: its channel
  correlations and tails make the noise yardsticks of :mod:`cornell_harness.evaluate.noise`
  match real renders where a Gaussian model would not;
- ``provenance.json``: renderer, version, variant, spp, seeds, wall time, the
  scene's content hash, date, command line; and, under ``verified.<engine>``,
  the verdicts of ``cbox reference verify`` that ship with the reference.

An animated scene (:mod:`cornell_harness.scenes.animation`) has no reference of its own but one per distinct
frame: frames whose still scenes are the same but for the frame index (a light at rest) share the reference of the
earliest of them (:meth:`~cornell_harness.scenes.animation.Animation.reference_frame`), the reference of
``scene.at_frame(j)`` in ``frames/0012/`` of the same folder (for j = 12: the moving light's frames 12 to the last
read it). Its files are a still scene's, with the frame j in the provenance and its scene hash
``scene.at_frame(j)``'s (so a frame sharing it is checked against that hash), seeds that are the frame seeds
(:func:`cornell_harness.adapters.seeds.frame_seed`) of the still scene's, so the distinct frames' references are
independent of each other, and the image and noise stored as half floats (``pixel_types`` in the provenance;
:data:`cornell_harness.workflows.reference_build.HALF_LIMIT`). A frame's state does not include the frame count,
so an animation made longer keeps its frames' references.

Those stored references are read-only package data. What is built or recorded
for them goes to the same place in the user store
(:mod:`cornell_harness.store.home`), ``<home>/references/<scene>/``
(:func:`user_folder`):

- the reference of a scene derived by ``--set``
  (:mod:`cornell_harness.scenes.overrides`), in ``derived/<content hash>/``,
  with the same files but ``scene.toml`` (:func:`reference_folder`);
- ``verdicts.json``: the verdicts ``cbox reference verify`` records
  (:func:`record_verdict`), one per engine, each with the digest of the
  images it judged, so a verdict is shown only beside those images
  (:func:`recorded_verdicts`);
- a stored scene's own reference, where the package has none valid for the
  scene (a scene file edited in a checkout).

A scene file of the user's own, outside the stored references, keeps all of
these in its own folder instead, ``derived/`` and ``verdicts.json`` included.
A reference is looked for beside its scene file first, then in the user store
(:func:`reference_folders`): the stored reference of a stored scene is the
one every command reads while it is valid. A missing or stale reference is
refused with the command that builds it and about how long that takes, scaled
from the wall time a build recorded in provenance (:func:`build_seconds`).

References are built by :mod:`cornell_harness.workflows.reference_build`, with seeds from
:data:`REFERENCE_SEED_BASE` up, a range no user
run uses by default, so a test render never shares samples with its reference.
"""

from __future__ import annotations

import hashlib
import json
import shlex
import statistics
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cornell_harness.store.atomic import write_json_atomic
from cornell_harness.store.exr import ImageFileError, read_exr
from cornell_harness.store.home import user_home
from cornell_harness.scenes.animation import frame_folder, reference_still
from cornell_harness.scenes.library import references_root
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY

REFERENCE_SEED_BASE = 1_000_000_000
REFERENCE_FILE, VARIANCE_FILE, NOISE_FILE = "reference.exr", "variance.exr", "noise.exr"
PROVENANCE_FILE = "provenance.json"
#: The folder, beside a scene file, of the references of scenes derived from it by ``--set``.
DERIVED_FOLDER = "derived"
#: The user store's folder of what is built or recorded for the stored references (:func:`user_folder`).
USER_REFERENCES = "references"
#: The file of the verdicts ``cbox reference verify`` recorded for a reference (:func:`record_verdict`).
VERDICTS_FILE = "verdicts.json"
#: The spp ``cbox reference build`` is suggested with when no earlier build says better.
DEFAULT_SPP = 16384
#: Where a reference's provenance keeps the verdicts of ``cbox reference verify`` it ships with, one per engine.
VERIFIED_KEY = "verified"


class ReferenceError(RuntimeError):
    """A reference is missing, stale or inconsistent. ``str()`` says how to fix it."""


@dataclass
class Reference:
    image: np.ndarray  # (H, W, 3) float32
    variance: np.ndarray  # variance of the mean, (H, W, 3) float32
    noise: np.ndarray  # one independent batch of noise_spp samples, (H, W, 3) float32
    provenance: dict
    folder: Path
    quantity: str = DEFAULT_QUANTITY  # the scene's: what the images mean (cornell_harness.scenes.quantities)

    @property
    def spp(self) -> int:
        return int(self.provenance["spp"])

    @property
    def noise_spp(self) -> int:
        return int(self.provenance["noise_spp"])


def _beside_file(scene: Scene) -> Path:
    """The reference's folder beside ``scene``'s file: the file's folder or, for a scene derived by ``--set``,
    ``derived/<content hash>/`` in it; keyed by content, so the same overrides in any order or spelling
    share one reference, and one made for an older version of the file is never mistaken for current.
    A frame of an animated scene (``Scene.at_frame``) reads that of the frame it shares its reference with
    (:func:`~cornell_harness.scenes.animation.reference_still`), ``frames/0012/`` in that folder for frame 12."""
    folder = scene.path.parent
    if scene.overrides:
        folder = folder / DERIVED_FOLDER / scene.content_hash().removeprefix("sha256:")[:16]
    return folder if scene.frame is None else folder / frame_folder(reference_still(scene).frame)


def user_folder(folder: str | Path, home: str | Path | None = None) -> Path:
    """Where what belongs to the reference folder ``folder`` is written: ``folder`` itself, but for one among the
    stored references (read-only package data) the same place in the user store, ``<home>/references/...``."""
    try:
        inside = Path(folder).resolve().relative_to(references_root().resolve())
    except ValueError:
        return Path(folder)
    return user_home(home) / USER_REFERENCES / inside


def reference_folder(scene: Scene, home: str | Path | None = None) -> Path:
    """Where the reference of ``scene`` is built: beside its file, or in the user store for a stored scene."""
    return user_folder(_beside_file(scene), home)


def reference_folders(scene: Scene, home: str | Path | None = None) -> list[Path]:
    """Where the reference of ``scene`` is looked for, in order: beside its file (a stored scene's stored
    reference), then where it is built (:func:`reference_folder`), when that is elsewhere."""
    return list(dict.fromkeys([_beside_file(scene), reference_folder(scene, home)]))


def rebuild_command(scene: Scene, spp: int = DEFAULT_SPP, batches: int | None = None,
                    home: str | Path | None = None) -> str:
    """The ``cbox reference build`` command for ``scene`` (its stored name where it has one, its ``--set``, and
    the ``--home`` it was looked for with)."""
    stored = references_root() / scene.path.parent.name / "scene.toml"
    named = scene.path.exists() and stored.exists() and stored.samefile(scene.path)
    args = ["cbox", "reference", "build", "--scene", scene.path.parent.name if named else str(scene.path.parent)]
    for override in scene.overrides:
        args += ["--set", override]
    args += ["--frames", str(reference_still(scene).frame)] if scene.frame is not None else []
    args += ["--spp", str(spp)] + (["--batches", str(batches)] if batches else [])
    args += ["--home", str(home)] if home else []
    return " ".join(map(shlex.quote, args))


def build_seconds(prov: dict, width: int, height: int, spp: int) -> float | None:
    """Seconds a build of ``width`` x ``height`` pixels at ``spp`` takes, scaled by pixels × samples from the
    wall time, resolution and spp in a reference's provenance ``prov``; None when it lacks them."""
    try:
        w0, h0 = prov["resolution"]
        return float(prov["wall_time_s"]) * width * height * spp / (int(w0) * int(h0) * int(prov["spp"]))
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def _about(seconds: float) -> str:
    if seconds < 10:
        return f"{seconds:.1g} s" if seconds < 1 else f"{seconds:.0f} s"
    if seconds < 600:
        return f"{round(seconds, -1 if seconds >= 100 else 0):.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def _provenance_at(folder: Path) -> dict | None:
    try:
        prov = json.loads((folder / PROVENANCE_FILE).read_text())
    except (OSError, ValueError):
        return None
    return prov if isinstance(prov, dict) else None


def _median_cost() -> float | None:
    """The stored references' median build cost, in seconds per pixel-sample; None when none says."""
    stored = (_provenance_at(f.parent) for f in references_root().glob(f"*/{PROVENANCE_FILE}"))
    costs = [c for p in stored if p and (c := build_seconds(p, 1, 1, 1)) is not None]
    return statistics.median(costs) if costs else None


def _other_frame(scene: Scene) -> dict | None:
    """The provenance of another frame's reference beside a frame of an animated scene (the first, in frame
    order), where ``scene`` is such a frame and one is there; else None."""
    if scene.frame is None:
        return None
    folders = sorted(_beside_file(scene).parent.glob(f"*/{PROVENANCE_FILE}"))
    return next((p for f in folders if (p := _provenance_at(f.parent)) is not None), None)


def _build_hint(scene: Scene, folder: Path, home: str | Path | None = None) -> str:
    """The command that builds ``scene``'s reference into ``folder``, and about how long it takes.

    The yardstick is the build this one replaces (its spp and batches are
    kept), else, for a derived scene, its base's reference, else, for a frame of an animated scene, another
    frame's, else the median cost of the stored references.
    """
    cam = scene.camera
    own = _provenance_at(folder)
    prov = own or (_provenance_at(scene.path.parent) if scene.overrides else None) or _other_frame(scene)
    if prov is None:
        if (cost := _median_cost()) is None:
            return rebuild_command(scene, home=home)
        return (f"{rebuild_command(scene, home=home)} (about {_about(cost * cam.width * cam.height * DEFAULT_SPP)}, from the "
                f"stored references' median cost of {cost * 1e6:.2g} µs per pixel-sample; the scene's may differ)")
    spp, batches = int(prov.get("spp", DEFAULT_SPP)), prov.get("batches")
    command = rebuild_command(scene, spp, batches if isinstance(batches, int) else None, home)
    if (seconds := build_seconds(prov, cam.width, cam.height, spp)) is None:
        return command
    source = "the last build" if own else f"the reference of {prov.get('scene') or scene.path.parent.name}" + (
        f" frame {prov['frame']}" if "frame" in prov else "")
    w0, h0 = prov["resolution"]
    machine = ", ".join(str(prov.get("machine", "")).split(", ")[:2])  # "x86_64, 2 CPUs"
    notes = f"; scaled to {cam.width}x{cam.height}" if [w0, h0] != [cam.width, cam.height] else ""
    if prov.get("max_depth", scene.max_depth) != scene.max_depth:
        notes += (f"; max_depth {scene.max_depth} instead of {prov['max_depth']} changes the cost per sample, "
                  "so this is only an estimate")
    return (f"{command} (about {_about(seconds)}: {source} took {float(prov['wall_time_s']):.0f} s at {w0}x{h0}, "
            f"{spp} spp{f' on {machine}' if machine else ''}{notes})")


def load_reference(scene: Scene, folder: Path | None = None, home: str | Path | None = None) -> Reference:
    """The reference of ``scene``: in ``folder``, else the first valid one of :func:`reference_folders`; refuse
    one built from different content, saying how to build it (into :func:`reference_folder`).

    An animated scene has one reference per frame: that of ``scene.at_frame(i)``, shared by frames at the same
    state; the animated scene itself has none (refused, saying so)."""
    if scene.animation is not None:
        raise ReferenceError(f"{scene.path}: animation: {scene.name} is animated ({scene.frame_count} frames) and has "
                             "one reference per frame, the reference of scene.at_frame(i); build them with: "
                             f"{rebuild_command(scene, home=home)}")
    if folder:
        return _load(scene, Path(folder), home)
    folders = reference_folders(scene, home)
    problem = None
    for candidate in (f for f in folders if (f / PROVENANCE_FILE).exists()):
        try:
            return _load(scene, candidate, home)
        except ReferenceError as e:
            problem = problem or e  # the first one's, the stored reference's where there is one
    raise problem or _missing(scene, folders[-1], home)


def _missing(scene: Scene, folder: Path, home: str | Path | None) -> ReferenceError:
    derived = (f"; the stored reference of {scene.path.parent.name} is for the scene without --set"
               if scene.overrides else "")
    frame = "" if scene.frame is None else f" frame {scene.frame}"
    if (shared := reference_still(scene).frame) != scene.frame:
        frame += f" (which shares frame {shared}'s reference)"
    return ReferenceError(f"{folder / PROVENANCE_FILE}: no reference for scene {scene.name!r}{frame}{derived}; build it "
                          f"with: {_build_hint(scene, folder, home)}")


def _load(scene: Scene, folder: Path, home: str | Path | None) -> Reference:
    """The reference in ``folder``, checked against ``scene``."""
    prov_path = folder / PROVENANCE_FILE
    if not prov_path.exists():
        raise _missing(scene, folder, home)
    try:
        prov = json.loads(prov_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ReferenceError(f"{prov_path}: unreadable ({e}); rebuild with: {_build_hint(scene, folder, home)}") from None
    expected = reference_still(scene).content_hash()  # a frame at rest: the hash of the frame it shares with
    if prov.get("scene_hash") != expected:
        raise ReferenceError(
            f"{prov_path}: reference was built for scene hash {prov.get('scene_hash')}, but {scene.name} "
            f"({scene.path}) now hashes to {expected}; rebuild it with: {_build_hint(scene, folder, home)}"
        )
    try:
        image, variance, noise = (read_exr(folder / f) for f in (REFERENCE_FILE, VARIANCE_FILE, NOISE_FILE))
    except ImageFileError as e:
        raise ReferenceError(f"{e}; rebuild with: {_build_hint(scene, folder, home)}") from None
    shape = (scene.camera.height, scene.camera.width, 3)
    if not image.shape == variance.shape == noise.shape == shape:
        raise ReferenceError(
            f"{folder}: reference images are {image.shape[1]}x{image.shape[0]}, scene is {shape[1]}x{shape[0]}; "
            f"rebuild with: {_build_hint(scene, folder, home)}"
        )
    return Reference(image, variance, noise, prov, folder, scene.quantity)


def reference_digest(folder: str | Path) -> str:
    """``sha256:...`` of the reference's image and variance files in ``folder``: what a verdict judged."""
    digest = hashlib.sha256()
    for name in (REFERENCE_FILE, VARIANCE_FILE):
        digest.update((Path(folder) / name).read_bytes())
    return f"sha256:{digest.hexdigest()}"


def _verdicts_at(path: Path) -> dict:
    try:
        verdicts = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return verdicts if isinstance(verdicts, dict) else {}


def record_verdict(folder: str | Path, record: dict, home: str | Path | None = None) -> Path:
    """Record ``record`` as the verdict of its engine on the reference in ``folder``, in :data:`VERDICTS_FILE` of
    :func:`user_folder` (atomically), with the digest of the images it judged; the file written.

    The reference's own files are not touched, the package's stored ones included. The file's other engines'
    verdicts are kept as they are, read just before writing."""
    path = user_folder(folder, home) / VERDICTS_FILE
    verdicts = _verdicts_at(path)
    verdicts[record["engine"]] = {**record, "reference_digest": reference_digest(folder)}
    write_json_atomic(path, verdicts)
    return path


def recorded_verdicts(folder: str | Path, home: str | Path | None = None) -> dict:
    """The verdicts recorded (:func:`record_verdict`) on the reference in ``folder`` as it is now, by engine:
    those of the images it holds; one recorded on images since rebuilt judged others, and is left out."""
    verdicts = _verdicts_at(user_folder(folder, home) / VERDICTS_FILE)
    if not verdicts:
        return {}
    digest = reference_digest(folder)
    return {engine: r for engine, r in verdicts.items()
            if isinstance(r, dict) and r.get("reference_digest") == digest}


def stored_verdicts(provenance: dict) -> dict:
    """The verdicts a reference's provenance carries (``verified.<engine>``), by engine."""
    verified = provenance.get(VERIFIED_KEY)
    return dict(verified) if isinstance(verified, dict) else {}


def verdict_line(verified: dict) -> str:
    """One line of verdicts by engine (:func:`stored_verdicts`, :func:`recorded_verdicts`):
    ``verified by luxcore: max |z| 1.9 (7 regions, 1024 spp)``, or ``not verified``."""
    if not verified:
        return "not verified"
    parts = []
    for engine, r in verified.items():
        z = r.get("max_abs_z")
        z_text = "inf" if z is None else f"{z:.1f}" if z < 100 else f"{z:.0f}"
        word = "verified by" if r.get("passed") else "DISAGREES with"
        n = len(r.get("regions", {}))
        parts.append(f"{word} {engine}: max |z| {z_text} ({n} region{'s' if n != 1 else ''}, {r.get('spp')} spp)")
    return "; ".join(parts)
