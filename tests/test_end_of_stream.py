"""End of stream and failures with several source chains and frames in flight.

Two independent chains declared one after the other end together when their sources end
(the sources run first in every frame, so the end is known before any part works on it),
in the one-frame loop, in sequential execution and with frames in flight.  A source that
fails at frame k delivers frames 0..k-1 to the sinks whatever the frames in flight: the
stages after the failing one finish the frames they were handed.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import load_generated, require_opencl, write_keep_types

from gpucompgen.build import compile_model, write
from gpucompgen.runtime import Monitor, PipelineError

CHAINS = """\
system: chains
types: [keep.yaml]
components:
  camA: {type: Camera, params: {seed: 1, width: 20, height: 16, frames: 5}}
  flipA: {type: FlipHorizontal}
  keepA: {type: Keep3}
  camB: {type: Camera, params: {seed: 2, width: 18, height: 16, frames: %d}}
  flipB: {type: FlipHorizontal}
  keepB: {type: Keep3}
connections:
  - camA.image -> flipA.image
  - flipA.flipped -> keepA.image
  - camB.image -> flipB.image
  - flipB.flipped -> keepB.image
"""

FAILING = """\
system: failing
types: [keep.yaml, failing.yaml]
components:
  source: {type: Counting, params: {fail_at: 10}}
  flip: {type: FlipHorizontal}
  keep: {type: Keep3}
connections:
  - source.image -> flip.image
  - flip.flipped -> keep.image
"""

COUNTING_YAML = """\
component_types:
  Counting:
    kind: standard
    description: Frame f is filled with f; raises at frame fail_at.
    params:
      fail_at: {type: int, default: -1}
    outputs:
      image: {memory: cpu, dtype: uint8, channels: 3, height: 16, width: 20}
    python: {file: counting.py, class: Counting}
"""

COUNTING_PY = """\
import numpy as np


class Counting:
    def __init__(self, fail_at=-1):
        self.fail_at, self.frame = fail_at, 0

    def initialize(self):
        return (16, 20, 3)

    def execute(self):
        if self.frame == self.fail_at:
            raise RuntimeError(f"source broke at frame {self.frame}")
        self.frame += 1
        return np.full((16, 20, 3), self.frame - 1, np.uint8)

    def free_memory(self):
        pass
"""

VARIANTS = [{}, {"execution": "sequential"}, {"frames_in_flight": 2},
            {"frames_in_flight": 3, "execution": "sequential"},
            {"frames_in_flight": 3, "places": {"flipA": "cpu", "flipB": "cpu"}},
            {"places": {"flipA": "cpu"}, "frames_in_flight": 2}]


def _program(folder: Path, text: str, tag: str, **options):
    model = folder / "m.yaml"
    model.write_text(text, encoding="utf-8")
    out = folder / f"out-{tag}"
    result = compile_model(model, out, **options)
    write(result, out)
    return load_generated(out / f"{result.system.model.name}.py", f"eos_{folder.name}_{tag}")


def _quiet():
    return Monitor(progress=False, options={"quiet": True})


@pytest.mark.parametrize("b_frames", [5, 7, 3])
@pytest.mark.parametrize("k", range(len(VARIANTS)))
def test_independent_chains_end_together_whatever_the_declaration_order(tmp_path, k,
                                                                          b_frames):
    require_opencl()
    write_keep_types(tmp_path)
    options = VARIANTS[k]
    program = _program(tmp_path, CHAINS % b_frames, f"{k}-{b_frames}", **options)
    result = program.run(monitor=_quiet())
    end = min(5, b_frames)
    assert result.frames == end
    kept = {n: result.components[n].frames for n in ("keepA", "keepB")}
    assert [len(f) for f in kept.values()] == [end, end], options
    from gpucompgen.library.camera import Camera

    for name, seed, width in (("keepA", 1, 20), ("keepB", 2, 18)):
        cam = Camera(seed=seed, width=width, height=16)
        cam.initialize()
        for f, frame in enumerate(kept[name]):
            np.testing.assert_array_equal(frame, cam.execute()[:, ::-1],
                                          err_msg=f"{name} frame {f} {options}")


@pytest.mark.parametrize("n", [1, 2, 3, 8])
@pytest.mark.parametrize("execution", ["parallel", "sequential"])
def test_frames_made_before_a_failure_reach_the_sinks(tmp_path, n, execution):
    """A source failing at frame 10: frames 0..9 reach the sink with any frames in flight;
    the error is the source's, at frame 10."""
    require_opencl()
    write_keep_types(tmp_path)
    (tmp_path / "failing.yaml").write_text(COUNTING_YAML, encoding="utf-8")
    (tmp_path / "counting.py").write_text(COUNTING_PY, encoding="utf-8")
    program = _program(tmp_path, FAILING, f"{n}-{execution}", frames_in_flight=n,
                       execution=execution)
    kept: list[np.ndarray] = []
    original = program.Keep3.execute

    def spy(self, image):
        kept.append(np.array(image, copy=True))
        return original(self, image)

    program.Keep3.execute = spy
    with pytest.raises(PipelineError, match=textwrap.dedent(
            r"^source failed at frame 10: RuntimeError: source broke at frame 10$")):
        program.run(monitor=_quiet())
    assert [int(f[0, 0, 0]) for f in kept] == list(range(10))
