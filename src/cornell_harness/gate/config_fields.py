"""The gate config's field checks, shared by its parts: the error that names file and field, metric names,
durations, bands."""

from __future__ import annotations

from pathlib import Path

from cornell_harness.durations import parse_duration
from cornell_harness.evaluate.registry import REGION_CHECK_METRICS, region_metric
from cornell_harness.suggest import closest


class GateConfigError(ValueError):
    """Bad gate config; ``str()`` names the file and the field."""

    def __init__(self, file, field: str, message: str):
        super().__init__(f"{file}: {field}: {message}")



def check_names(path: Path, names, allowed, where: str, what: str = "metric") -> None:
    """Refuse any name not in ``allowed``, naming it and the closest allowed one."""
    for key in names:
        if key not in allowed:
            hint = closest(key, allowed)
            raise GateConfigError(path, f"{where}{key}", f"unknown {what}"
                                  + (f" (did you mean {hint!r}?)" if hint else f"; known: {', '.join(allowed)}"))


def check_metrics(path: Path, names, allowed, where: str) -> None:
    """Refuse a metric name that is neither in ``allowed`` nor a region metric ``region.<region>.<metric>``."""
    for key in names:
        parts = region_metric(key)
        if parts is None:
            check_names(path, [key], allowed, where)
            continue
        region, metric = parts
        if not region or metric not in REGION_CHECK_METRICS:
            hint = closest(metric, REGION_CHECK_METRICS) if region else None
            raise GateConfigError(path, f"{where}{key}", "unknown region metric: expected region.<region>.<metric> "
                                  "with <metric> one of " + ", ".join(REGION_CHECK_METRICS)
                                  + (f" (did you mean 'region.{region}.{hint}'?)" if hint else ""))


def duration(path: Path, table: dict, key: str, where: str, default: float | None) -> float | None:
    if key not in table:
        return default
    try:
        return parse_duration(str(table[key]))
    except ValueError as e:
        raise GateConfigError(path, f"{where}{key}", str(e)) from None


def band(path: Path, value: list, field: str) -> tuple[float, float]:
    if not value[0] < value[1]:
        raise GateConfigError(path, field, "expected [low, high] with low < high")
    return float(value[0]), float(value[1])
