"""`gpucompgen types`: every type a model can use, and one type in full (as gst-inspect)."""

from __future__ import annotations

import re

import pytest
from conftest import ROOT

from gpucompgen.cli import main
from gpucompgen.model import library_types

USER_MODEL = ROOT / "tests" / "data" / "user_model" / "bright.yaml"


def run(capsys, *args) -> tuple[int, str, str]:
    code = main(["types", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_listing_names_every_library_type_once_with_its_kind(capsys):
    code, out, err = run(capsys)
    assert code == 0 and err == ""
    rows = {m.group(1): m.group(2) for m in re.finditer(r"^  (\w+) +(gpu-aware|standard|flexible) ",
                                                         out, re.MULTILINE)}
    types = library_types()
    assert rows == {name: t.kind for name, t in types.items()}
    assert f"{len(types)} component types" in out
    # grouped by family, in this order; each line says what the type takes and gives
    titles = ["colour:", "filters:", "morphology:", "geometry:", "arithmetic and thresholds:",
              "features:", "I/O: sources and sinks:"]
    assert [line for line in out.splitlines() if line.endswith(":")] == titles
    assert all(len(line) <= 100 for line in out.splitlines())
    # the one-line description is the first sentence
    # (cut with '...' where the columns before it leave too little room)
    assert re.search(r"^  Resize +flexible   8U\|16S\|32F C1\|3 -> same +Scales a frame"
                     r".*\.\.\.$", out, re.MULTILINE)
    assert re.search(r"^  Filter2D +flexible   8U\|16S\|32F C1\|3 -> D\(ddepth\) ", out, re.MULTILINE)
    assert re.search(r"^  Sobel +flexible   8U\|32F C1\|3 -> D\(ddepth\) +Derivative of order",
                     out, re.MULTILINE)
    assert re.search(r"^  ConvertScale +flexible   8U\|16S\|32F C1\|3 -> 8U ", out, re.MULTILINE)
    assert re.search(r"^  AbsDiff +flexible   2 x 8U\|16S\|32F C1\|3 -> same ", out, re.MULTILINE)
    assert re.search(r"^  ErodeGray +flexible   8U\|16S\|32F C1 -> C1 +deprecated: Erode with 1 "
                     r"channel$", out, re.MULTILINE)
    assert re.search(r"^  FlipHorizontal +flexible   \* C1\|3 -> same ", out, re.MULTILINE)
    assert re.search(r"^  MaskWriter +standard   8UC3, 8UC1 -> +Sink", out, re.MULTILINE)
    assert re.search(r"^  Camera +standard   -> 8UC3 +Camera source\.$", out, re.MULTILINE)


def test_listing_with_a_model_adds_its_own_types(capsys):
    code, out, _ = run(capsys, "--model", USER_MODEL)
    assert code == 0
    assert "tests/data/user_model/my_types.yaml:" in out
    assert re.search(r"^  Brighten +gpu-aware  8UC3 -> 8UC3 +Adds gain to every channel", out,
                     re.MULTILINE)
    assert re.search(r"^  MeanProbe +standard ", out, re.MULTILINE)
    assert f"{len(library_types()) + 2} component types" in out
    # the library first, the model's files after it
    assert out.index("I/O: sources and sinks:") < out.index("my_types.yaml:")


def test_one_flexible_type_in_full_with_every_form(capsys):
    code, out, _ = run(capsys, "Threshold")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].split() == ["Name", "Threshold"]
    assert lines[1].startswith("Kind            flexible (runs on the GPU or the CPU, as placed")
    assert re.search(r"^Declared in     <gpucompgen>/library/imgproc\.yaml:\d+ \(library\)$",
                     out, re.MULTILINE)
    assert "cv2.threshold(src, thresh, maxval, thresh_type)" in " ".join(out.split())
    # a flexible type's ports live where it runs; a generic one's channels follow its input
    assert ("  src           memory where placed, uint8, int16 or float32, 1 or 3 channels, any "
            "size (old name:") in lines
    assert ("  dst           memory where placed, the dtype of src, the channels of src, height "
            "src.height, width") in lines
    assert "                src.width (old name: thresholded)" in lines
    assert "  thresh        float, default 127.0" in lines
    assert "  thresh_type   int, default 0, range 0..4" in lines
    assert "4 TOZERO_INV" in out
    forms = lines[lines.index("Forms:") + 1:lines.index("Example:") - 1]
    snippet = library_types()["Threshold"].fusable.value
    assert " ".join(" ".join(forms).split()) == (
        "GPU kernel generated from the fusable form below, for a component alone as for a "
        "fused group; the system chooses its settings CPU function threshold() in cpu_kernels.py, called with the input "
        "arrays and the parameters as keywords; runs where the model places the component "
        "(placement: cpu, --place) fusable pointwise: " + " ".join(snippet.split()))
    # a snippet of several lines is printed as written, under its form
    at = forms.index("  fusable       pointwise:")
    assert forms[at + 1:at + 3] == ["                  const bool whole = (src_t)0.5f == (src_t)0;",
                                    "                  const float t = whole ? floor(thresh) : "
                                    "thresh;"]
    assert forms[0].startswith("  GPU kernel    ") and any(
        f.startswith("  CPU function  threshold() in cpu_kernels.py") for f in forms)


def test_requirements_float_parameters_and_int16_ports(capsys):
    _, out, _ = run(capsys, "SobelGray")  # a deprecated alias: Sobel with 1 channel
    assert ("  dst           memory where placed, the dtype of parameter ddepth, 1 channel, "
            "height src.height") in out
    assert "Deprecated      a name of Sobel with 1 channel: write 'type: Sobel'" in out
    assert "dx + dy >= 1: give a derivative: dx or dy at least 1" in out
    assert "src.itemsize != 4 or ddepth == -1 or ddepth == 5: the derivative of a float32 " \
           "frame" in out
    _, out, _ = run(capsys, "ConvertScale")  # takes Sobel's int16
    assert ("  src           memory where placed, uint8, int16 or float32, 1 or 3 channels, "
            "any size") in out
    _, out, _ = run(capsys, "AddWeighted")
    assert "  gamma         float, default 0.0" in out
    assert ("  src2          memory where placed, the dtype of src1, the channels of src1, "
            "any size") in out
    assert "  CPU function  add_weighted() in cpu_kernels.py" in out


def test_standard_type_and_model_type_in_full(capsys, monkeypatch):
    _, out, _ = run(capsys, "Camera")
    assert "Kind            standard (runs on the CPU)" in out
    assert "  image         CPU memory, uint8, 3 channels, height height, width width" in out
    assert "  folder        input, default ''" in out
    assert "  seed          int, default 1, range 0.." in out
    assert "  CPU (python)  class Camera in camera.py" in out.splitlines()
    assert out.splitlines()[-3:] == [
        "    camera: {type: Camera, params: {width: 640, height: 480, seed: 1, buoys: 2, frames: 0}}",
        "  connections:", "    - camera.image -> <consumer>.<port>  # uint8, 3 channels"]
    monkeypatch.chdir(ROOT)  # paths as the user wrote them, relative to the working folder
    code, out, _ = run(capsys, "Brighten", "--model", USER_MODEL.relative_to(ROOT))
    assert code == 0
    assert "Declared in     tests/data/user_model/my_types.yaml:" in out
    assert ("  brighter      GPU memory, uint8, 3 channels, height image.height, "
            "width image.width") in out  # no size declared: the input's
    assert "brighten() in brighten.cl; tiles 16, 32; preferred tile 16, block 8x8x1" in out


def test_unknown_type_is_an_error_with_a_hint(capsys):
    code, out, err = run(capsys, "Thresold")
    assert code == 1 and out == ""
    assert "no component type 'Thresold' in the library" in err
    assert "did you mean 'Threshold'?" in err
    assert "--model MODEL" in err
    # a model's type needs the model
    code, _, err = run(capsys, "Brighten")
    assert code == 1 and "did you mean" not in err.splitlines()[0]


def test_model_problems_are_positioned_errors(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("system: s\ntypes: [missing.yaml]\ncomponents: {}\n")
    code, _, err = run(capsys, "--model", bad)
    assert code == 1
    assert re.search(r"bad\.yaml:2:\d+: error: component-type file 'missing.yaml' not found",
                     err)
    assert "Traceback" not in err
    code, _, err = run(capsys, "--model", tmp_path / "none.yaml")
    assert code == 2 and "no such file" in err


@pytest.mark.parametrize("name", sorted(library_types()))
def test_every_library_type_shows_in_full(capsys, name):
    code, out, _ = run(capsys, name)
    assert code == 0
    assert "Forms:" in out and ("GPU kernel" in out or "CPU (python)" in out)
    assert all(len(line) <= 100 for line in out.splitlines()), name


def test_docs_show_the_current_listing_and_every_imgproc_type(capsys):
    """docs/library.md quotes `gpucompgen types` and has a row for every library type."""
    text = (ROOT / "docs" / "library.md").read_text()
    _, out, _ = run(capsys)
    assert f"$ gpucompgen types\n{out}```" in text, "docs/library.md: re-paste the listing"
    _, out, _ = run(capsys, "InRange")
    assert f"$ gpucompgen types InRange\n{out}```" in text
    rows = " ".join(line for line in text.splitlines() if line.startswith("| "))
    for name, ctype in library_types().items():
        if ctype.decl_file.name in ("imgproc.yaml", "bitwise.yaml", "convert.yaml",
                                    "filters2.yaml", "morphology.yaml", "features.yaml",
                                    "drawing.yaml", "warp.yaml"):
            assert re.search(rf"\b{name}\b", rows), name


def test_one_type_in_full_ends_with_an_example_connection(capsys):
    _, out, _ = run(capsys, "AbsDiffGray")  # a deprecated name: the example writes the type
    assert out.splitlines()[out.splitlines().index("Example:"):] == [
        "Example:", "  components:", "    abs_diff: {type: AbsDiff}", "  connections:",
        "    - <producer>.<port> -> abs_diff.src1  # uint8, int16 or float32, 1 channel",
        "    - <producer>.<port> -> abs_diff.src2  # the dtype of src1, 1 channel",
        "    - abs_diff.dst -> <consumer>.<port>   # the dtype of src1, 1 channel"]


def test_fusable_forms_are_listed_with_their_snippets(capsys):
    _, out, _ = run(capsys, "VerticalMirror")
    assert "  fusable       index map: src(src_height - 1 - y, x, c)" in out.splitlines()
    _, out, _ = run(capsys, "BoxBlur")
    text = " ".join(out.split())
    assert "fusable stencil; window radius radius, border clamp: const int n =" in text




def test_a_reader_that_stops_early_is_not_an_internal_error():
    """`gpucompgen types | head -1`: a closed pipe ends the command quietly."""
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before anything is written
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "types"], stdout=write_end,
                          stderr=subprocess.PIPE, text=True, timeout=60, check=False)
    os.close(write_end)
    assert proc.returncode == 0, proc.stderr
    assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr
