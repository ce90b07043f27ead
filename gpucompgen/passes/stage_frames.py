"""stage-frames: with frames in flight (N >= 2), the stages that work on different frames at
the same time, and which buffers need one set per frame in flight.

A stage is a run of consecutive nodes of the schedule on one side — the host (standard
components) or the device (GPU-aware components and their adapters) — run by one thread,
frame after frame (GStreamer's queue, G-API streaming): so each component is still called
by one thread, in frame order.  The sources, with the CPU-to-GPU adapters that upload their
frames, form the first stage, so one thread decides where the stream ends.

Which buffers need N sets follows from one rule, applied to what each stage reads and
writes, whatever kind of node writes it (a component, a fused group, an adapter, a CPU
function): a buffer written in one stage and read in another is written for frame f + 1
while frame f is read, so it needs a set per frame in flight (used in turn; at most N
frames are in the pipeline, so a set is rewritten only when its frame has left it).  A
buffer read only in the stage that writes it needs one set: the stage finishes a frame
before it starts the next.

Where the data of an output lives (`holders`) is the one thing that depends on the node:
its own buffer for a component, a group or a copying adapter; for a zero-copy download
also the mapped device buffer of the node that wrote it (its reader reads that memory);
for a zero-copy upload the adapter's own kept copy of the frame (the producer may
overwrite the frame itself).  A part that can keep sets (a GPU component or group, an
adapter) gets them; a CPU component (standard, or a flexible one placed on the CPU) owns
one array per output, so a read of it in another stage would need a copy the system does
not make: the stages from its producer to that reader are merged instead (said in the
plan).  A stage hands a frame on only once its device commands are complete (it waits
for the events of its queues' last commands), so no command waits for an event of another
stage's frame.
"""

from __future__ import annotations

from ..ir import AdapterNode, ComponentNode, System
from ..model import Endpoint
from .assign_queues import gpu_command
from .base import Pass


class StageFrames(Pass):
    name = "stage-frames"

    def apply(self, system, rep):
        system.flight_stages, system.flight_notes = [], []
        system.flight_end_waits, system.buffer_sets, system.one_set = [], {}, {}
        if system.frames_in_flight < 2:
            return system
        stage_of, notes = _stages(system)
        count = max(stage_of.values(), default=-1) + 1
        system.flight_stages = [[n for n in system.order if stage_of[n] == s]
                                for s in range(count)]
        system.flight_notes = notes
        system.buffer_sets = _buffer_sets(system, stage_of)
        system.one_set = one_set_reasons(system, stage_of)
        system.flight_end_waits = [_end_waits(system, names) for names in system.flight_stages]
        return system


def side(system: System, name: str) -> str:
    node = system.nodes[name]
    if isinstance(node, AdapterNode):
        return "host" if node.direction == "cpu2gpu" else "device"
    return "device" if node.on_gpu else "host"


def is_source(system: System, name: str) -> bool:
    node = system.nodes[name]
    return isinstance(node, ComponentNode) and not node.inputs and not node.on_gpu


def _stages(system: System) -> tuple[dict[str, int], list[str]]:
    stage: dict[str, int] = {}
    sources = [n for n in system.order if is_source(system, n)]
    for n in sources:
        stage[n] = 0
    current, current_side = (0, "host") if sources else (-1, "")
    for n in system.order:
        if n in stage:
            continue
        node = system.nodes[n]
        if isinstance(node, AdapterNode) and node.direction == "cpu2gpu":
            # uploads run in the stage of the frame's producer: the device stage gets
            # complete device data, and the producer may go on to its next frame
            stage[n] = stage[node.source.component]
            continue
        if side(system, n) != current_side:
            current, current_side = current + 1, side(system, n)
        stage[n] = current
    notes: list[str] = []
    while True:  # data that cannot keep sets read in another stage: merge those stages
        crossing = next(((e, h, stage[h], stage[e.target.component])
                         for e in system.edges for h in holders(system, e.source)
                         if not keeps_sets(system, h)
                         and stage[h] != stage[e.target.component]), None)
        if crossing is None:
            break
        e, h, low, high = crossing
        low, high = min(low, high), max(low, high)
        notes.append(f"{e.source} is read by {e.target.component} in a later stage; "
                     f"{h} keeps one array per output, so those stages are one")
        for n, s in stage.items():
            if low <= s <= high:
                stage[n] = low
            elif s > high:
                stage[n] = s - (high - low)
    return stage, notes


def holders(system: System, end: Endpoint) -> list[str]:
    """The parts whose memory holds the data of an output endpoint when its readers read
    it: the endpoint's own node, and for a zero-copy download also the holders of what it
    maps (the device buffer of the node that wrote it)."""
    node = system.nodes[end.component]
    if isinstance(node, AdapterNode) and node.direction == "gpu2cpu" and node.zero_copy:
        return [end.component, *holders(system, system.writer(Endpoint(end.component,
                                                                        "input")))]
    return [end.component]


def keeps_sets(system: System, name: str) -> bool:
    """Whether a part can keep a set of its outputs per frame in flight: GPU components,
    groups and adapters allocate their buffers from the plan; a CPU component owns one
    array per output (or returns its own)."""
    node = system.nodes[name]
    return isinstance(node, AdapterNode) or bool(node.on_gpu)


def _buffer_sets(system: System, stage: dict[str, int]) -> dict[str, str]:
    """Every part whose outputs are read in a stage other than the one that writes them,
    with why (the first such read)."""
    sets: dict[str, str] = {}
    for e in system.edges:
        reader = e.target.component
        for h in holders(system, e.source):
            if stage[h] == stage[reader] or h in sets:
                continue
            how = "" if h == e.source.component else f", mapped by {e.source.component}"
            sets[h] = (f"written in stage{stage[h] + 1}, read in stage{stage[reader] + 1} by "
                       f"{reader}{how}: the next frame is written while this one is read")
    return dict(sorted(sets.items(), key=lambda kv: system.order.index(kv[0])))


def one_set_reasons(system: System, stage: dict[str, int]) -> dict[str, str]:
    """Why each part with outputs that keeps one set of them has one."""
    why: dict[str, str] = {}
    for n in system.order:
        if not system.nodes[n].outputs or n in system.buffer_sets:
            continue
        why[n] = f"written and read in stage{stage[n] + 1} only" + (
            "" if keeps_sets(system, n) else ": a CPU component keeps one array per output")
    return why


def _end_waits(system: System, names: list[str]) -> list[str]:
    """The commands a stage waits for before handing a frame on: the last command of each
    queue it uses, unless that one blocks the host (a GPU-to-CPU copy or map, a blocking
    upload) or enqueues nothing (a zero-copy upload)."""
    last: dict[int, str] = {}
    for n in names:
        if gpu_command(system, n) and system.mode != "standard":
            last[system.lanes.get(n, 0)] = n
    waits = []
    for n in last.values():
        node = system.nodes[n]
        if isinstance(node, AdapterNode):
            if node.direction == "gpu2cpu" or node.zero_copy:
                continue
            if system.execution == "sequential":
                continue  # a blocking copy
        waits.append(n)
    return sorted(waits, key=system.order.index)
