"""Generic ports resolved per component (passes/resolve_types.py), on hand-written models.

Each case states, worked out by hand from the type declarations, the element type and
channels every port of the IR must carry after the pass; errors carry the connection's
line and column. Deprecated names (type aliases, old port names) resolve to the same IR.
"""

from __future__ import annotations

import pytest

from gpucompgen.device import PROFILES
from gpucompgen.errors import GpucompgenError
from gpucompgen.model import load_system
from gpucompgen.passes import run_passes

USER_TYPES = """\
component_types:
  Source:
    kind: standard
    description: A source of gray or colour frames, as its parameter says.
    params:
      n: {type: int, default: 3, min: 1, max: 4}
    outputs:
      dst: {memory: cpu, dtype: uint8, channels: n, height: 20, width: 30}
    python: {file: parts.py, class: Source}
  Floats:
    kind: standard
    description: float32 frames, any channels, following its input.
    inputs:
      src: {memory: cpu, channels: any}
    outputs:
      dst: {memory: cpu, dtype: float32, channels: src.channels}
    python: {file: parts.py, class: Floats}
  Keep:
    kind: standard
    description: Takes anything.
    inputs:
      src: {memory: cpu, dtype: any, channels: any}
    python: {file: parts.py, class: Keep}
"""
PARTS = """\
class Source:
    pass


class Floats:
    pass


class Keep:
    pass
"""


def resolved(tmp_path, components: dict, connections: list[str]) -> dict[str, str]:
    """{'component.port': 'dtype x channels'} of every port after the passes."""
    (tmp_path / "types.yaml").write_text(USER_TYPES)
    (tmp_path / "parts.py").write_text(PARTS)
    text = "system: s\ntypes: [types.yaml]\ncomponents:\n" + "".join(
        f"  {name}: {spec}\n" for name, spec in components.items()) + "connections:\n" + \
        "".join(f"  - {c}\n" for c in connections)
    (tmp_path / "m.yaml").write_text(text)
    system, _ = run_passes(load_system(tmp_path / "m.yaml"), PROFILES["portable"])
    return {f"{c}.{p.name}": f"{p.dtype}x{p.channels}" for c in components
            for p in system.component(c).ports}


def test_channels_and_element_types_follow_what_feeds_each_component(tmp_path):
    ports = resolved(tmp_path, {
        # listed against the flow: the order of the data decides, not the model's
        "sink3": "{type: Keep}", "sink1": "{type: Keep}", "sinkf": "{type: Keep}",
        "abs3": "{type: ConvertScale}", "abs1": "{type: ConvertScale}",
        "absf": "{type: ConvertScale}", "grad3": "{type: Sobel}", "grad1": "{type: Sobel}",
        "blur3": "{type: GaussianBlur}", "blur1": "{type: GaussianBlur}",
        "floats": "{type: Floats}", "diff": "{type: AbsDiff}",
        "colour": "{type: Source}", "gray": "{type: Source, params: {n: 1}}",
    }, [
        "colour.dst -> blur3.src", "gray.dst -> blur1.src",
        "blur3.dst -> grad3.src", "blur1.dst -> grad1.src",
        "grad3.dst -> abs3.src", "grad1.dst -> abs1.src",
        "abs3.dst -> diff.src1", "blur3.dst -> diff.src2", "diff.dst -> sink3.src",
        "abs1.dst -> sink1.src", "gray.dst -> floats.src", "floats.dst -> absf.src",
        "absf.dst -> sinkf.src",
    ])
    assert ports == {
        "colour.dst": "uint8x3", "gray.dst": "uint8x1",  # channels: n
        "blur3.src": "uint8x3", "blur3.dst": "uint8x3",  # [1, 3] -> src.channels
        "blur1.src": "uint8x1", "blur1.dst": "uint8x1",
        "grad3.src": "uint8x3", "grad3.dst": "int16x3",  # int16, src.channels
        "grad1.src": "uint8x1", "grad1.dst": "int16x1",
        "abs3.src": "int16x3", "abs3.dst": "uint8x3",  # [uint8, int16, float32] -> uint8
        "abs1.src": "int16x1", "abs1.dst": "uint8x1",
        "floats.src": "uint8x1", "floats.dst": "float32x1",
        "absf.src": "float32x1", "absf.dst": "uint8x1",
        "diff.src1": "uint8x3", "diff.src2": "uint8x3", "diff.dst": "uint8x3",
        "sink3.src": "uint8x3", "sink1.src": "uint8x1", "sinkf.src": "uint8x1",
    }


def test_deprecated_names_resolve_to_the_same_ports(tmp_path):
    """ErodeGray is Erode with one channel; old port names connect the new ports."""
    new = resolved(tmp_path, {"gray": "{type: Source, params: {n: 1}}",
                              "erode": "{type: Erode}", "sink": "{type: Keep}"},
                   ["gray.dst -> erode.src", "erode.dst -> sink.src"])
    old = resolved(tmp_path, {"gray": "{type: Source, params: {n: 1}}",
                              "erode": "{type: ErodeGray}", "sink": "{type: Keep}"},
                   ["gray.dst -> erode.image", "erode.eroded -> sink.src"])
    assert new == old == {"gray.dst": "uint8x1", "erode.src": "uint8x1",
                          "erode.dst": "uint8x1", "sink.src": "uint8x1"}
    notes = [n.format() for n in load_system(tmp_path / "m.yaml").notes]
    assert notes == [
        f"{tmp_path / 'm.yaml'}:5:17: note: 'ErodeGray' of 'erode' is a deprecated name of "
        "'Erode' with 1 channel\n  hint: write 'type: Erode': it takes 1 or 3 channels, from "
        "what feeds it",
        f"{tmp_path / 'm.yaml'}:8:5: note: 'erode' (ErodeGray) is connected by old port names: "
        "'image' is now 'src', 'eroded' is now 'dst'\n  hint: the old names work for now; "
        "write 'erode.src', 'erode.dst'"]


@pytest.mark.parametrize("components,connections,expected", [
    ({"gray": "{type: Source, params: {n: 1}}", "colour": "{type: Source}",
      "diff": "{type: AbsDiff}", "sink": "{type: Keep}"},
     ["gray.dst -> diff.src1", "colour.dst -> diff.src2", "diff.dst -> sink.src"],
     ["m.yaml:10:5: error: channel mismatch: 'colour.dst' gives 3 channel(s), 'diff.src2' "
      "takes 1, the channels of 'diff.src1'"]),
    ({"four": "{type: Source, params: {n: 4}}", "blur": "{type: GaussianBlur}",
      "sink": "{type: Keep}"},
     ["four.dst -> blur.src", "blur.dst -> sink.src"],
     ["m.yaml:8:5: error: channel mismatch: 'four.dst' gives 4 channel(s), 'blur.src' "
      "takes 1 or 3"]),
    ({"gray": "{type: Source, params: {n: 1}}", "floats": "{type: Floats}",
      "blur": "{type: BoxBlur}", "sink": "{type: Keep}"},
     ["gray.dst -> floats.src", "floats.dst -> blur.src", "blur.dst -> sink.src"],
     ["m.yaml:10:5: error: element type mismatch: 'floats.dst' gives float32, 'blur.src' "
      "takes uint8"]),
    ({"colour": "{type: Source}", "erode": "{type: ErodeGray}", "sink": "{type: Keep}"},
     ["colour.dst -> erode.image", "erode.dst -> sink.src"],
     ["m.yaml:8:5: error: channel mismatch: 'colour.dst' gives 3 channel(s), 'erode.src' "
      "takes 1"]),
])
def test_what_a_port_does_not_take_is_an_error_on_its_connection(tmp_path, components,
                                                                  connections, expected):
    with pytest.raises(GpucompgenError) as err:
        resolved(tmp_path, components, connections)
    found = [f"{d.file.rsplit('/', 1)[-1]}:{d.line}:{d.col}: {d.severity}: {d.message}"
             for d in err.value.diagnostics if d.severity == "error"]
    assert found == expected


def test_specialized_fixes_every_generic_port():
    from gpucompgen.model import library_types

    t = library_types()["AbsDiff"].specialized("uint8", 3)
    assert not t.generic
    assert {p: (d.dtype, d.channels) for p, d in {**t.inputs, **t.outputs}.items()} == {
        "src1": ("uint8", 3), "src2": ("uint8", 3), "dst": ("uint8", 3)}
    t = library_types()["ConvertScale"].specialized("float32", 1)
    assert (t.inputs["src"].dtype, t.outputs["dst"].dtype, t.outputs["dst"].channels) == \
        ("float32", "uint8", 1)
    assert library_types()["ConvertScale"].generic  # the library's own is unchanged


def test_a_generic_type_file_reads_back(tmp_path):
    """The declarations as written: choices, 'any', following ports and parameters."""
    from gpucompgen.errors import Reporter
    from gpucompgen.model import load_types_file

    (tmp_path / "types.yaml").write_text(USER_TYPES)
    (tmp_path / "parts.py").write_text(PARTS)
    types = load_types_file(tmp_path / "types.yaml", "types.yaml", "user", Reporter())
    text = {n: {p: d.describe() for p, d in {**t.inputs, **t.outputs}.items()}
            for n, t in types.items()}
    assert text == {"Source": {"dst": "CPU uint8xparameter n"},
                    "Floats": {"src": "CPU uint8xany", "dst": "CPU float32xas src"},
                    "Keep": {"src": "CPU uint8|int8|uint16|int16|int32|uint32|float32xany"}}


def test_a_channels_parameter_is_fixed_at_build_time(tmp_path):
    """'channels: n' sizes the buffers: --set cannot change n when the program starts."""
    resolved(tmp_path, {"gray": "{type: Source, params: {n: 1}}", "sink": "{type: Keep}"},
             ["gray.dst -> sink.src"])
    system, _ = run_passes(load_system(tmp_path / "m.yaml"), PROFILES["portable"])
    assert "gray.n" not in {s.key for s in system.plan.settable}
