"""A consistent renderer's checks in a gate config: the ``consistency`` and ``bias_limit`` tables, parsed and
checked (the config's format and meaning: :mod:`cornell_harness.gate.config`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cornell_harness.evaluate.registry import HIGHER_IS_BETTER, IMAGE_METRICS, region_metric
from cornell_harness.gate.config_fields import GateConfigError, band, check_metrics, check_names

#: The signed error a bias limit extrapolates, image-wide or as a region's ``region.<region>.<metric>``.
BIAS_LIMIT_METRIC = "mean_radiance_rel_error"
#: Image metrics a consistency check may follow: errors, which fall towards 0 (not PSNR or SSIM).
CONSISTENCY_METRICS = tuple(m for m in IMAGE_METRICS if m not in HIGHER_IS_BETTER)


@dataclass
class Consistency:
    """A consistent renderer's error must fall with its budget: a slope band, or a ratio to a smaller budget."""

    metric: str = "mse"
    slope: tuple[float, float] | None = None
    from_spp: int | None = None  # first checkpoint of the slope; None: spp // 16, at least 1
    max_ratio: float | None = None
    smaller_spp: int | None = None  # the smaller render's spp; None: the expectation's
    smaller_settings: dict = field(default_factory=dict)  # replace the expectation's (validated at resolve)

    def first_spp(self, spp: int) -> int:
        """The slope's first checkpoint for a render of ``spp``."""
        return self.from_spp if self.from_spp is not None else max(1, spp // 16)


@dataclass
class BiasLimit:
    """Renders at several efforts over seeds, each seed's error extrapolated to infinite effort and t-tested."""

    efforts: tuple[int, ...]
    setting: tuple[str, ...] = ()  # settings set to each effort; () : the efforts are spp checkpoints
    rate: float = 1.0
    seeds: int = 8
    spp: int = 16  # with ``setting``: the spp of every render
    metrics: tuple[str, ...] = (BIAS_LIMIT_METRIC,)
    tolerance: dict = field(default_factory=dict)  # metric -> |limit| allowed (default 0)
    margin: dict = field(default_factory=dict)  # metric -> equivalence margin: three verdicts where one is set

    def seed_list(self, seed: int) -> list[int]:
        """The seeds of an expectation at ``seed``: k·seed .. k·seed + k − 1 (disjoint sets for distinct seeds)."""
        return [self.seeds * seed + j for j in range(self.seeds)]


def parse_bias_limit(path: Path, t: dict, w: str) -> BiasLimit | None:
    """The ``bias_limit`` table of an expectation (None without one); see the module docstring."""
    if "bias_limit" not in t:
        return None
    b, where = t["bias_limit"], f"{w}bias_limit."
    efforts = b["efforts"]
    if efforts != sorted(set(efforts)):
        raise GateConfigError(path, f"{where}efforts", "expected two or more increasing integers >= 1 (photon "
                              "counts with setting, else spp checkpoints)")
    setting = b.get("setting", [])
    setting = [setting] if isinstance(setting, str) else setting
    if "spp" in b and not setting:
        raise GateConfigError(path, f"{where}spp", "goes with setting; without it the efforts are the spps")
    metrics = b.get("metrics", [BIAS_LIMIT_METRIC])
    for m in metrics:
        parts = region_metric(m)
        if (m if parts is None else parts[1]) != BIAS_LIMIT_METRIC or (parts is not None and not parts[0]):
            raise GateConfigError(path, f"{where}metrics", f"{m!r}: a bias limit extrapolates a signed mean "
                                  f"error: {BIAS_LIMIT_METRIC!r} or 'region.<region>.{BIAS_LIMIT_METRIC}'")
    if len(set(metrics)) != len(metrics):
        raise GateConfigError(path, f"{where}metrics", "a metric is named twice")
    tolerance, margin = b.get("tolerance", {}), b.get("margin", {})
    check_names(path, tolerance, metrics, f"{where}tolerance.", "metric (not in metrics)")
    check_names(path, margin, metrics, f"{where}margin.", "metric (not in metrics)")
    for key, value in margin.items():
        if value <= tolerance.get(key, 0.0):
            raise GateConfigError(path, f"{where}margin.{key}", f"{value:g} must be above its tolerance "
                                  f"({tolerance.get(key, 0.0):g}): no interval could pass and not fail")
    return BiasLimit(tuple(efforts), tuple(setting), float(b.get("rate", 1.0)), b.get("seeds", 8), b.get("spp", 16),
                     tuple(metrics), {k: float(v) for k, v in tolerance.items()},
                     {k: float(v) for k, v in margin.items()})


def parse_consistency(path: Path, t: dict, w: str, spp: int | None) -> Consistency | None:
    """The ``consistency`` table of an expectation (None without one); see the module docstring."""
    if "consistency" not in t:
        return None
    c, where = t["consistency"], f"{w}consistency."
    metric = c.get("metric", "mse")
    if metric in HIGHER_IS_BETTER:
        raise GateConfigError(path, f"{where}metric", f"{metric!r} is higher-is-better; a consistency check "
                              "follows an error that falls towards 0 (e.g. mse, rel_mse)")
    check_metrics(path, [metric], CONSISTENCY_METRICS, f"{where}metric: ")
    if ("slope" in c) == ("max_ratio" in c):
        raise GateConfigError(path, f"{w}consistency", "give exactly one of slope = [low, high] (over the "
                              "render's checkpoints) or max_ratio = r with smaller = { spp = N, ... }")
    out = Consistency(metric)
    if "slope" in c:
        out.slope = band(path, c["slope"], f"{where}slope")
        if "smaller" in c:
            raise GateConfigError(path, f"{where}smaller", "goes with max_ratio, not with slope")
        if "from_spp" in c:
            out.from_spp = c["from_spp"]
            if spp is not None and out.from_spp >= spp:
                raise GateConfigError(path, f"{where}from_spp", f"must be >= 1 and below spp ({spp}): the slope "
                                      "needs two checkpoints")
        return out
    if "from_spp" in c:
        raise GateConfigError(path, f"{where}from_spp", "goes with slope, not with max_ratio")
    out.max_ratio = float(c["max_ratio"])
    out.smaller_spp, out.smaller_settings = _smaller(path, c, where, spp)
    return out


def _smaller(path: Path, c: dict, where: str, spp: int | None) -> tuple[int | None, dict]:
    """``smaller = { spp = N, <setting> = value, ... }``: its spp (None: the expectation's) and its settings."""
    small = c.get("smaller")
    if small is None:
        raise GateConfigError(path, f"{where}smaller", "max_ratio needs smaller = { spp = N, <setting> = value, "
                              "... }: the budget the full render's error is compared with")
    small_spp = small.get("spp")
    if small_spp is not None and spp is not None and small_spp > spp:
        raise GateConfigError(path, f"{where}smaller.spp", f"must be >= 1 and at most spp ({spp})")
    settings = {k: v for k, v in small.items() if k != "spp"}
    if not settings and (small_spp is None or small_spp == spp):
        raise GateConfigError(path, f"{where}smaller", "must lower the budget: a smaller spp and/or settings "
                              "(e.g. fewer photons)")
    return small_spp, settings
