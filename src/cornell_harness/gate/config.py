"""The CI quality gate: expectations per (scene, renderer, budget), checked with stated error rates.

A gate config (TOML) lists expectations::

    alpha = 0.01                      # family-wise false-alarm rate per expectation (its statistical tests)
    baseline = "gate-baseline.json"   # optional, relative to this file; once named it must exist
                                      # (cbox gate --update-baseline creates it)
    regression_margin = 0.05          # relative; a metric worse than baseline by more fails
    regression_metrics = ["delta_e2000_mean", "rel_mse_trimmed", "ssim"]
    time_limit = "30m"                # default per expectation: a render past it is killed and fails

    [[expect]]
    scene = "cornell-box"             # stored name or path
    renderer = "pathtracer"           # registered name or package.module:Class
    spp = 256                         # budget: spp, or time = "10s" (spp is then calibrated), or max_spp
    seed = 0                          # fixed: the same commit gives the same verdict
    unbiased = true                   # agreement, variance and outlier tests against the reference (below)
    margin = { image = 0.005 }        # optional: pass / fail / inconclusive on bias intervals (gate/margins.py)
    tile = 16
    slope = [-0.55, -0.45]            # optional: RMSE-vs-spp slope over checkpoints spp/64 .. spp
    max = { delta_e2000_mean = 3.0 }  # optional budgets on any harness metric ...
    min = { ssim = 0.7 }
    abs_max = { mean_radiance_rel_error = 0.3, "region.caustic.mean_radiance_rel_error" = 0.05 }  # ... or region's
    consistency = { metric = "mse", slope = [-0.9, -0.4] }  # optional, for a consistent renderer (below)
    bias_limit = { efforts = [62500, 250000], setting = ["global_photons"], rate = 1 }  # optional (below)
    settings = { rr_depth = 3 }       # optional: the renderer's settings (`cbox renderers --settings`)
    time_limit = "10m"                # optional: kill the render after this long (default: time_limit above)
    finite_only = true                # only to allow an expectation with no accuracy check (see below)

A *sequential* expectation gives ``max_spp = N`` (and optionally ``first_spp``, default N // 16) in place of
``spp``: with ``unbiased = true`` and a ``margin`` it looks at spp doubling from ``first_spp`` up to
``max_spp`` and stops at the first look with a verdict, its error rates spent over the looks
(:mod:`cornell_harness.gate.sequential`; the config's ``beta`` and ``spending``).

The config is strict (``src/cornell_harness/schemas/gate.schema.json``, every key in ``docs/formats.md``): an
unknown key or metric is a config error (exit 2) with a did-you-mean before anything renders, so a misspelt key
never turns a gate green; so is a budget outside its metric's range, or a ``min`` above its ``max``. An
expectation must check accuracy (``unbiased``, a budget, a slope or ``consistency``) unless it says
``finite_only = true``. A budget may name a region's metric, ``"region.<region>.<metric>"``
(:data:`cornell_harness.evaluate.registry.REGION_CHECK_METRICS`); the region is checked against the scene's
when the gate resolves it (:mod:`cornell_harness.gate.run`). Baseline regression checks stay image-wide.

A ``max`` budget on a temporal metric (:data:`cornell_harness.evaluate.registry.TEMPORAL_METRICS`: flicker, lag,
ghosting) makes the expectation one on an animated scene's frames (:attr:`Expectation.frames`): every frame is
rendered at ``spp`` and scored against its own reference (:func:`cornell_harness.workflows.sequence_run.sequence_record`),
its other budgets being means over frames; checks of one still render (``unbiased``, ``slope``, ``consistency``,
``bias_limit``, a ``time`` or ``max_spp`` budget) and region budgets do not go with it.

``unbiased = true`` runs three statistical tests against the reference: ``agreement`` (tiled z-tests,
:mod:`cornell_harness.evaluate.agreement`), ``variance`` (the renderer's own variance against its residuals,
:mod:`cornell_harness.evaluate.variance_check`; skipped, not failed, without one, the other two then using the
reference renderer's noise model) and ``outliers`` (a z-test per pixel, :mod:`cornell_harness.evaluate.outliers`).
``alpha`` is their family-wise false-alarm rate, Šidák-shared: each at 1 − (1 − alpha)^(1/3). They assume an
unbiased estimator: ``unbiased = true`` for a renderer that declares ``estimator = "consistent"`` or
``"biased"`` is a config error.

``consistency`` is what a consistent renderer (photon mapping, SPPM: biased, its error going to 0 as its
budget grows) is checked with instead: ``slope = [lo, hi]``, the log-log slope of ``metric`` (default ``mse``;
an error that falls, :data:`cornell_harness.gate.consistency.CONSISTENCY_METRICS`, or a region's) against spp over the render's own checkpoints
from ``from_spp`` (default spp // 16), or ``max_ratio = r`` with ``smaller = { spp = N, <setting> = value }``, a
second render at a smaller budget whose error must be at least 1/r times the full render's. SPPM with radius
reduction α = 2/3 has an MSE rate of iterations^(-2/3) (Knaus & Zwicker 2011), so its band sits around −2/3.

``bias_limit`` tests a consistent renderer's error in the limit of infinite effort against 0 across seeds
(:mod:`cornell_harness.evaluate.bias_extrapolation`): each of ``seeds`` seeds (k·seed .. k·seed + k − 1) is
rendered at every effort (the named ``setting`` set to each, at ``spp``; without ``setting`` the efforts are
spp checkpoints), each seed's signed mean errors fitted as b∞ + c·(E/E₀)^(−rate) (Richardson extrapolation) and
the limits t-tested against 0 at ``alpha``, Šidák over ``metrics``; ``tolerance`` allows a limit up to ±x and
``margin`` gives it three verdicts. docs/gate-detection.md, "Biased renderers", has the derivation and the
measured rates.

Every expectation also checks that the image has no NaN and no Inf pixel. Baseline checks compare runs at the
baseline's own seed only (a metric's spread between seeds can exceed any useful margin); one that cannot be
compared (another seed, no record, scenes derived with ``--set``) has one skipped ``baseline`` check saying why.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cornell_harness.evaluate.sequential import SPENDING, doubling
from cornell_harness.evaluate.registry import IMAGE_METRICS, TEMPORAL_METRICS, bound_problem, region_metric
from cornell_harness.gate.config_fields import GateConfigError, band, check_metrics, check_names, duration
from cornell_harness.gate.consistency import BiasLimit, Consistency, parse_bias_limit, parse_consistency
from cornell_harness.gate.margins import MarginProblem, Margins, parse_margins
from cornell_harness.schemas.reader import FormatProblem, check, read_toml

#: The config's defaults (gate.schema.json states the same; tests/test_schemas.py holds them equal).
DEFAULT_ALPHA = 0.01
DEFAULT_REGRESSION_MARGIN = 0.05
DEFAULT_REGRESSION_METRICS = ("delta_e2000_mean", "rel_mse_trimmed", "ssim")
#: Default wall-time limit of one expectation's render: generous, it only has to stop a hang.
DEFAULT_TIME_LIMIT_S = 1800.0
#: A sequential expectation's default false-pass rate at its margin, over all its looks.
DEFAULT_BETA = 0.05


@dataclass
class Expectation:
    name: str
    scene: str
    renderer: str
    spp: int | None = None
    time_s: float | None = None
    seed: int = 0
    unbiased: bool = False
    tile: int = 16
    slope: tuple[float, float] | None = None
    max: dict = field(default_factory=dict)
    min: dict = field(default_factory=dict)
    abs_max: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)  # the renderer's settings (validated when the gate resolves it)
    time_limit_s: float = DEFAULT_TIME_LIMIT_S
    consistency: Consistency | None = None
    bias_limit: BiasLimit | None = None
    margins: Margins | None = None  # an unbiased expectation's margins (gate.margins): three verdicts
    inconclusive: str = "fail"  # how an inconclusive verdict counts: "fail" (exit 3) or "pass"
    max_spp: int | None = None  # sequential: looks at spp doubling from first_spp up to max_spp (gate.sequential)
    first_spp: int | None = None

    def looks(self) -> list[int]:
        """A sequential expectation's looks: first_spp (default max_spp // 16), doubling, up to max_spp."""
        return doubling(self.first_spp or max(1, self.max_spp // 16), self.max_spp)

    @property
    def frames(self) -> bool:
        """True for an expectation on an animated scene's frames: one that budgets a temporal metric
        (:data:`cornell_harness.evaluate.registry.TEMPORAL_METRICS`); its other budgets are then means over frames."""
        return any(k in TEMPORAL_METRICS for k in self.max)

    def region_metrics(self) -> list[tuple[str, str]]:
        """(field, ``region.<region>.<metric>``) of every region metric it names: the gate checks the regions."""
        out = [(f"{kind}.{key}", key) for kind in ("max", "min", "abs_max") for key in getattr(self, kind)
               if region_metric(key)]
        if self.consistency and region_metric(self.consistency.metric):
            out.append(("consistency.metric", self.consistency.metric))
        if self.bias_limit:
            out += [("bias_limit.metrics", m) for m in self.bias_limit.metrics if region_metric(m)]
        return out


@dataclass
class GateConfig:
    path: Path
    alpha: float
    expectations: list[Expectation]
    baseline: Path | None = None
    regression_margin: float = DEFAULT_REGRESSION_MARGIN
    regression_metrics: tuple[str, ...] = DEFAULT_REGRESSION_METRICS
    beta: float = DEFAULT_BETA
    spending: str = SPENDING[0]


def load_config(path: str | Path) -> GateConfig:
    """Parse and validate a gate config; GateConfigError names the file and field of any problem.

    The format is ``src/cornell_harness/schemas/gate.schema.json``, checked by :mod:`cornell_harness.schemas.reader`;
    what is left here is what the schema cannot say: metric names, durations, and the fields that go together."""
    path = Path(path)
    try:
        doc = read_toml(path)
        check(doc, "gate")
    except FormatProblem as e:
        raise GateConfigError(path, e.field, e.message) from None
    reg = doc.get("regression_metrics", list(DEFAULT_REGRESSION_METRICS))
    check_names(path, reg, IMAGE_METRICS, "regression_metrics: ")
    time_limit = duration(path, doc, "time_limit", "", DEFAULT_TIME_LIMIT_S)
    baseline = doc.get("baseline")
    exps = [_parse_expectation(path, i, t, time_limit) for i, t in enumerate(doc["expect"])]
    names = [e.name for e in exps]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise GateConfigError(path, f"expect[{i}].name", f"two expectations are named {name!r}; give one a name")
    return GateConfig(path, float(doc.get("alpha", DEFAULT_ALPHA)), exps,
                      path.parent / baseline if baseline else None,
                      float(doc.get("regression_margin", DEFAULT_REGRESSION_MARGIN)), tuple(reg),
                      float(doc.get("beta", DEFAULT_BETA)), doc.get("spending", SPENDING[0]))


def _parse_expectation(path: Path, i: int, t: dict, time_limit: float) -> Expectation:
    w = f"expect[{i}]."
    if sum(k in t for k in ("spp", "time", "max_spp")) != 1:
        raise GateConfigError(path, f"{w}spp", "give exactly one budget: spp = N, time = \"10s\" or max_spp = N "
                              "(sequential)")
    spp = t.get("spp")
    time_s = duration(path, t, "time", w, None)
    slope = band(path, t["slope"], f"{w}slope") if "slope" in t else None
    budgets = {}
    for key in ("max", "min", "abs_max"):
        check_metrics(path, t.get(key, {}), IMAGE_METRICS + (TEMPORAL_METRICS if key == "max" else ()),
                       f"{w}{key}.")
        budgets[key] = {k: float(v) for k, v in t.get(key, {}).items()}
    _check_budgets(path, w, budgets)
    unbiased, settings = t.get("unbiased", False), t.get("settings", {})
    consistency = parse_consistency(path, t, w, spp)
    bias_limit = parse_bias_limit(path, t, w)
    try:
        margins = parse_margins(t, bool(bias_limit and bias_limit.margin))
    except MarginProblem as e:
        raise GateConfigError(path, f"{w}{e.field}", e.message) from None
    if not (unbiased or slope or any(budgets.values()) or consistency or bias_limit or t.get("finite_only", False)):
        raise GateConfigError(path, f"expect[{i}]", "no accuracy check: give unbiased = true, a budget (max, min, "
                              "abs_max), a slope or a consistency check; or finite_only = true to check only for "
                              "NaN and Inf")
    _check_sequential(path, t, w)
    _check_frames(path, t, w)
    budget = f"{spp}spp" if spp else f"max{t['max_spp']}spp" if "max_spp" in t else f"{time_s:g}s"
    shown = f"[{','.join(f'{k}={v}' for k, v in sorted(settings.items()))}]" if settings else ""
    name = t.get("name") or f"{t['scene']}/{t['renderer']}{shown}@{budget}"
    return Expectation(name, t["scene"], t["renderer"], spp, time_s, t.get("seed", 0), unbiased, t.get("tile", 16),
                       slope, budgets["max"], budgets["min"], budgets["abs_max"], settings,
                       duration(path, t, "time_limit", w, time_limit), consistency, bias_limit, margins,
                       t.get("inconclusive", "fail"), t.get("max_spp"), t.get("first_spp"))


#: What an expectation on an animated scene's frames cannot have: checks of one still render.
_STILL_CHECKS = ("time", "max_spp", "unbiased", "slope", "consistency", "bias_limit")


def _check_frames(path: Path, t: dict, w: str) -> None:
    """A budget on a temporal metric renders the scene's frames (at ``spp``): no check of one still render goes
    with it, and its budgets are image-wide (a sequence's row has no regions)."""
    if not any(k in TEMPORAL_METRICS for k in t.get("max", {})):
        return
    for key in _STILL_CHECKS:
        if key in t and t[key] is not False:
            raise GateConfigError(path, f"{w}{key}", "goes with a still render; a budget on "
                                  f"{', '.join(TEMPORAL_METRICS)} renders the scene's frames at spp")
    for kind in ("max", "min", "abs_max"):
        for key in t.get(kind, {}):
            if region_metric(key):
                raise GateConfigError(path, f"{w}{kind}.{key}", "a budget on the frames of a sequence is image-wide")


#: What a sequential expectation cannot have: checks of a render at one fixed spp.
_FIXED_SPP_CHECKS = ("slope", "max", "min", "abs_max", "consistency", "bias_limit")


def _check_sequential(path: Path, t: dict, w: str) -> None:
    """``max_spp`` goes with ``unbiased = true`` and a ``margin`` (its pass is equivalence), not with checks
    made at one fixed spp; ``first_spp`` goes with it, below it."""
    if "max_spp" not in t:
        if "first_spp" in t:
            raise GateConfigError(path, f"{w}first_spp", "goes with max_spp (a sequential expectation)")
        return
    if not t.get("unbiased", False) or "margin" not in t:
        raise GateConfigError(path, f"{w}max_spp", "a sequential expectation needs unbiased = true and a margin "
                              "table: it stops at the first look whose bias intervals fail or lie inside the margins")
    for key in _FIXED_SPP_CHECKS:
        if key in t:
            raise GateConfigError(path, f"{w}{key}", "goes with spp, not max_spp: a sequential expectation stops at "
                                  "a spp of its own, and this check is made at one fixed spp")
    if t.get("first_spp", 1) >= t["max_spp"]:
        raise GateConfigError(path, f"{w}first_spp", f"must be below max_spp ({t['max_spp']}): a sequential "
                              "expectation needs two looks")


def _check_budgets(path: Path, w: str, budgets: dict[str, dict[str, float]]) -> None:
    """Refuse a budget no render can break or none can meet: outside its metric's range (the registry's
    :func:`~cornell_harness.evaluate.registry.bound_problem`, as ``--fail``), or a ``min`` above the same metric's
    ``max`` or ``abs_max``."""
    for kind, table in budgets.items():
        for key, value in table.items():
            if problem := bound_problem(key, value, kind, "render"):
                raise GateConfigError(path, f"{w}{kind}.{key}", problem)
    for key, low in budgets["min"].items():
        for kind in ("max", "abs_max"):
            if key in budgets[kind] and low > budgets[kind][key]:
                raise GateConfigError(path, f"{w}min.{key}", f"{low:g} is above {kind}.{key} = "
                                      f"{budgets[kind][key]:g}: every render would fail one of them")


