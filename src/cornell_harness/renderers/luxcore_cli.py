"""``cbox-luxcore``: render a LuxCore SDL scene (``cbox export --format luxcore``) with pyluxcore.

    cbox-luxcore DIR/scene.cfg --out x.exr --spp 64 --seed 3 [--threads 2] [--batches 8 --variance v.exr]

The render is split into batches, each halting at its spp (``batch.haltspp``; about, see
:func:`render_batch`) with its own
seed, ``pass_seed(seed, k)`` (:mod:`cornell_harness.adapters.api`) for batch k: the image is their
spp-weighted mean, and ``--variance`` the per-pixel variance of that mean estimated from the batch
means (at least two batches). Both are float32 EXR, top row first (LuxCore's film is bottom row
first and is flipped here). ``--batch-dir`` also writes each batch's mean image as ``.npy`` with a
``batches.json`` (spp, seed, seconds): how the ``luxcore`` renderer (:mod:`cornell_harness.renderers.luxcore`)
gets its checkpoints and variance.

pyluxcore aborts the process at interpreter exit once initialised (a GIL fatal error), and aborts if
OpenImageIO is imported after it: OpenImageIO is imported first, and the program ends with
``os._exit``. Errors are one line on stderr, exit 2. On success stdout's last line is
``cbox-luxcore: rendered N spp in S s`` (the batches' render time, without start-up and file writing).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from cornell_harness.adapters.api import default_threads, pass_seed
from cornell_harness.extras import install_line
from cornell_harness.renderers.batches import mean_and_variance

#: Exit status of a usage or input error (one line on stderr).
USAGE_ERROR = 2
#: Seconds between checks of a batch's halt condition.
POLL_S = 0.01


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cbox-luxcore",
        description="Render a LuxCore SDL scene (a scene.cfg written by `cbox export --format luxcore`) with "
                    "pyluxcore's PATHCPU engine; write the mean radiance as a float32 EXR, top row first.")
    p.add_argument("cfg", help="the exported scene.cfg (it names its scene.scn; paths resolve from its folder)")
    p.add_argument("--out", required=True, help="output EXR: the mean linear-sRGB radiance per pixel")
    p.add_argument("--spp", type=int, required=True, help="samples per pixel in all (each batch halts at its share "
                                                          "with batch.haltspp; LuxCore misses it by a sample or two "
                                                          "per pixel, see batches.json)")
    p.add_argument("--seed", type=int, required=True, help="the render's seed (non-negative); batch k is seeded "
                                                           "with pass_seed(seed, k), LuxCore's renderengine.seed")
    p.add_argument("--threads", type=int, default=None,
                   help="LuxCore render threads (native.threads.count); default $CBOX_THREADS or the CPU count")
    p.add_argument("--batches", type=int, default=1,
                   help="independent batches the spp is split into, as evenly as possible (default 1)")
    p.add_argument("--passes", default=None,
                   help="the batches' spp, comma-separated, summing to --spp (instead of --batches)")
    p.add_argument("--variance", default=None,
                   help="also write the per-pixel variance of the mean, from the batch means (needs 2+ batches)")
    p.add_argument("--batch-dir", default=None,
                   help="also write each batch's mean image (batch-K.npy, float64, top row first) and "
                        "batches.json (spp, seed, seconds of each) into this folder")
    return p


def batch_sizes(spp: int, batches: int, passes: str | None) -> list[int]:
    """The spp of each batch: ``passes`` as given, or ``spp`` split into ``batches`` near-equal parts."""
    if passes is not None:
        try:
            sizes = [int(x) for x in passes.split(",")]
        except ValueError:
            raise ValueError(f"--passes: expected comma-separated integers, got {passes!r}") from None
        if any(n < 1 for n in sizes) or sum(sizes) != spp:
            raise ValueError(f"--passes: expected positive integers summing to --spp {spp}, got {passes!r}")
        return sizes
    if not 1 <= batches <= spp:
        raise ValueError(f"--batches: expected 1 to --spp ({spp}), got {batches}")
    return [spp // batches + (k < spp % batches) for k in range(batches)]


def write_exr(path: str, image: np.ndarray) -> None:
    """An (H, W, 3) float32 EXR through OpenImageIO (the harness's own writer, cornell_harness.store.exr, is not
    importable from a renderer; OpenImageIO must be imported before pyluxcore, see the module docstring)."""
    import OpenImageIO as oiio

    img = np.ascontiguousarray(image, dtype=np.float32)
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.FLOAT)
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, spec) or not out.write_image(img):
        raise OSError(f"{path}: cannot write EXR: {oiio.geterror()}")
    out.close()


def render_batch(pyluxcore, props, n: int, seed: int, threads: int) -> tuple[np.ndarray, np.ndarray]:
    """One batch of ``n`` spp seeded ``seed``: the film's mean radiance (H, W, 3), top row first, and the
    samples each pixel got (H, W).

    LuxCore halts a batch on the film's total sample count, checked while its threads run, so a pixel
    gets about ``n`` samples, not exactly (measured: 15 to 17 at n = 16, with one thread or two), and
    which pixels get one more depends on thread timing: the image is the mean of each pixel's own
    samples (unbiased), and is not reproducible bit for bit. TILEPATHCPU, whose single pass gives an
    exact count, ignores ``renderengine.seed`` (measured: seeds 1 and 2 give the same image), so its
    batches would not be independent.
    """
    p = pyluxcore.Properties(props)
    p.Set(pyluxcore.Property("batch.haltspp", [n]))
    p.Set(pyluxcore.Property("batch.halttime", [0]))
    p.Set(pyluxcore.Property("renderengine.seed", [seed]))
    p.Set(pyluxcore.Property("native.threads.count", [threads]))
    p.Set(pyluxcore.Property("film.outputs.9.type", ["SAMPLECOUNT"]))  # how many samples each pixel got
    p.Set(pyluxcore.Property("film.outputs.9.filename", ["samplecount.exr"]))
    session = pyluxcore.RenderSession(pyluxcore.RenderConfig(p))
    session.Start()
    # The halt conditions are checked when the statistics are updated (WaitForDone alone never returns).
    while not session.HasDone():
        time.sleep(POLL_S)
        session.UpdateStats()
    session.Stop()
    film = session.GetFilm()
    w, h = film.GetWidth(), film.GetHeight()
    buf = np.zeros(w * h * 3, dtype=np.float32)
    film.GetOutputFloat(pyluxcore.FilmOutputType.RGB, buf)
    counts = np.zeros(w * h, dtype=np.uint32)
    film.GetOutputUInt(pyluxcore.FilmOutputType.SAMPLECOUNT, counts)
    return buf.reshape(h, w, 3)[::-1].astype(np.float64), counts.reshape(h, w)[::-1]


def run(args: argparse.Namespace) -> None:
    if args.spp < 1:
        raise ValueError(f"--spp: expected a positive integer, got {args.spp}")
    if args.seed < 0:
        raise ValueError(f"--seed: expected a non-negative integer, got {args.seed}")
    threads = default_threads() if args.threads is None else args.threads
    if threads < 1:
        raise ValueError(f"--threads: expected a positive integer, got {threads}")
    sizes = batch_sizes(args.spp, args.batches, args.passes)
    if args.variance and len(sizes) < 2:
        raise ValueError("--variance needs at least 2 batches (--batches or --passes)")
    cfg = Path(args.cfg).resolve()
    if not cfg.is_file():
        raise ValueError(f"{args.cfg}: no such file")
    out = [str(Path(p).resolve()) if p else None for p in (args.out, args.variance, args.batch_dir)]
    for path in out[:2]:
        if path and not path.lower().endswith(".exr"):
            raise ValueError(f"{path}: images are written as OpenEXR; give a name ending in .exr")
    import OpenImageIO  # noqa: F401  (before pyluxcore: importing it after pyluxcore aborts)
    import pyluxcore

    os.chdir(cfg.parent)  # the .cfg names its .scn, and the .scn its PLY files, relative to this folder
    pyluxcore.Init(lambda message: None)  # LuxCore logs every step to stdout otherwise
    props = pyluxcore.Properties(str(cfg))
    means, record = [], []
    for k, n in enumerate(sizes):
        seed = pass_seed(args.seed, k)
        t0, cpu0 = time.perf_counter(), time.process_time()  # process time: LuxCore's threads included
        mean, counts = render_batch(pyluxcore, props, n, seed, threads)
        means.append(mean)
        record.append({"spp": n, "seed": seed, "seconds": time.perf_counter() - t0,
                       "cpu_seconds": time.process_time() - cpu0,
                       "pixel_samples": [int(counts.min()), int(counts.max())], "samples": int(counts.sum())})
    mean, variance = mean_and_variance(means, sizes)
    # One line a renderer file's `time` regex can read: the render proper, without start-up and writing.
    print(f"cbox-luxcore: rendered {args.spp} spp in {sum(r['seconds'] for r in record):.3f} s", flush=True)
    write_exr(out[0], mean)
    if out[1]:
        write_exr(out[1], variance)
    if out[2]:
        folder = Path(out[2])
        folder.mkdir(parents=True, exist_ok=True)
        for k, m in enumerate(means):
            np.save(folder / f"batch-{k}.npy", m)
        (folder / "batches.json").write_text(json.dumps({"threads": threads, "batches": record}, indent=1))


def main(argv: list[str] | None = None) -> None:
    """Entry point; always leaves through ``os._exit`` (pyluxcore aborts at a normal interpreter exit)."""
    try:
        args = parser().parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2, argparse's one line already printed)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(int(e.code or 0))
    status = 0
    try:
        run(args)
    except ImportError as e:  # a core install, without the [luxcore] extra
        print(f"cbox-luxcore: {e}: {install_line(['luxcore'])}", file=sys.stderr)
        status = USAGE_ERROR
    except (ValueError, OSError, RuntimeError) as e:
        print(f"cbox-luxcore: {' '.join(str(e).split())}", file=sys.stderr)
        status = USAGE_ERROR
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


if __name__ == "__main__":
    main()
