"""The report's timing-quality badge: whether an experiment's times were taken on a quiet machine.

The verdict is :func:`cornell_harness.evaluate.timing_quality.timing_quality`'s (other processes' CPU beside the
renders' threads; without that figure, load and calibration kernel slowdown): **good**, **contended** (some render competed for the cores: its wall time
is inflated) or **unknown** (results written before the load and calibration figures were recorded). The
figures behind it are the badge's text and tooltip. The machine's cores are those of the machine the
report is built on (:func:`cornell_harness.adapters.api.machine_cores`) unless given: experiment.json does not
record them, so a report built elsewhere than the experiment ran should pass them.
"""

from __future__ import annotations

from html import escape

import pandas as pd
from markupsafe import Markup

from cornell_harness.adapters.api import machine_cores
from cornell_harness.evaluate.timing_quality import TimingQuality, timing_quality


def verdict(quality: TimingQuality) -> str:
    """"good", "contended" or "unknown"."""
    return "unknown" if not quality.known else "good" if quality.ok else "contended"


def timing_badge(runs: pd.DataFrame | None, cores: int | None = None, figures: bool = True) -> Markup:
    """HTML (escaped): the badge ``timing good|contended|unknown`` with the verdict's line as its title, and
    (``figures``) the figures behind it in a note beside it."""
    runs = runs if runs is not None else pd.DataFrame()
    quality = timing_quality(runs, cores or machine_cores())
    state = verdict(quality)
    text = quality.figures() if quality.known else "these results carry no load or calibration figures"
    tip = quality.line()
    badge = (f'<span class="badge timing timing-{state}" data-timing="{state}" title="{escape(tip)}">'
             f'timing {state}</span>')
    return Markup(badge + (f' <span class="note timing-figures">{escape(text)}</span>' if figures else ""))
