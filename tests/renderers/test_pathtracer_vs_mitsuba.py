"""benchmarks/pathtracer_vs_mitsuba.py's arithmetic, on made-up rounds: medians, efficiency, the per-path gap.

The benchmark itself takes minutes and Mitsuba; what can go wrong without either is how it reduces its rounds
into the table BENCHMARKS.md shows, which is checked here against figures worked out by hand.
"""

from __future__ import annotations

import re

import pytest

pytest.importorskip("mitsuba")

from benchmarks import embree_floor  # noqa: E402
from benchmarks import pathtracer_vs_mitsuba as bench  # noqa: E402
from cornell_harness.scenes.library import resolve_scene  # noqa: E402

PATHS = 1_000_000


def made_up_round(k: int) -> dict:
    """A round whose figures grow with k, so that medians are the middle round's and means differ."""
    out = {("floor", b, *c): 10.0 * (1 + i) + k for b in embree_floor.BATCHES
           for i, c in enumerate(embree_floor.CONFIGS)}
    out |= {("ours", "camera"): 15.0 + k, ("ours", "bounce"): 80.0 + k,
            ("mitsuba", "camera"): 12.0 + k, ("mitsuba", "bounce"): 60.0 + k}
    out["render", "ours", bench.OURS[0]] = (2.0 + k, 1.0 + k, 4e-5 * (1 + k), 6_000_000)
    out["render", "mitsuba", bench.MITSUBA[0]] = (1.0 + k, 0.5 + k, 2e-5 * (1 + k), None)
    out["render", "ours", bench.OURS[1]] = (1.8 + k, 0.9 + k, 4e-5, 6_000_000)
    out["render", "mitsuba", bench.MITSUBA[1]] = (0.9 + k, 0.45 + k, 8e-5, None)
    out |= {("loop", s): {"whole": 900.0 + k, "embree": 400.0 + k, "rest": 500.0} for s in bench.OURS}
    return out


def test_the_rounds_reduce_to_medians_and_the_mse_to_its_mean():
    s = bench.summarise([made_up_round(k) for k in range(3)], PATHS)
    ours = s["renders"]["ours", bench.OURS[0]]
    assert (ours["wall"], ours["cpu"]) == (3.0, 2.0)  # the middle round's
    assert ours["mse"] == pytest.approx(8e-5)  # (4 + 8 + 12) / 3 e-5
    assert ours["eff_cpu"] == pytest.approx(1 / (8e-5 * 2.0)) and ours["ns_path"] == pytest.approx(2000.0)
    assert s["rays_per_path"] == 6.0 and s["query"]["ours", "camera"] == 16.0
    assert s["floors"]["camera", "robust"] == 11.0  # the fastest call of the scene: the first configuration's


def test_the_per_path_gap_splits_into_its_rows():
    s = bench.summarise([made_up_round(k) for k in range(3)], PATHS)
    ctx = {"scene": resolve_scene("cornell-box"), "spp": 256, "variant": "llvm_ad_rgb", "device": "embree"}
    lines = bench.markdown(s, ctx, 3, (1.0, 1.0))
    gap = {line.split(" | ")[0].strip("| "): float(re.search(r"\*\*(-?\d+)\*\* \|$", line)[1])
           for line in lines if re.search(r"\*\*-?\d+\*\* \|$", line)}
    whole = gap.pop("whole path (render CPU ÷ paths)")
    assert whole == 2000 - 1500  # ours 2.0 s, Mitsuba 1.5 s of CPU for a million paths (the middle rounds)
    assert gap.pop("camera ray (its query)") == 16 - 13
    assert sum(gap.values()) == pytest.approx(whole - 3, abs=1)  # the other rays and the rest: the remainder
    assert any(line.startswith(f"| Mitsuba `{bench.MITSUBA[0]}` |") and line.endswith("**1.00×**, **1.00×** |")
               for line in lines)
