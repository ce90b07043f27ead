"""What a program says of its model and lets its user change, recorded in the plan.

After lowering: the model's description, digests of the model and the files it names, the
components in run order, which parameters ``--set`` may change when the program starts (a
parameter no size, requirement, channel count or stencil radius depends on: a generated
kernel takes it as a build option) and which parameters are paths relative to the model.
A backend prints these from the plan (``ProgramPlan.for_program``), never from the model.
"""

from __future__ import annotations

import ast
import dataclasses
import os
from pathlib import Path

from ..ir import ComponentNode, System
from ..plan import ProgramPlan, Settable


def size_names(t) -> set[str]:
    """The parameters a type's output sizes or requirements name, those that give a port
    its channels ('channels: n'), and a stencil's radius parameter (its generated kernel's
    window and interior are constants): fixed at build time."""
    exprs = [e for d in t.outputs.values() for e in (d.height, d.width) if e is not None]
    exprs += [check for check, _ in t.requires]
    names = {n.id for e in exprs for n in ast.walk(e) if isinstance(n, ast.Name)}
    names |= {d.channels_param for d in (*t.inputs.values(), *t.outputs.values())
              if d.channels_param}
    names |= {d.dtype_param for d in t.outputs.values() if d.dtype_param}
    decl = getattr(t, "fusable", None)
    if decl is not None:
        names |= decl.radius_names()
    return names


def settable(system: System, plan: ProgramPlan) -> tuple[Settable, ...]:
    """The parameters --set may change: every scalar parameter of a component, a launch or
    a group's build constants that nothing fixed at build time depends on."""
    found: dict[str, Settable] = {}

    def declare(key: str, t, value) -> None:
        pname = key.split(".", 1)[1]
        decl = t.params.get(pname)
        if decl is None or pname in size_names(t) or decl.shape:
            return  # arrays are tables compiled into a generated kernel
        found[key] = Settable(key, decl.type, value, decl.minimum, decl.maximum)

    for part in plan.parts:
        t = getattr(system.nodes.get(part.name), "type", None)
        if t is not None:
            for k, v in part.params:
                declare(f"{part.name}.{k}", t, v)
    for la in plan.launches:
        node = system.nodes[la.part]
        for a in la.arguments:
            if a.param:
                # a group's parameters are its members' (a group of one: the component's)
                owner = a.param.split(".", 1)[0]
                member = node.member(owner) if hasattr(node, "members") else node
                declare(a.param, member.type, a.value)
    members = {m.name: m for g in system.kernel_groups for m in g.members}
    for prog in plan.programs:
        for a in prog.defines:  # a group's constants: its members' parameters
            declare(a.param, members[a.param.split(".", 1)[0]].type, a.value)
    return tuple(sorted(found.values(), key=lambda s: s.key))


def path_params(system: System, plan: ProgramPlan) -> tuple[str, ...]:
    """The 'part.param' keys of parameters declared as paths (or inputs) with a value."""
    keys = []
    for part in plan.parts:
        decls = getattr(getattr(system.nodes.get(part.name), "type", None), "params", {})
        keys += [f"{part.name}.{k}" for k, v in part.params
                 if decls.get(k) is not None and decls[k].type in ("path", "input")
                 and isinstance(v, str) and v]
    return tuple(keys)


def with_program_facts(system: System, plan: ProgramPlan) -> ProgramPlan:
    """The plan with the facts above."""
    model = system.model
    folder = model.file.resolve().parent
    inputs = tuple(sorted((Path(os.path.relpath(p, folder)).as_posix(), digest)
                          for p, digest in model.inputs.items()
                          if p != model.file.resolve()))
    return dataclasses.replace(
        plan, description=model.description, model_sha256=model.text_sha256,
        model_inputs=inputs,
        sources=tuple(n for n in system.order if isinstance(system.nodes[n], ComponentNode)),
        settable=settable(system, plan), path_params=path_params(system, plan))
