"""The system IR: single passes on small hand-built IRs, and verify() on broken ones."""

from __future__ import annotations

import pytest

from gpucompgen.device import PROFILES
from gpucompgen.errors import Pos, Reporter
from gpucompgen.ir import (
    AdapterNode,
    Data,
    Edge,
    GroupNode,
    Port,
    System,
    VerifyError,
    component_node,
)
from gpucompgen.model import Endpoint, library_types
from gpucompgen.passes.check_connections import CheckConnections
from gpucompgen.passes.check_port_types import CheckPortTypes
from gpucompgen.passes.insert_adapters import InsertAdapters
from gpucompgen.passes.name_variables import NameVariables
from gpucompgen.passes.propagate_sizes import PropagateSizes
from gpucompgen.passes.resolve_types import ResolveTypes
from gpucompgen.passes.schedule import Schedule
from gpucompgen.runtime import Size

TYPES = library_types()


def E(text: str) -> Endpoint:
    component, port = text.split(".")
    return Endpoint(component, port)


def hand_built(*edges: str, mode: str = "gpu-aware", **nodes: str) -> System:
    """A system of library components (name=Type) joined by edges ('a.x -> b.y'), with the
    types' default parameters; model-level settings are not needed by the passes tested."""
    system = System("hand", None, PROFILES["portable"], mode)
    for i, (name, tname) in enumerate(nodes.items()):
        t = TYPES[tname]
        params = {k: d.default for k, d in t.params.items()}
        system.add_node(component_node(name, t, params, Pos("hand.yaml", i + 1, 1), i, mode))
    for e in edges:
        src, dst = (s.strip() for s in e.split("->"))
        system.edges.append(Edge(E(src), E(dst)))
    return system


def apply(system: System, *passes) -> Reporter:
    rep = Reporter()
    for p in passes:
        p.apply(system, rep)
        system.done.append(p.name)
        if not rep.has_errors:
            system.verify()
    return rep


def chain() -> System:
    """camera -> mirror -> blur -> sink: one upload, one download."""
    return hand_built("camera.image -> mirror.src", "mirror.dst -> blur.src",
                      "blur.dst -> sink.image", camera="Camera", mirror="VerticalMirror",
                      blur="BoxBlur", sink="FrameSink")


def test_schedule_orders_a_hand_built_chain_given_backwards():
    system = hand_built("b.dst -> c.image", "a.image -> b.src",
                        c="FrameSink", b="VerticalMirror", a="Camera")
    rep = apply(system, CheckConnections(), ResolveTypes(), Schedule())
    assert not rep.has_errors
    # the model order (c, b, a) only breaks ties; the edges decide
    assert system.order == ["a", "b", "c"]
    assert system.stages == {"a": 1, "b": 2, "c": 3}


def test_schedule_reports_a_cycle():
    system = hand_built("m1.dst -> m2.src", "m2.dst -> m1.src",
                        m1="VerticalMirror", m2="VerticalMirror")
    rep = apply(system, Schedule())
    assert [d.message for d in rep.diagnostics if d.severity == "error"] == [
        "the connections form a cycle: m1 -> m2 -> m1"]


def test_check_connections_drops_a_second_writer_and_reports_it():
    system = hand_built("a.image -> s.image", "b.image -> s.image",
                        a="Camera", b="Camera", s="FrameSink")
    rep = apply(system, CheckConnections())
    assert [d.message for d in rep.diagnostics if d.severity == "error"] == [
        "input 's.image' has two writers: 'a.image' and 'b.image'"]
    assert [str(e) for e in system.edges] == ["a.image -> s.image"]


def test_propagate_sizes_puts_data_on_ports_and_edges():
    system = chain()
    apply(system, CheckConnections(), ResolveTypes(), Schedule(), PropagateSizes())
    frame = Data(Size(480, 640, 3), "uint8")
    assert all(e.data == frame for e in system.edges)
    assert system.data(E("blur.dst")) == frame and frame.nbytes == 921_600


def test_insert_adapters_rewires_the_edges_through_new_nodes():
    system = chain()
    apply(system, CheckConnections(), ResolveTypes(), Schedule(), PropagateSizes(), InsertAdapters())
    assert system.order == ["camera", "adapter1_cpu2gpu", "mirror", "blur",
                            "adapter2_gpu2cpu", "sink"]
    assert sorted(str(e) for e in system.edges) == sorted([
        "camera.image -> adapter1_cpu2gpu.input", "adapter1_cpu2gpu.output -> mirror.src",
        "mirror.dst -> blur.src", "blur.dst -> adapter2_gpu2cpu.input",
        "adapter2_gpu2cpu.output -> sink.image"])
    up = system.nodes["adapter1_cpu2gpu"]
    assert isinstance(up, AdapterNode) and up.source == E("camera.image")
    assert (up.inputs["input"].memory, up.outputs["output"].memory) == ("cpu", "gpu")


def test_insert_adapters_serves_every_output_of_a_node_that_crosses():
    """Issue 12, section 1: the second output crossing memories crashed with a KeyError."""
    system = hand_built("camera.image -> m.src", "m.dst -> s1.image",
                        "m.dst -> s2.image", "camera.image -> b.src",
                        "b.dst -> s3.image", camera="Camera", m="VerticalMirror",
                        b="BoxBlur", s1="FrameSink", s2="FrameSink", s3="FrameSink")
    apply(system, CheckConnections(), ResolveTypes(), Schedule(), PropagateSizes(), InsertAdapters(),
          NameVariables())
    adapters = [a.name for a in system.adapters]
    # one upload shared by both GPU consumers, one download per GPU output
    assert adapters == ["adapter1_cpu2gpu", "adapter2_gpu2cpu", "adapter3_gpu2cpu"]
    assert sorted(map(str, system.readers(E("adapter1_cpu2gpu.output")))) == [
        "b.src", "m.src"]
    assert sorted(map(str, system.readers(E("adapter2_gpu2cpu.output")))) == [
        "s1.image", "s2.image"]
    assert system.output_vars[E("adapter3_gpu2cpu.output")] == "b_dst_cpu"


def test_standard_mode_needs_no_adapters():
    system = hand_built("camera.image -> m.src", "m.dst -> s.image", mode="standard",
                        camera="Camera", m="VerticalMirror", s="FrameSink")
    apply(system, CheckConnections(), ResolveTypes(), Schedule(), PropagateSizes(), InsertAdapters())
    assert system.adapters == [] and len(system.edges) == 2


def test_dump_prints_every_node_port_and_edge():
    system = chain()
    apply(system, CheckConnections(), ResolveTypes(), Schedule(), PropagateSizes(), InsertAdapters())
    text = system.dump()
    for line in ("component mirror: VerticalMirror on GPU [stage 2]",
                 "in src: GPU uint8x3 = 480x640x3 uint8",
                 "adapter adapter2_gpu2cpu: gpu2cpu of blur.dst [stage 3]",
                 "edge blur.dst -> adapter2_gpu2cpu.input : 480x640x3 uint8"):
        assert line in text, text
    assert text == system.dump()  # deterministic


# --- verify() on broken IRs: each breakage named ------------------------------------------

def checked_chain() -> System:
    system = chain()
    apply(system, CheckConnections(), ResolveTypes(), CheckPortTypes(), Schedule(), PropagateSizes(),
          InsertAdapters(), NameVariables())
    return system


def _break_missing_endpoint(s):
    s.edges.append(Edge(E("ghost.out"), E("sink.image")))


def _break_second_writer(s):
    s.edges.append(Edge(E("mirror.dst"), E("sink.image")))


def _break_unfed_input(s):
    s.edges = [e for e in s.edges if e.target != E("blur.src")]


def _break_crossing_without_adapter(s):
    s.remove_node("adapter1_cpu2gpu")
    s.edges.append(Edge(E("camera.image"), E("mirror.src"), data=s.data(E("camera.image"))))


def _break_size(s):
    s.nodes["blur"].outputs["dst"].data = None


def _break_order(s):
    s.order.remove("mirror")
    s.order.append("mirror")


def _break_name(s):
    s.nodes["renamed"] = s.nodes.pop("sink")


def _break_group(s):
    s.nodes["g"] = GroupNode("g", Pos(""), {}, {}, members=[s.nodes["blur"]])
    s.order.append("g")


def _break_edge_data(s):
    s.edges[0].data = Data(Size(1, 1, 3), "uint8")


def _break_port_types(s):
    s.nodes["sink"].inputs["image"] = Port("image", "in", "cpu", "float32", 3,
                                           s.data(E("sink.image")))


@pytest.mark.parametrize("breakage,message", [
    (_break_missing_endpoint, "edge ghost.out -> sink.image: no output 'ghost.out'"),
    (_break_second_writer, "input 'sink.image' has 2 writers"),
    (_break_unfed_input, "input 'blur.src' has 0 writers"),
    (_break_crossing_without_adapter, "edge camera.image -> mirror.src crosses from CPU to "
                                      "GPU memory without an adapter"),
    (_break_size, "port 'blur.dst' has no size"),
    (_break_order, "the order runs 'blur' before 'mirror', which feeds it"),
    (_break_name, "node 'sink' is filed as 'renamed'"),
    (_break_group, "'blur' is a member of group 'g' and a node"),
    (_break_edge_data, "edge camera.image -> adapter1_cpu2gpu.input carries 1x1x3 uint8"),
    (_break_port_types, "edge adapter2_gpu2cpu.output -> sink.image joins uint8x3 to "
                        "float32x3"),
], ids=lambda v: v.__name__.removeprefix("_break_") if callable(v) else "")
def test_verify_names_what_is_broken(breakage, message):
    system = checked_chain()
    system.verify()  # whole, it holds
    breakage(system)
    with pytest.raises(VerifyError, match="name-variables") as err:
        system.verify()
    assert message in str(err.value)


def test_verify_checks_only_what_the_passes_so_far_promise():
    system = chain()
    system.edges.append(Edge(E("camera.image"), E("sink.image")))  # two writers
    system.verify()  # nothing checked yet: fine
    system.done.append("check-connections")
    with pytest.raises(VerifyError, match="input 'sink.image' has 2 writers"):
        system.verify()
