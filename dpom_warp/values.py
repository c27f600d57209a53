"""The config's value types, each checking its input and saying what it expected, and `Node`,
the mapping every section is: unknown keys are errors naming the closest known key. Below every
layer, so that the owner of a config section (the tracker, the background estimator, ...)
declares its typed options once, with their checks and descriptions, and the config package
composes them."""

from __future__ import annotations

import difflib
import re
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError


class ConfigError(ValueError):
    """Invalid configuration; str(e) is one line naming the key."""


def _fmt(v):
    return repr(v) if not isinstance(v, (dict, list, tuple)) else type(v).__name__


def _fail(message: str, key: str = "") -> PydanticCustomError:
    """An error with our own message; `key` (dotted) is appended to the error's location."""
    return PydanticCustomError("dpom", message, {"key": key}) if key else PydanticCustomError("dpom", message)


# -- value types: each checks its input and says what it expected ------------------------------
def _number(v):
    if isinstance(v, str):  # YAML 1.1 reads 1e-3 (no dot) as a string
        try:
            if np.isfinite(float(v)):
                return float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _fail(f"expected a number, found {_fmt(v)}")
    return v


def _integer(v):
    if isinstance(v, bool) or not isinstance(v, int):
        raise _fail(f"expected an integer, found {_fmt(v)}")
    return v


def _boolean(v):
    if not isinstance(v, bool):
        raise _fail(f"expected true or false, found {_fmt(v)}")
    return v


def _string(v):
    if not isinstance(v, str):
        raise _fail(f"expected a string, found {_fmt(v)}")
    return v


def _numbers(n: int):
    def check(v):
        if (not isinstance(v, (list, tuple)) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            raise _fail(f"expected a list of {n} numbers, found {_fmt(v)}"
                        + (f" of length {len(v)}" if isinstance(v, (list, tuple)) else ""))
        return tuple(float(x) for x in v)
    return BeforeValidator(check)


def _lens(v):
    """OpenCV's distortion: [k1, k2, p1, p2, k3] or the rational [k1, k2, p1, p2, k3, k4, k5, k6]."""
    if (not isinstance(v, (list, tuple)) or len(v) not in (5, 8)
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise _fail(f"expected a list of 5 or 8 numbers, found {_fmt(v)}"
                    + (f" of length {len(v)}" if isinstance(v, (list, tuple)) else ""))
    return tuple(float(x) for x in v)


Lens = Annotated[tuple[float, ...], BeforeValidator(_lens)]


def _heights(v):
    """A list of heights in metres, each > 0 (model.top_heights)."""
    if (not isinstance(v, (list, tuple))
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and x > 0 for x in v)):
        found = list(v) if isinstance(v, (list, tuple)) else _fmt(v)
        raise _fail(f"expected a list of heights > 0 (metres), found {found}")
    return tuple(float(x) for x in v)


Heights = Annotated[tuple[float, ...], BeforeValidator(_heights)]


class PathValue:
    """Marks a config value that is a file, folder or glob: relative to the config's folder."""


Num = Annotated[float, BeforeValidator(_number)]


Int = Annotated[int, BeforeValidator(_integer)]


Bool = Annotated[bool, BeforeValidator(_boolean)]


Str = Annotated[str, BeforeValidator(_string)]


FilePath = Annotated[str, BeforeValidator(_string), PathValue()]


Pair = Annotated[tuple[float, float], _numbers(2)]


Triple = Annotated[tuple[float, float, float], _numbers(3)]


def _axis(v):
    lo, hi, step = _numbers(3).func(v)
    if step <= 0:
        raise _fail(f"expected a step > 0 in [min, max, step], found {step!r}")
    if lo >= hi:
        raise _fail(f"expected min < max in [min, max, step], found {lo!r} >= {hi!r}")
    return lo, hi, step


Axis = Annotated[tuple[float, float, float], BeforeValidator(_axis)]


def check_device(device: str, key: str = "device") -> str:
    if device not in ("auto", "cpu", "cuda") and not (device.startswith("cuda:") and device[5:].isdigit()):
        raise ConfigError(f"{key}: expected auto, cpu, cuda or cuda:N, found {device!r}")
    return device


def _device(v):
    try:
        return check_device(_string(v))
    except ConfigError:
        raise _fail(f"expected auto, cpu, cuda or cuda:N, found {v!r}") from None


Device = Annotated[str, BeforeValidator(_device), Field(pattern=r"^(auto|cpu|cuda(:[0-9]+)?)$")]


def _stride(v):
    if v == "auto":
        return v
    if isinstance(v, bool) or not isinstance(v, int):
        raise _fail(f"expected auto or an integer >= 1, found {_fmt(v)}")
    if not 1 <= v <= 64:
        raise _fail(f"expected a value {'>= 1' if v < 1 else '<= 64'}, found {v}")
    return v


Stride = Annotated[Union[Literal["auto"], Annotated[int, Field(ge=1, le=64)]], BeforeValidator(_stride)]


def _batch(v):
    if v == "auto":
        return v
    if isinstance(v, bool) or not isinstance(v, int):
        raise _fail(f"expected auto or an integer >= 1, found {_fmt(v)}")
    if v < 1:
        raise _fail(f"expected a value >= 1, found {v}")
    return v


Batch = Annotated[Union[Literal["auto"], Annotated[int, Field(ge=1)]], BeforeValidator(_batch)]


def _switch(v):
    """YAML 1.1 reads a bare on / off as true / false: the words they were."""
    return {True: "on", False: "off"}.get(v, v) if isinstance(v, bool) else v


Switch = BeforeValidator(_switch)


def _up(v):
    if v == "auto":
        return v
    if (not isinstance(v, (list, tuple)) or len(v) != 3
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise _fail(f"expected auto or a list of 3 numbers, found {_fmt(v)}"
                    + (f" of length {len(v)}" if isinstance(v, (list, tuple)) else ""))
    return tuple(float(x) for x in v)


Up = Annotated[Union[Literal["auto"], tuple[float, float, float]], BeforeValidator(_up)]


# -- the sections -------------------------------------------------------------------------------
class Node(BaseModel):
    """A mapping of the config: unknown keys are errors that name the closest known key."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _mapping(cls, raw):
        if raw is None:
            return {}
        if not isinstance(raw, dict):
            raise _fail(f"expected a mapping, found {_fmt(raw)}")
        known = list(cls.model_fields)
        unknown = [str(key) for key in raw if key not in known]
        if len(unknown) == 1:
            close = difflib.get_close_matches(unknown[0], known, n=1, cutoff=0.6)
            hint = f"did you mean {close[0]}? " if close else ""
            raise _fail(f"unknown key ({hint}expected one of {', '.join(known)})", unknown[0])
        if unknown:  # every one named, in one line
            named = []
            for key in unknown:
                close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
                named.append(f"{key} (did you mean {close[0]}?)" if close else key)
            raise _fail(f"unknown keys {', '.join(named)}; expected keys among {', '.join(known)}")
        return raw


def _read_yaml(path: Path, what: str):
    if not path.is_file():
        raise ConfigError(f"{path}: no such {what}")
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{path}: not valid YAML{where} ({getattr(e, 'problem', e)})") from None


def _g(x):
    return f"{x:g}" if isinstance(x, (int, float)) else str(x)


LISTS = ("zones", "lines", "cameras", "polygon")  # the config's lists of sections: an item is named NAME[i]


def _one_line(error: dict) -> str:
    loc = []
    for p in error["loc"]:
        if str(p).startswith("<"):
            continue
        if isinstance(p, int) and loc and loc[-1] in LISTS:  # zones[1], as the checks across sections say it
            loc[-1] += f"[{p}]"
        else:
            loc.append(str(p))
    ctx = error.get("ctx") or {}
    if ctx.get("key"):
        loc.append(ctx["key"])
    key = ".".join(loc) or "config"
    kind, found = error["type"], _fmt(error.get("input"))
    bounds = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<", "less_than_equal": "<="}
    if kind == "missing":
        text = "required key is missing"
    elif kind in bounds:
        limit = ctx.get({">": "gt", ">=": "ge", "<": "lt", "<=": "le"}[bounds[kind]])
        text = f"expected a value {bounds[kind]} {_g(limit)}, found {found}"
    elif kind == "literal_error":
        choices = re.findall(r"'([^']*)'", str(ctx.get("expected", "")))
        text = f"expected one of {', '.join(choices)}, found {found}"
    elif kind == "dpom":
        text = error["msg"]
    else:
        text = f"{error['msg'][0].lower()}{error['msg'][1:]}, found {found}"
    return f"{key}: {text}"


def _first_error(e: ValidationError) -> str:
    errors = e.errors(include_url=False)
    unknown = [x for x in errors if x["type"] == "dpom" and x["msg"].startswith("unknown key")]
    if len(unknown) > 1:  # in several sections: each named, in the one line
        return "; ".join(_one_line(x) for x in unknown)
    return _one_line((unknown or errors)[0])
