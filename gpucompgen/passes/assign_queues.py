"""assign-queues: which in-order queue ("lane") runs each GPU command, and what it waits for.

parallel: a command continues the lane of its first GPU input whose lane it ends;
otherwise it takes a lane the host has already waited for, else a new lane.  It waits
for the events of inputs made on other lanes (unless the host already waited for
them).  The host waits where it reads a result (GPU-to-CPU adapters, which block) and,
at the end of a frame, for lane ends no host read covers, so a frame is complete before
the next one reuses any buffer.  sequential: one lane, every copy blocks.
"""

from __future__ import annotations

from ..ir import AdapterNode, ComponentNode, GroupNode, System
from ..model import Endpoint
from .base import Pass


def gpu_command(system: System, name: str) -> bool:
    """A node that enqueues OpenCL commands: an adapter, a component placed on the GPU, or
    a group."""
    node = system.nodes[name]
    return isinstance(node, (AdapterNode, GroupNode)) or (isinstance(node, ComponentNode)
                                                          and node.on_gpu)


class AssignQueues(Pass):
    name = "assign-queues"

    def apply(self, system, rep):
        producer = {n: [p for p in system.predecessors(n) if gpu_command(system, p)]
                    for n in system.order if gpu_command(system, n)}
        # zero-copy GPU-to-CPU adapters unmap after the last node that reads their view
        last_reader: dict[str, str] = {}
        for n in system.order:
            node = system.nodes[n]
            if isinstance(node, AdapterNode):
                continue
            for pname in node.inputs:
                src = system.writer(Endpoint(n, pname))
                a = system.nodes[src.component]
                if isinstance(a, AdapterNode) and a.zero_copy and a.direction == "gpu2cpu":
                    last_reader[a.name] = n
        for a_name, reader in sorted(last_reader.items()):
            system.unmap_after.setdefault(reader, []).append(a_name)
        sequential = system.execution == "sequential"
        tails: list[str] = []  # last command of each lane
        synced: set[str] = set()  # commands the host knows to be complete
        ancestors: dict[str, set[str]] = {}
        for name in system.order:
            if name not in producer:
                continue
            preds = producer[name]
            ancestors[name] = set(preds).union(*(ancestors[p] for p in preds))
            lane = 0 if sequential and tails else next(
                (system.lanes[p] for p in preds if tails[system.lanes[p]] == p), None)
            if lane is None:
                lane = next((i for i, t in enumerate(tails) if t in synced), len(tails))
                if lane == len(tails):
                    tails.append(name)
            tails[lane] = name
            system.lanes[name] = lane
            system.waits[name] = [p for p in preds if system.lanes[p] != lane
                                  and p not in synced]
            a = system.nodes[name]
            if not isinstance(a, AdapterNode):
                a = None
            if system.mode == "standard" or (sequential and a is not None and not a.zero_copy):
                # a blocking copy on the one in-order queue: everything before it is done
                synced |= set(system.lanes)
            elif a is not None and (a.direction == "gpu2cpu" or a.zero_copy):
                # a host read blocks (and a zero-copy upload enqueues nothing)
                synced |= {name} | (ancestors[name] if a.direction == "gpu2cpu" else set())
        system.frame_end_waits = [t for t in tails if t not in synced]
        return system
