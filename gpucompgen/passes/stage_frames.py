"""stage-frames: with frames in flight (N >= 2), the stages that work on different frames at
the same time, and which buffers need one set per frame in flight.

A stage is a run of consecutive nodes of the schedule on one side — the host (standard
components) or the device (GPU-aware components and their adapters) — run by one thread,
frame after frame (GStreamer's queue, G-API streaming): so each component is still called
by one thread, in frame order.  The sources, with the CPU-to-GPU adapters that upload their
frames, form the first stage, so one thread decides where the stream ends.

Which buffers need N sets follows from one rule: a buffer written in one stage and read in
another is written for frame f + 1 while frame f is read, so it needs a set per frame in
flight (used in turn; at most N frames are in the pipeline, so a set is rewritten only
when its frame has left it).  A buffer read only in the stage that writes it needs one set:
the stage finishes a frame before it starts the next.  That gives:

- a CPU-to-GPU adapter's device buffer (written by the sources' stage, read by the
  device's); zero-copy: the frame itself, which the producer may overwrite, so the adapter
  keeps its own copy of each frame (a host copy, no CPU-GPU copy);
- a GPU-to-CPU adapter's host array (written by the device's stage, read by the sinks');
  zero-copy: the mapped device buffer of the component that writes it;
- a GPU-aware component's output read by a GPU-aware component in another stage (and, in
  standard mode, where components copy their own data, its host outputs).

Standard components own their outputs, one array each, so one read in another stage
would need a copy the system does not make: the stages from its producer to that reader
are merged instead (said in the plan).  A stage hands a frame on only once its device
commands are complete (it waits for the events of its queues' last commands), so no
command waits for an event of another stage's frame.
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
        system.flight_end_waits, system.buffer_sets = [], {}
        if system.frames_in_flight < 2:
            return system
        stage_of, notes = _stages(system)
        count = max(stage_of.values(), default=-1) + 1
        system.flight_stages = [[n for n in system.order if stage_of[n] == s]
                                for s in range(count)]
        system.flight_notes = notes
        system.buffer_sets = _buffer_sets(system, stage_of)
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
    while True:  # a standard component's output read in another stage: merge them
        crossing = next(((e, stage[e.source.component], stage[e.target.component])
                         for e in system.edges
                         if isinstance(system.nodes[e.source.component], ComponentNode)
                         and not system.nodes[e.source.component].on_gpu
                         and stage[e.source.component] != stage[e.target.component]), None)
        if crossing is None:
            break
        e, low, high = crossing
        notes.append(f"{e.source} is read by {e.target.component} in a later stage; a "
                     "standard component keeps one output array, so those stages are one")
        for n, s in stage.items():
            if low <= s <= high:
                stage[n] = low
            elif s > high:
                stage[n] = s - (high - low)
    return stage, notes


def _buffer_sets(system: System, stage: dict[str, int]) -> dict[str, str]:
    sets: dict[str, str] = {}
    for e in system.edges:
        p, c = e.source.component, e.target.component
        if stage[p] == stage[c]:
            continue
        node = system.nodes[p]
        if isinstance(node, AdapterNode):
            if node.direction == "cpu2gpu":
                sets[p] = (f"{c} reads frame f's copy of {node.source} while the next frame "
                           "is " + ("kept" if node.zero_copy else "copied"))
            elif node.zero_copy:
                sets[p] = f"{c} reads frame f's mapped {node.source} while the next is mapped"
                # the node that writes it: its component, or the fused group it is in
                writer = system.writer(Endpoint(p, "input")).component
                sets[writer] = (f"{node.source} stays mapped for {c} while the next frame "
                                "is written")
            else:
                sets[p] = f"{c} reads frame f's {node.source} while the next is copied"
        elif isinstance(node, ComponentNode) and node.on_gpu:
            sets[p] = f"{c} reads frame f's {e.source} while the next frame is written"
    return dict(sorted(sets.items(), key=lambda kv: system.order.index(kv[0])))


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
