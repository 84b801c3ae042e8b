"""The report's charts: convergence, speed/accuracy (Pareto) and bias²/variance, as inline SVG.

- **Convergence plots** (error against spp and against time, log-log,
  median over seeds with its 95% confidence band, and on the time axis the
  time's 95% CI as whiskers, over seeds and timing repeats:
  :func:`cornell_harness.evaluate.bootstrap.median_interval`; slope guide), one pair per metric
  of :data:`PLOT_METRICS` with a metric selector. With a single spp per
  renderer they are omitted with a one-line note (:data:`SINGLE_SPP_NOTE`).
- **Speed/accuracy chart**: every (renderer, spp) point, medians over seeds
  (:func:`convergence_table`) with 95% CI whiskers in time and error, and the Pareto frontier
  (:func:`cornell_harness.reports.plotmath.pareto_front`).
- **Bias² and variance bars** per renderer from ``summary``, the bias share above them, or "bias not
  significant" where its interval reaches 0.

Each chart is a :class:`Figure`: its data bound to a :mod:`cornell_harness.reports.plots`
function, drawn once for the page (:data:`cornell_harness.reports.plots.PAGE`) and once as a
standalone file (:mod:`cornell_harness.reports.figures`), under a file name that says what it
shows (:data:`FIGURE_KINDS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd
from markupsafe import Markup

from cornell_harness.evaluate import bootstrap, registry
from cornell_harness.evaluate.convergence import bias_significant
from cornell_harness.reports import bars, plots
from cornell_harness.reports.numbers import is_finite
from cornell_harness.reports.tables import column_or_nan, numeric_column, ok_runs

SINGLE_SPP_NOTE = "single spp: run `cbox converge` for convergence plots"
#: What the convergence plots' bands are.
BAND_LABEL = "95% CI over seeds"

# Metrics that the convergence and speed/accuracy charts offer: key -> (axis label, guide slope).
PLOT_METRICS: dict[str, tuple[str, float | None]] = {
    k: (registry.METRICS[k].axis_label, registry.METRICS[k].guide_slope) for k in registry.PLOT_METRICS}
_GUIDE_LABELS = {-0.5: "slope −½ (∝ 1/√N)", -1.0: "slope −1 (∝ 1/N)"}


@dataclass(frozen=True)
class Figure:
    """One chart: the file name it is saved under (no extension) and its drawing, data bound, layout free."""

    stem: str
    draw: Callable[..., str]  # draw(layout=..., extra_attrs=...) -> SVG (or a note when there is nothing to plot)

    def __html__(self) -> str:
        """The chart as the report page shows it (markupsafe's protocol: Jinja inserts it unescaped)."""
        return self.draw(layout=plots.PAGE)


#: What a figure's file name starts with; a per-metric chart's goes on with the metric (convergence-spp-rmse).
FIGURE_KINDS = ("convergence-spp", "convergence-time", "speed-accuracy", "bias-variance")


def convergence_table(runs: pd.DataFrame, metric_keys: Sequence[str], time_column: str = "time_s") -> pd.DataFrame:
    """One row per (renderer, spp) of the ok runs: median over seeds of each metric and of the time
    (``time_column``, shown as ``time_s``), each with its 95% interval (``_low`` / ``_high``; the time's
    over seeds and its timing repeats); and each metric's range over seeds (``_min`` / ``_max``)."""
    ok = ok_runs(runs)
    rows = []
    samples = bootstrap.samples_column(time_column)
    for (name, spp), g in ok.groupby(["renderer", "spp"], sort=False):
        t = numeric_column(g, time_column).to_numpy(float)
        reps = [bootstrap.parse_samples(x, ti) for x, ti in zip(column_or_nan(g, samples), t)]
        row = {"renderer": str(name), "spp": float(spp), "n": len(g)}
        row["time_s"], row["time_s_low"], row["time_s_high"] = bootstrap.median_interval(t, reps)
        for k in metric_keys:
            v = numeric_column(g, k).to_numpy(float)
            row[k], row[k + "_low"], row[k + "_high"] = bootstrap.median_interval(v)
            finite = v[np.isfinite(v)]  # the range over seeds, which benchmarks/ draw as their bands
            row[k + "_min"], row[k + "_max"] = (finite.min(), finite.max()) if finite.size else (math.nan, math.nan)
        rows.append(row)
    df = pd.DataFrame(rows)
    if not len(df):
        return df
    order = {n: i for i, n in enumerate(dict.fromkeys(df["renderer"]))}  # renderers in the order of the runs
    return df.assign(_o=df["renderer"].map(order)).sort_values(["_o", "spp"], kind="stable").drop(columns="_o")


def has_convergence(runs: pd.DataFrame) -> bool:
    """True when some renderer has ok rows at two or more spp: convergence plots then make sense."""
    ok = ok_runs(runs)
    return bool(len(ok)) and bool((ok.groupby("renderer")["spp"].nunique() >= 2).any())


def _series_for(conv: pd.DataFrame, metric: str, x: str, names: Sequence[str], colors: dict,
                shown: dict | None = None) -> list[plots.Series]:
    out = []
    for name in names:
        g = conv[conv["renderer"] == name].sort_values(x if x == "spp" else "spp")
        if not len(g) or not np.isfinite(g[metric].to_numpy(float)).any():
            continue
        labels = [_point_label(name, r, metric) for _, r in g.iterrows()]
        multi = (g["n"] > 1).any()
        timed = x == "time_s" and np.isfinite(g["time_s_low"].to_numpy(float)).any()
        out.append(plots.Series(
            name=name, color=colors[name], x=g[x].astype(float).tolist(), y=g[metric].astype(float).tolist(),
            lo=g[metric + "_low"].astype(float).tolist() if multi else None,
            hi=g[metric + "_high"].astype(float).tolist() if multi else None, labels=labels,
            xlo=g["time_s_low"].astype(float).tolist() if timed else None,
            xhi=g["time_s_high"].astype(float).tolist() if timed else None, label=(shown or {}).get(name, name),
        ))
    return out


def _ci_text(r, key: str, fmt: str) -> str:
    lo, hi = r.get(key + "_low"), r.get(key + "_high")
    return f" (95% CI {lo:{fmt}}–{hi:{fmt}})" if is_finite(lo) and is_finite(hi) else ""


def _point_label(name: str, r, metric: str) -> str:
    """A point's tooltip: its figures with their 95% intervals, and how many seeds."""
    n = int(r["n"])
    return (f"{name}: {int(r['spp'])} spp, {r['time_s']:.3g} s{_ci_text(r, 'time_s', '.3g')}, "
            f"{metric} = {r[metric]:.4g}{_ci_text(r, metric, '.4g')} (median of {n} seed{'s' if n != 1 else ''})")


def _plot_metrics(conv: pd.DataFrame) -> list[str]:
    if not len(conv):
        return []
    out = []
    for k in PLOT_METRICS:
        if k in conv.columns:
            v = conv[k].to_numpy(float)
            if (np.isfinite(v) & (v > 0)).any():
                out.append(k)
    return out


def _prefixed(prefix: str, name: str) -> str:
    """A figure's file stem or element id in a report section (``sweep-a-convergence-spp-rmse``), so several
    experiments' charts neither overwrite each other's files nor share ids on one page."""
    return f"{prefix}-{name}" if prefix else name


def page_charts(runs, names, colors, prefix: str = "", time_column: str = "time_s", labels=None) -> dict:
    """The page's charts, as :class:`Figure` objects, with what the template needs around them; ``prefix``
    starts their file stems and element ids (:func:`_prefixed`); ``time_column``: the clock of the time
    axes (``time_s``, wall, or ``cpu_time_s``); ``labels``: a series' shown text by name (default its name)."""
    labels = labels or {}
    ok = ok_runs(runs)
    conv = convergence_table(runs, [k for k in PLOT_METRICS if k in ok.columns], time_column)
    clock = "CPU time (s)" if time_column == "cpu_time_s" else "wall time (s)"
    metric_keys = _plot_metrics(conv)
    charts: dict[str, Any] = {"metrics": [{"key": k, "label": PLOT_METRICS[k][0]} for k in metric_keys],
                              "convergence": [], "pareto": [], "has_convergence": has_convergence(runs),
                              "clock": clock.removesuffix(" (s)")}
    for i, k in enumerate(metric_keys):
        label, slope = PLOT_METRICS[k]
        hidden = "" if i == 0 else ' style="display:none"'
        attrs = f' data-metric="{k}"{hidden}'
        if charts["has_convergence"]:
            guide = _GUIDE_LABELS.get(slope, f"slope {slope:g}")
            spp = Figure(_prefixed(prefix, f"convergence-spp-{k}"), partial(
                plots.line_plot_svg, _series_for(conv, k, "spp", names, colors, labels),
                uid=_prefixed(prefix, f"conv-spp-{k}"),
                xlabel="samples per pixel", ylabel=label, guide_slope=slope, guide_label=guide, xbase2=True,
                band_label=BAND_LABEL))
            tim = Figure(_prefixed(prefix, f"convergence-time-{k}"), partial(
                plots.line_plot_svg, _series_for(conv, k, "time_s", names, colors, labels),
                uid=_prefixed(prefix, f"conv-time-{k}"),
                xlabel=clock, ylabel=label, guide_slope=slope, guide_label=guide, band_label=BAND_LABEL))
            charts["convergence"].append({"key": k, "attrs": Markup(attrs), "spp": spp, "time": tim})
        points = [
            plots.Point(name=r["renderer"], color=colors[r["renderer"]], x=float(r["time_s"]), y=float(r[k]),
                        tip=_point_label(r["renderer"], r, k), tag=f"{int(r['spp'])}",
                        label=labels.get(r["renderer"], r["renderer"]),
                        xlo=_finite(r["time_s_low"]), xhi=_finite(r["time_s_high"]),
                        ylo=_finite(r[k + "_low"]), yhi=_finite(r[k + "_high"]))
            for _, r in conv.iterrows()
        ]
        charts["pareto"].append({"key": k, "attrs": Markup(attrs), "svg": Figure(
            _prefixed(prefix, f"speed-accuracy-{k}"), partial(plots.scatter_svg, points,
                                                             uid=_prefixed(prefix, f"pareto-{k}"),
                                                             xlabel=clock, ylabel=label))})
    return charts


def _finite(v) -> float | None:
    return float(v) if is_finite(v) else None


def chart_figures(charts: dict, bias_variance: Figure | None) -> list[Figure]:
    """Every figure of the report, in page order."""
    figures = [f for c in charts["convergence"] for f in (c["spp"], c["time"])]
    figures += [p["svg"] for p in charts["pareto"]]
    return figures + ([bias_variance] if bias_variance is not None else [])


def chart_rows(charts: dict, bias_variance: Figure | None) -> list[dict]:
    """The same charts laid out for a report section (:func:`cornell_harness.reports.html.write_report`'s ``sections``):
    per metric a row of (caption, figure) boxes, its convergence against spp and time and its speed/accuracy
    chart, the rows of all but the first metric hidden (the page's metric selector switches them); then
    the bias/variance bars. ``cls``: the row's CSS class, a grid of charts or one chart at readable width."""
    convergence = {c["key"]: c for c in charts["convergence"]}
    rows = []
    for p in charts["pareto"]:  # one per plotted metric, in the selector's order
        c = convergence.get(p["key"])
        boxes = [("against samples per pixel", c["spp"]), (f"against {charts['clock']}", c["time"])] if c else []
        rows.append({"cls": "charts", "attrs": p["attrs"], "boxes": boxes + [("speed / accuracy", p["svg"])]})
    if bias_variance is not None:
        rows.append({"cls": "chart-wrap", "attrs": Markup(""), "boxes": [("bias² and variance", bias_variance)]})
    return rows


def bias_variance_chart(summary, names, colors, prefix: str = "", labels=None) -> Figure | None:
    if summary is None or not len(summary) or "bias2" not in summary.columns or "variance" not in summary.columns:
        return None
    by_name = {str(r["renderer"]): r for r in summary.to_dict("records")}
    groups = []
    for name in names:
        r = by_name.get(name)
        if r is None:
            continue
        b2, var = float(r.get("bias2", math.nan)), float(r.get("variance", math.nan))
        if not (math.isfinite(b2) or math.isfinite(var)):
            continue
        frac = r.get("bias2_fraction")
        significant = bias_significant(r.get("bias2_fraction_low"))
        # a short mark over the renderer's bars; the tooltip says it in full, the legend what marks mean
        note, tip = (("n.s.", "bias not significant (its 95% interval reaches 0)") if significant is False else
                     (f"{100 * float(frac):.0f} %", f"bias {100 * float(frac):.0f} % of bias² + variance")
                     if is_finite(frac) else ("", ""))
        bounds = [[float(r.get(f"{k}_{end}", math.nan)) for k in ("bias2", "variance")] for end in ("low", "high")]
        groups.append(bars.BarGroup(name, [b2, var], note, *bounds, label=(labels or {}).get(name, name),
                                    note_tip=tip))
    if not groups:
        return None
    key = [text for text, used in ((NOTE_SHARE, any(g.note.endswith("%") for g in groups)),
                                   (NOTE_NS, any(g.note == "n.s." for g in groups))) if used]
    return Figure(_prefixed(prefix, "bias-variance"), partial(
        bars.bars_svg, groups, (("bias²", "#e69f00"), ("variance", "#56b4e9")),
        uid=_prefixed(prefix, "bias-variance"), ylabel="mean over pixels and channels", note_key=key))


#: The bias/variance chart's legend lines for its marks over the bars.
NOTE_SHARE = "n %: bias² share"
NOTE_NS = "n.s.: bias not significant"
