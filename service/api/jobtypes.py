"""Typed job requests: one pydantic model per job kind's options, generated from the library's option
dataclasses (``SceneParams``, ``FitOptions``, ``CyclicOptions`` + the flat swim parameters), and the request
body as a union discriminated on ``kind``, so the OpenAPI document tells a generated client every field.

The models check JSON types only (strictly: no "3" for 3); the library's ``from_dict`` still checks ranges and
combinations and names the problem (422 ``invalid_parameter``). Parameters may be given in ``params`` or
flat next to ``kind`` (the released form); flat ones are checked by the same model after merging.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, create_model

from pdeanim.cyclic.swim import SwimParams
from pdeanim.sim.scene import IGNORED_KEYS as SCENE_IGNORED_KEYS

from ..jobspec import options_class
from .errors import ApiError

STRICT = {int: Annotated[int, Strict()], float: Annotated[float, Strict()], bool: Annotated[bool, Strict()],
          str: Annotated[str, Strict()]}
OPTIONS_CONFIG = ConfigDict(extra="forbid", allow_inf_nan=False)
EXTRA_FIELDS: dict[str, type] = {"cyclic": SwimParams}  # accepted flat by CyclicOptions.from_dict
IGNORED_KEYS: dict[str, tuple[str, ...]] = {"simulate": SCENE_IGNORED_KEYS}  # accepted for old clients
MODEL_NAMES = {
    "simulate": "SceneParams",
    "fit": "FitOptions",
    "cyclic": "CyclicOptions",
    "export": "ExportOptions",
}


def wire_type(tp: Any) -> Any:
    """The JSON-side type of a dataclass field type: strict scalars, tuples/lists/dicts of them, optionals."""
    if tp in STRICT:
        return STRICT[tp]
    if tp is dict or tp is typing.Any:
        return dict[str, Any] if tp is dict else Any
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        return Union[tuple(wire_type(a) for a in args)]  # noqa: UP007 - built from a tuple
    if origin is tuple:
        return tuple[tuple(wire_type(a) for a in args)] if args else list[Any]
    if origin is list:
        return list[wire_type(args[0]) if args else Any]
    if origin is dict:
        return dict[str, Any]
    return tp


def _fields(cls: type, optional: bool = False, skip: frozenset[str] = frozenset()) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.name in skip or f.name.startswith("_"):
            continue
        tp = wire_type(hints[f.name])
        if optional:
            out[f.name] = (tp | None, Field(None, description="swim parameter overriding the preset's"))
        elif f.default is not dataclasses.MISSING:
            default = list(f.default) if isinstance(f.default, tuple) else f.default
            out[f.name] = (tp, Field(default))
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = (tp, Field(default_factory=f.default_factory))
        else:
            out[f.name] = (tp, Field(...))
    return out


def options_model(kind: str) -> type[BaseModel]:
    """The options model of ``kind``, generated from its dataclass."""
    name = MODEL_NAMES[kind]
    cls = options_class(kind)
    fields = _fields(cls)
    for key in IGNORED_KEYS.get(kind, ()):
        fields[key] = (Any, Field(None, deprecated=True, description="accepted for old clients and ignored"))
    if kind in EXTRA_FIELDS:
        fields.update(_fields(EXTRA_FIELDS[kind], optional=True, skip=frozenset(fields) | {"mode"}))
    doc = (cls.__doc__ or name).strip()
    return create_model(name, __config__=OPTIONS_CONFIG, __doc__=doc, **fields)


SceneParamsModel = options_model("simulate")
FitOptionsModel = options_model("fit")
CyclicOptionsModel = options_model("cyclic")
ExportOptionsModel = options_model("export")
MODELS = {"simulate": SceneParamsModel, "fit": FitOptionsModel, "cyclic": CyclicOptionsModel,
          "export": ExportOptionsModel}
FLAT = ("Options may also be given flat, next to kind (not both ways for one key).")


class _JobBase(BaseModel):
    model_config = ConfigDict(extra="allow")


class SimulateJob(_JobBase):
    """Simulate the mesh's motion (scene parameters), optionally fitting a clip in the same job."""

    model_config = ConfigDict(extra="allow", json_schema_extra={
        "description": __doc__ + " " + FLAT, "examples": [
            {"kind": "simulate", "mesh_id": "mesh_0123", "params": {"frames": 60}, "then_fit": True,
             "fit": {"target_rel_rms": 0.002}}]})

    kind: Literal["simulate"]
    mesh_id: str = Field(max_length=64, description="the mesh to simulate")
    params: SceneParamsModel = Field(default_factory=SceneParamsModel)  # type: ignore[valid-type]
    then_fit: bool = Field(False, description="fit the simulated poses in the same job")
    fit: FitOptionsModel | None = Field(None, description="fit options when then_fit is true")  # type: ignore


class FitJob(_JobBase):
    """Fit a clip to poses: ``poses_id``, or ``mesh_id`` alone to fit the mesh's latest poses."""

    model_config = ConfigDict(extra="allow", json_schema_extra={
        "description": __doc__ + " " + FLAT, "examples": [
            {"kind": "fit", "poses_id": "poses_0123", "params": {"segments": 4}},
            {"kind": "fit", "mesh_id": "mesh_0123", "target_rel_rms": 0.003}]})

    kind: Literal["fit"]
    poses_id: str | None = Field(None, max_length=64, description="the poses to fit (default: the mesh's)")
    mesh_id: str | None = Field(None, max_length=64, description="fit this mesh's latest poses; or a check")
    params: FitOptionsModel = Field(default_factory=FitOptionsModel)  # type: ignore[valid-type]


class CyclicJob(_JobBase):
    """Make a looping swim clip of the mesh from a preset and its overrides."""

    model_config = ConfigDict(extra="allow", json_schema_extra={
        "description": __doc__ + " " + FLAT, "examples": [
            {"kind": "cyclic", "mesh_id": "mesh_0123", "params": {"mode": "eel", "frames": 24}}]})

    kind: Literal["cyclic"]
    mesh_id: str = Field(max_length=64, description="the mesh to animate")
    params: CyclicOptionsModel = Field(default_factory=CyclicOptionsModel)  # type: ignore[valid-type]


class ExportJob(_JobBase):
    """Build a clip's animation GLB in a worker (for exports above PDEANIM_MAX_SYNC_EXPORT_BYTES); the
    result names ``export_url`` to download it from."""

    model_config = ConfigDict(extra="allow", json_schema_extra={
        "description": __doc__ + " " + FLAT, "examples": [
            {"kind": "export", "clip_id": "clip_0123", "params": {"fps": 60}},
            {"kind": "export", "clip_id": "clip_0123", "fps": 30}]})

    kind: Literal["export"]
    clip_id: str = Field(max_length=64, description="the clip to export")
    mesh_id: str | None = Field(None, max_length=64, description="optional check: the clip's mesh")
    params: ExportOptionsModel = Field(default_factory=ExportOptionsModel)  # type: ignore[valid-type]


JobBody = Annotated[SimulateJob | FitJob | CyclicJob | ExportJob, Field(discriminator="kind")]


def _reason(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors()[:5]:
        loc = ".".join(str(p) for p in err.get("loc", ()))
        parts.append(f"{loc}: {err.get('msg', 'invalid')}")
    return "; ".join(parts)


def job_options(req: SimulateJob | FitJob | CyclicJob | ExportJob) -> dict[str, Any]:
    """The options the caller gave (in ``params`` and flat), type-checked, without defaults filled in."""
    given = req.params.model_dump(exclude_unset=True)
    flat = dict(req.model_extra or {})
    both = sorted(set(flat) & set(given))
    if both:
        raise ApiError(422, "invalid_parameter",
                       f"parameters given both flat and in params: {', '.join(both)}")
    if flat:
        try:
            flat = MODELS[req.kind].model_validate(flat).model_dump(exclude_unset=True)
        except ValidationError as exc:
            raise ApiError(422, "invalid_parameter", f"{req.kind} parameters: {_reason(exc)}") from exc
    return {**given, **flat}
