"""Run-time overrides of a generated program: --set NAME.PARAM=VALUE, --input NAME=URI and
--output NAME=URI.

The program's PARAMS table declares the parameters that may change when it starts (no
size, requirement or compiled kernel depends on them) with their type and bounds; an
override is checked against that declaration the way ``gpucompgen check`` checks a model.
``--input camera=URI`` sets the source component's ``source`` parameter (and clears its
older ``folder`` and ``video``); ``--output NAME=URI`` sets a sink's ``output``.
"""

from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass

from .errors import PipelineError

INPUT_PARAM, OUTPUT_PARAM = "source", "output"
INPUT_ALIASES = ("folder", "video")  # a source's older input parameters, cleared by --input
BOOLS = {"true": True, "yes": True, "on": True, "1": True,
         "false": False, "no": False, "off": False, "0": False}


@dataclass(frozen=True)
class Param:
    """A settable parameter: its declared type, the model's value, its bounds."""

    type: str  # int | float | bool | str | path
    value: object
    minimum: float | None = None
    maximum: float | None = None


class OverrideError(PipelineError):
    """An override that does not fit the program: a usage error (exit 2)."""


def param_values(table: dict[str, Param], overrides: dict | None) -> dict[str, object]:
    """The value of every settable parameter: the model's, or the override's."""
    values = {key: p.value for key, p in table.items()}
    for key, value in (overrides or {}).items():
        if key not in table:
            raise OverrideError(unknown(key, table))
        values[key] = checked(key, value, table[key])
    return values


def checked(key: str, value: object, p: Param) -> object:
    """A value given from Python (run(params=...)): of the declared type, within bounds."""
    kinds = {"int": int, "float": (int, float), "bool": bool}
    kind = kinds.get(p.type, str)
    if isinstance(value, bool) != (p.type == "bool") or not isinstance(value, kind):
        raise OverrideError(f"{key}: expected {p.type}, not {type(value).__name__} "
                            f"{value!r}")
    problem = range_problem(value, p)
    if problem:
        raise OverrideError(f"{key}: {problem}")
    return float(value) if p.type == "float" else value


def range_problem(value: object, p: Param) -> str:
    """Why a number does not fit the declaration (finite, within its bounds), or ''."""
    if p.type not in ("int", "float"):
        return ""
    if p.type == "float" and not math.isfinite(value):
        return f"expected a finite number, not {value!r}"
    if p.minimum is not None and value < p.minimum:
        return f"{value} is below the minimum {_num(p.minimum)}"
    if p.maximum is not None and value > p.maximum:
        return f"{value} is above the maximum {_num(p.maximum)}"
    return ""


def unknown(key: str, table: dict[str, Param]) -> str:
    component = key.split(".", 1)[0]
    mine = sorted(k for k in table if k.startswith(component + "."))
    if mine:
        close = difflib.get_close_matches(key, mine, 1, cutoff=0.8)
        hint = f"did you mean '{close[0]}'? " if close else ""
        return (f"'{key}' cannot be set at run time: {hint}{component}'s settable parameters "
                f"are {', '.join(k.split('.', 1)[1] for k in mine)} (parameters that "
                "change a size, or are compiled into a kernel, need a rebuild)")
    components = sorted({k.split(".", 1)[0] for k in table})
    close = difflib.get_close_matches(component, components, 1)
    return (f"'{key}': the program has no component '{component}' with settable parameters"
            + (f" (did you mean '{close[0]}'?)" if close else "")
            + (f"; components with some: {', '.join(components)}" if components else ""))


def convert(key: str, text: str, p: Param) -> object:
    """A command-line value as the declaration's type, within its bounds."""
    where = f"--set {key}={text}"
    if p.type == "bool":
        if text.strip().lower() not in BOOLS:
            raise OverrideError(f"{where}: expected true or false")
        return BOOLS[text.strip().lower()]
    if p.type in ("int", "float"):
        try:
            value = int(text, 0) if p.type == "int" else float(text)
        except ValueError:
            kind = "a whole number" if p.type == "int" else "a number"
            raise OverrideError(f"{where}: expected {kind}, e.g. {key}={p.value}") from None
        problem = range_problem(value, p)
        if problem:
            raise OverrideError(f"{where}: {problem}")
        return value
    if p.type in ("path", "input") and text and "://" not in text \
            and not text.startswith("device:"):
        return os.path.abspath(os.path.expanduser(text))  # from the working folder
    return text


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else str(v)


def parse_overrides(table: dict[str, Param], sets: list[str], inputs: list[str],
                    outputs: list[str]) -> dict[str, object]:
    """{'component.param': value} from --set, --input and --output; later options win."""
    result: dict[str, object] = {}
    for flag, items in (("--input", inputs), ("--output", outputs)):
        param = INPUT_PARAM if flag == "--input" else OUTPUT_PARAM
        for item in items:
            name, sep, uri = item.partition("=")
            name = name.strip()
            if not sep or not name or not uri.strip():
                raise OverrideError(f"{flag} {item}: write {flag} NAME=URI, e.g. "
                                    + ("--input camera=shots/" if param == INPUT_PARAM
                                       else "--output writer=out.mp4"))
            key = f"{name}.{param}"
            if key not in table:
                which = sorted(k.split(".", 1)[0] for k in table if k.endswith("." + param))
                raise OverrideError(
                    f"{flag} {item}: "
                    + (f"component '{name}' takes no {param} URI" if any(
                        k.startswith(name + ".") for k in table) else
                       f"the program has no component '{name}' with an {param} URI")
                    + f"; components that do: {', '.join(which) if which else 'none'}")
            result[key] = convert(key, uri.strip(), table[key])
            if param == INPUT_PARAM:
                for alias in INPUT_ALIASES:
                    if f"{name}.{alias}" in table:
                        result[f"{name}.{alias}"] = ""
    for item in sets:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or "." not in key:
            raise OverrideError(f"--set {item}: write --set NAME.PARAM=VALUE, e.g. "
                                "--set detector.red_min=120")
        if key not in table:
            raise OverrideError(f"--set {item}: {unknown(key, table)}")
        result[key] = convert(key, text, table[key])
    return result
