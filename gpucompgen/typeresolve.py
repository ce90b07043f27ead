"""Generic ports: the element type and channels each port of one component carries.

A type's port may accept several element types or channel counts (``dtype: [uint8,
int16]``, ``channels: [1, 3]``, ``channels: any``), take another port's (``dtype:
src.dtype``, ``channels: src.channels``) or an int parameter's value (``channels: n``).
``resolve_ports`` fixes them for one component from what feeds its inputs, as
sizeexpr.evaluate fixes sizes; passes/resolve_types.py calls it for every component of a
model, in the order data flows, and reports what a port does not accept.
"""

from __future__ import annotations

from typing import Any

from .model.decls import DEPTH_CODES

Value = tuple[str, int]  # (dtype, channels)


def accepts_dtype(decl, dtype: str) -> bool:
    """An input takes frames of this element type (one that follows another port takes
    what that port has: resolve_ports compares them)."""
    if decl.dtype_of:
        return True
    return dtype in decl.dtypes if decl.dtypes else dtype == decl.dtype


def accepts_channels(decl, channels: int) -> bool:
    if decl.channels_of or decl.channels_param:
        return True
    if decl.any_channels:
        return channels >= 1
    return channels in decl.channel_counts if decl.channel_counts else channels == decl.channels


def param_channels(decl, params: dict[str, Any]) -> int:
    value = params.get(decl.channels_param)
    return value if isinstance(value, int) and not isinstance(value, bool) and value >= 1 \
        else decl.channels


def param_dtype(decl, params: dict[str, Any], resolved: dict[str, Value]) -> str:
    """An output's element type from its int parameter, OpenCV's depth code (-1: the
    first input's); its declared dtype where the value is no code."""
    code = params.get(decl.dtype_param)
    if code == -1 and resolved:
        return next(iter(resolved.values()))[0]
    return DEPTH_CODES.get(code, decl.dtype) if isinstance(code, int) else decl.dtype


def resolve_ports(ctype, given: dict[str, tuple[str | None, int | None]],
                  params: dict[str, Any]) -> dict[str, Value]:
    """Every port's (dtype, channels) for a component whose inputs are fed given[port]
    ((dtype, channels); None where not known): an input takes what feeds it where it
    accepts it, else its first choice; a port that follows an earlier one takes its
    value; an output its own, its input's or its parameter's."""
    out: dict[str, Value] = {}
    for pname, decl in (*ctype.inputs.items(), *ctype.outputs.items()):
        gd, gc = given.get(pname, (None, None)) if decl.direction == "in" else (None, None)
        if decl.dtype_of:
            dtype = out[decl.dtype_of][0] if decl.dtype_of in out else decl.dtype
        elif decl.dtype_param:
            dtype = param_dtype(decl, params, out)
        elif gd is not None and accepts_dtype(decl, gd):
            dtype = gd
        else:
            dtype = decl.dtype
        if decl.channels_of:
            channels = out[decl.channels_of][1] if decl.channels_of in out else decl.channels
        elif decl.channels_param:
            channels = param_channels(decl, params)
        elif gc is not None and accepts_channels(decl, gc):
            channels = gc
        else:
            channels = decl.channels
        out[pname] = (dtype, channels)
    return out


def choices_text(decl, what: str) -> str:
    """What a port takes, for messages: 'uint8, int16 or float32', '1 or 3', 'any'."""
    if what == "dtype":
        values = list(decl.dtypes) or [decl.dtype]
    elif decl.any_channels:
        return "any number of"
    else:
        values = [str(c) for c in decl.channel_counts] or [str(decl.channels)]
    return values[0] if len(values) == 1 else ", ".join(values[:-1]) + " or " + values[-1]
