"""Ports: the loader of a type's 'inputs:' and 'outputs:' (memory, element type and
channels, fixed or generic), the checks of what generic ports follow, and the size
expressions of outputs."""

from __future__ import annotations

import re
from dataclasses import replace
from typing import Any

from .. import sizeexpr
from ..errors import did_you_mean
from ..names import fold, name_problem
from .decls import ANY, DTYPES, MAX_PORTS, MEMORIES, ComponentType, ParamDecl, PortDecl
from .fields import _expect_map, _named, _positive_int, _unknown_keys
from .params import _int_params

PORT_KEYS = ("memory", "dtype", "channels", "height", "width", "description", "aliases")


def _load_port(doc, rep, path, ctype, direction, pname, pspec) -> PortDecl | None:
    problem = name_problem(pname, "port name")
    if problem:
        rep.error(doc.key_pos(*path), problem)
        return None
    pspec = _expect_map(doc, rep, path, pspec, f"port '{pname}'")
    _unknown_keys(doc, rep, path, pspec, PORT_KEYS, f"port '{pname}'")
    if ctype.kind == "flexible":
        if "memory" in pspec:
            rep.error(doc.key_pos(*path, "memory"),
                      f"port '{pname}' of flexible type '{ctype.name}' has no memory of its "
                      "own: it lives where the component is placed",
                      "remove 'memory:'; the system inserts the adapters its neighbours need")
        memory = "any"
    else:
        memory = pspec.get("memory", "cpu")
    if memory != "any" and memory not in MEMORIES:
        rep.error(doc.pos(*path, "memory"), f"port '{pname}': memory must be 'gpu' or 'cpu', "
                  f"not {memory!r}")
        return None
    if memory == "gpu" and ctype.kind == "standard":
        rep.error(doc.pos(*path, "memory"),
                  f"standard type '{ctype.name}' cannot have GPU port '{pname}'",
                  "standard components have only CPU ports; make the type 'kind: gpu-aware'")
        return None
    if memory == "cpu" and ctype.kind == "gpu-aware":
        rep.error(doc.pos(*path, "memory"),
                  f"GPU-aware kernel type '{ctype.name}': port '{pname}' must be a GPU port",
                  "kernel components read and write device buffers; let the system insert "
                  "adapters by declaring 'memory: gpu'")
        return None
    generic = _generic_spec(doc, rep, path, ctype, pname, pspec)
    if generic is None:
        return None
    dtype, channels, extra = generic
    if direction == "in":
        for key in ("height", "width"):
            if key in pspec:
                rep.error(doc.key_pos(*path, key),
                          f"input port '{pname}' takes its size from what feeds it",
                          f"remove '{key}'; sizes are declared on outputs")
    aliases = pspec.get("aliases", [])
    if not isinstance(aliases, list) or any(name_problem(a, "port alias") for a in aliases):
        rep.error(doc.pos(*path, "aliases"), f"aliases of port '{pname}' must be a list of "
                  "port names", "e.g. 'aliases: [image]': old names still accepted")
        aliases = []
    return PortDecl(pname, direction, memory, dtype, channels, pos=doc.key_pos(*path),
                    aliases=tuple(aliases), **extra)


FOLLOW_RE = re.compile(r"^\s*([A-Za-z_]\w*)\s*\.\s*(dtype|channels)\s*$")


def _generic_spec(doc, rep, path, ctype, pname, pspec) -> tuple[str, int, dict] | None:
    """A port's dtype and channels as declared: fixed, a list of choices, 'any', another
    port's ('src.dtype', 'src.channels') or an int parameter's value (channels only).
    Returns (dtype, channels, the PortDecl fields of a generic port); which port or
    parameter is followed is checked once every port is known (_check_generic)."""
    extra: dict[str, Any] = {}
    dtype = pspec.get("dtype", "uint8")
    follow = FOLLOW_RE.match(dtype) if isinstance(dtype, str) else None
    if follow and follow[2] == "dtype":
        extra["dtype_of"], dtype = follow[1], "uint8"
    elif dtype in ANY or isinstance(dtype, list):
        choices = list(DTYPES) if dtype in ANY else dtype
        bad = [d for d in choices if not _named(d, DTYPES)]
        if bad or not choices or len(set(choices)) != len(choices):
            rep.error(doc.pos(*path, "dtype"), f"port '{pname}': dtype must list distinct "
                      f"element types of {', '.join(DTYPES)}"
                      + (f"; {bad[0]!r} is none" if bad else ""),
                      did_you_mean(str(bad[0]), DTYPES) if bad else "e.g. [uint8, int16]")
            return None
        if len(choices) > 1:
            extra["dtypes"] = tuple(choices)
        dtype = choices[0]
    elif isinstance(dtype, str) and dtype.isidentifier() and dtype not in DTYPES \
            and dtype in ctype.params:
        extra["dtype_param"], dtype = dtype, "uint8"
    elif not _named(dtype, DTYPES):
        rep.error(doc.pos(*path, "dtype"), f"port '{pname}': unknown element type {dtype!r}",
                  did_you_mean(str(dtype), DTYPES) or
                  "an element type, a list of them, 'any', '<input>.dtype' or an int "
                  "parameter holding OpenCV's depth code")
        return None
    channels = pspec.get("channels")
    follow = FOLLOW_RE.match(channels) if isinstance(channels, str) else None
    if follow and follow[2] == "channels":
        extra["channels_of"], channels = follow[1], 1
    elif channels in ANY:
        extra["any_channels"], channels = True, 1
    elif isinstance(channels, str) and channels.isidentifier():
        extra["channels_param"], channels = channels, 1
    elif isinstance(channels, list):
        if not channels or len(set(channels)) != len(channels) or not all(
                isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in channels):
            rep.error(doc.pos(*path, "channels"), f"port '{pname}': channels must list "
                      "distinct positive integers", "e.g. 'channels: [1, 3]'")
            return None
        if len(channels) > 1:
            extra["channel_counts"] = tuple(channels)
        channels = channels[0]
    else:
        channels = _positive_int(doc, rep, path + ("channels",), channels, "channels", 1)
    return dtype, channels, extra


def _check_generic(doc, rep, base, ctype: ComponentType, spec: dict) -> None:
    """What generic ports follow exists, and every generic port can be resolved: an input
    follows an earlier input, an output an input or an int parameter; an output never
    chooses among several (nothing would choose); a hand-written kernel is written for
    one element type and channel count."""
    inputs = list(ctype.inputs)
    for key, ports in (("inputs", ctype.inputs), ("outputs", ctype.outputs)):
        for pname, port in ports.items():
            path = base + (key, pname)
            for what, followed in (("dtype", port.dtype_of), ("channels", port.channels_of)):
                if not followed:
                    continue
                earlier = inputs[:inputs.index(pname)] if key == "inputs" else inputs
                if followed not in earlier:
                    rep.error(doc.pos(*path, what), f"port '{pname}' of '{ctype.name}' takes "
                              f"the {what} of '{followed}', which is no "
                              + ("earlier input" if key == "inputs" else "input") + " port",
                              did_you_mean(followed, earlier) or
                              f"write '{what}: <input>.{what}' with one of its inputs")
            if port.dtype_param and (key == "inputs" or ctype.params[
                    port.dtype_param].type != "int"):
                rep.error(doc.pos(*path, "dtype"), f"dtype of port '{pname}' of "
                          f"'{ctype.name}' names parameter {port.dtype_param!r}, which "
                          + ("an input cannot follow" if key == "inputs"
                             else "is no int parameter"),
                          "an output's element type may follow an int parameter holding "
                          "OpenCV's depth code (-1: the first input's)")
            if port.channels_param and ctype.params.get(port.channels_param, ParamDecl(
                    "", "")).type != "int":
                rep.error(doc.pos(*path, "channels"), f"channels of port '{pname}' of "
                          f"'{ctype.name}' name {port.channels_param!r}, which is no int "
                          "parameter", did_you_mean(port.channels_param, _int_params(ctype))
                          or "give a number, a list, 'any', '<input>.channels' or an int "
                          "parameter")
            if key == "outputs" and (port.dtypes or port.channel_counts or port.any_channels):
                what = "dtype" if port.dtypes else "channels"
                rep.error(doc.pos(*path, what), f"output '{pname}' of '{ctype.name}' may "
                          f"have several {what}: nothing would choose one",
                          f"give one, or follow an input: '{what}: "
                          f"{inputs[0] if inputs else '<input>'}.{what}'"
                          + (" or an int parameter" if what == "channels" else ""))
    if ctype.generic and "kernel" in spec:
        rep.error(doc.key_pos(*base, "kernel"), f"'{ctype.name}' has generic ports and a "
                  "hand-written kernel, which is written for one element type and channel "
                  "count", "give the type a fusable form instead (its kernel is generated "
                  "for each component), or fix its ports' dtype and channels")


def _port_sizes(doc, rep, path, ctype, port: PortDecl, quiet: bool = False) -> PortDecl:
    """Parse an output's size expressions; quiet: an input failed (already reported), so a
    missing size that the input would have given is not reported again."""
    spec = doc.data
    for key in path:
        spec = spec.get(key, {}) if isinstance(spec, dict) else {}
    trees = {}
    for dim in sizeexpr.DIMS:
        text = spec.get(dim) if isinstance(spec, dict) else None
        if text is None:
            if len(ctype.inputs) == 1:  # default: same size as the only input
                text = f"{next(iter(ctype.inputs))}.{dim}"
            elif quiet:
                continue
            else:
                rep.error(port.pos, f"output '{port.name}' of '{ctype.name}' needs '{dim}:'",
                          f"give a size expression, e.g. '{dim}: 480' or "
                          f"'{dim}: <input>.{dim}'")
                continue
        try:
            trees[dim] = sizeexpr.parse(text, set(ctype.inputs), set(_int_params(ctype)))
        except sizeexpr.SizeExprError as exc:
            rep.error(doc.pos(*path, dim), f"output '{port.name}' of '{ctype.name}': {exc}")
    return replace(port, height=trees.get("height"), width=trees.get("width"))


def _load_ports(doc, rep, base: tuple, ctype: ComponentType, spec: dict) -> int | None:
    """A type's 'inputs:' and 'outputs:' into ctype (names distinct, aliases included):
    how many inputs failed to load, or None when there are too many ports to load."""
    seen_ports: dict[str, str] = {}
    failed_inputs = 0
    for direction, key in (("in", "inputs"), ("out", "outputs")):
        ports = _expect_map(doc, rep, base + (key,), spec.get(key), key)
        if len(ports) > MAX_PORTS:
            rep.error(doc.key_pos(*base, key),
                      f"component type '{ctype.name}' has {len(ports):,} {key}; at most "
                      f"{MAX_PORTS:,} are allowed", "split the component")
            return None
        for pname, pspec in ports.items():
            port = _load_port(doc, rep, base + (key, pname), ctype, direction, pname, pspec)
            if port is None:
                failed_inputs += direction == "in"
                continue
            if fold(pname) in seen_ports:
                rep.error(doc.key_pos(*base, key, pname),
                          f"port '{pname}' collides with port '{seen_ports[fold(pname)]}'",
                          "input and output ports of a type need distinct names")
                continue
            seen_ports[fold(pname)] = pname
            for alias in port.aliases:
                if fold(alias) in seen_ports:
                    rep.error(doc.pos(*base, key, pname, "aliases"),
                              f"alias '{alias}' of port '{pname}' collides with port "
                              f"'{seen_ports[fold(alias)]}'", "give each port its own names")
                seen_ports.setdefault(fold(alias), f"{pname}' (alias '{alias}')")
            (ctype.inputs if direction == "in" else ctype.outputs)[pname] = port
    return failed_inputs
