"""What a job of each kind needs from the library: its options class (validated at submission by the API,
rebuilt by the worker) and the library versions recorded with every attempt."""

from __future__ import annotations

from typing import Any

from pdeanim.cyclic.job import CyclicOptions
from pdeanim.errors import ParameterError
from pdeanim.fit.options import FitOptions
from pdeanim.gltf.clipexport import ExportOptions
from pdeanim.sim.scene import SceneParams

OPTIONS: dict[str, type] = {
    "simulate": SceneParams,
    "fit": FitOptions,
    "cyclic": CyclicOptions,
    "export": ExportOptions,
}


def options_class(kind: str) -> type:
    """The options dataclass of ``kind`` (with ``from_dict``/``to_dict``)."""
    if kind not in OPTIONS:
        raise ParameterError(f"unknown job kind {kind!r} (known: {', '.join(OPTIONS)})")
    return OPTIONS[kind]


def normalize(kind: str, params: dict[str, Any] | None) -> dict[str, Any]:
    """Validate options of ``kind`` (ParameterError on unknown/bad keys, LimitError when the work the
    options ask for is over the budget the worker enforces) and return them with defaults."""
    if params is not None and not isinstance(params, dict):
        raise ParameterError(f"{kind} parameters must be a JSON object")
    options = options_class(kind).from_dict(dict(params or {}))
    check_work = getattr(options, "check_work", None)
    if check_work is not None:
        check_work()  # the same estimate the worker checks (pdeanim.sim.scene.SceneParams.work)
    return options.to_dict()


def normalize_request(kind: str, params: dict[str, Any], then_fit: bool, fit: dict[str, Any] | None) -> dict:
    """The job's stored parameters: {"params": ..., "then_fit": ..., "fit": ...}, all validated."""
    if then_fit and kind != "simulate":
        raise ParameterError("then_fit applies to simulate jobs only")
    if fit is not None and not then_fit:
        raise ParameterError("fit options are given but then_fit is false")
    spec: dict[str, Any] = {"params": normalize(kind, params), "then_fit": bool(then_fit)}
    if then_fit:
        spec["fit"] = normalize("fit", fit)
    return spec
