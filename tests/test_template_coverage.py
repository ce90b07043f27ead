"""Every branch of the program template is taken by some checked-in golden.

The branches are found with Jinja's own parser: every `{% if %}` body, each `{% elif %}`
body and `{% else %}` body, every `{% for %}` body and its `{% else %}` body, macros
included. Each golden is rebuilt, exactly as scripts/regen_golden.py --check does
(`gpucompgen build MODEL -o FOLDER OPTIONS --check`, in-process), with the template compiled
from its syntax tree after a marker statement was put first in every branch body: the
marker records its branch and prints nothing, so the rebuilt program must still equal the
checked-in one byte for byte (the build's --check). A branch no golden takes fails the test
with its line of the template; the designed model (tests/golden/every_branch/) must take
every branch on its own, so a new template branch comes with a change to that model.
(Inline `x if c else y` expressions are not counted.)
"""

from __future__ import annotations

import contextlib
import runpy

import jinja2
import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl
from jinja2 import nodes

from gpucompgen import cli, printing
from gpucompgen.library.camera import Camera

# the common program and each backend's, which extends it
TEMPLATES = ("common/program.py.j2", "opencl/program.py.j2", "cuda/program.py.j2")
REGEN = runpy.run_path(str(ROOT / "scripts" / "regen_golden.py"))
MARKER = "__branch_taken__"


def branches(tree: nodes.Template) -> list[tuple[str, list[nodes.Node]]]:
    """(label, body) of every branch in the tree, in source order: 'LINE if', 'LINE elif',
    'LINE for' (LINE: the line of that tag), 'LINE else', 'LINE for-else' (LINE: the line
    of the `if` or `for` whose else it is; Jinja's tree keeps no line for an else tag)."""
    elifs = {id(e) for n in tree.find_all(nodes.If) for e in n.elif_}
    found = []
    for n in tree.find_all((nodes.If, nodes.For)):
        if id(n) in elifs:  # listed with the `if` it continues
            continue
        kind = "if" if isinstance(n, nodes.If) else "for"
        found.append((f"{n.lineno} {kind}", n.body))
        for e in getattr(n, "elif_", ()):
            found.append((f"{e.lineno} elif", e.body))
        if n.else_:
            found.append((f"{n.lineno} {'for-else' if kind == 'for' else 'else'}", n.else_))
    return found


def instrumented(tree: nodes.Template, prefix: str = "") -> list[str]:
    """Put a marker call first in every branch body of tree; the branches' labels (each
    after prefix: the template's name)."""
    labels = []
    for where, body in branches(tree):
        label = prefix + where
        call = nodes.Call(nodes.Name(MARKER, "load"), [nodes.Const(label)], [], None, None)
        body.insert(0, nodes.ExprStmt(call))
        labels.append(label)
    return labels


@contextlib.contextmanager
def recording(taken: set[str]):
    """While inside, every backend's printer renders with the instrumented templates (its
    own and the common one it extends), adding the label of each branch taken to
    `taken`."""
    original = printing.environment

    def environment() -> jinja2.Environment:
        env = original()

        def get_template(name, parent=None, globals=None):
            source, filename, _ = env.loader.get_source(env, name)
            tree = env.parse(source, name, filename)
            instrumented(tree, f"{name}:")
            return env.from_string(tree)

        env.globals[MARKER] = lambda label: taken.add(label) or ""
        env.get_template = get_template
        return env

    printing.environment = environment
    try:
        yield
    finally:
        printing.environment = original


def template_branches() -> list[str]:
    return [f"{name}:{label}" for name in TEMPLATES for label, _ in branches(
        jinja2.Environment().parse((ROOT / "templates" / name).read_text()))]


def golden_coverage(builds, capsys) -> dict[str, set[str]]:
    """Rebuild each (model, folder, options) with --check through the instrumented
    template: the branches each golden takes."""
    coverage = {}
    for model, folder, options in builds:
        taken: set[str] = set()
        with recording(taken):
            code = cli.main(["build", str(ROOT / model), "-o", str(ROOT / folder), *options,
                             "--check"])
        err = capsys.readouterr().err
        assert code == 0, f"{folder}/ is stale for {model} (or the marker printed something):" \
                          f" run 'python scripts/regen_golden.py'\n{err}"
        coverage[f"{folder}: {model}"] = taken
    return coverage


def _missing(labels: list[str], taken: set[str]) -> list[str]:
    missing = []
    for label in labels:
        if label not in taken:
            name, where = label.split(":")
            line, kind = where.split()
            text = (ROOT / "templates" / name).read_text().splitlines()[int(line) - 1]
            missing.append(f"templates/{name}:{line}: {kind}: {text.strip()}")
    return missing


def test_every_template_branch_is_taken_by_a_golden_and_by_the_designed_model(
        monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    labels = template_branches()
    assert len(labels) > 40  # the parser found the template's branches
    coverage = golden_coverage(REGEN["builds"](), capsys)
    designed = [key for key in coverage if key.endswith(REGEN["DESIGNED"])]
    assert len(designed) == len(REGEN["DESIGNED_VARIANTS"])
    missing = _missing(labels, set().union(*coverage.values()))
    assert not missing, "template branches no golden takes:\n" + "\n".join(missing)
    missing = _missing(labels, set().union(*(coverage[key] for key in designed)))
    assert not missing, ("template branches the designed model's goldens do not take "
                         "(change tests/golden/every_branch/every_branch.yaml or its "
                         "variants in scripts/regen_golden.py):\n" + "\n".join(missing))


def test_the_marker_finds_a_branch_not_taken():
    """The mechanism cannot pass vacuously: an untaken branch, an else and an empty loop
    are reported; taken ones are not."""
    env = jinja2.Environment()
    tree = env.parse("{% if a %}A{% elif b %}B{% else %}C{% endif %}\n"
                     "{% for x in xs %}{{ x }}{% else %}none{% endfor %}\n")
    name = TEMPLATES[0]
    labels = instrumented(tree, f"{name}:")
    assert labels == [f"{name}:{x}" for x in ("1 if", "1 elif", "1 else", "2 for", "2 for-else")]
    taken: set[str] = set()
    env.globals[MARKER] = lambda label: taken.add(label) or ""
    assert env.from_string(tree).render(a=False, b=True, xs=[1, 2]) == "B\n12"
    assert taken == {f"{name}:1 elif", f"{name}:2 for"}
    assert _missing(labels, taken) != []


def test_branch_labels_name_the_template_lines():
    """A label names the line of its tag, or of the `if`/`for` whose else it is (what a
    failure prints)."""
    for label in template_branches():
        name, where = label.split(":")
        lines = (ROOT / "templates" / name).read_text().splitlines()
        line, kind = where.split()
        tag = {"else": "if", "for-else": "for"}.get(kind, kind)
        assert "{% " + tag + " " in lines[int(line) - 1], label


def test_the_designed_goldens_run_and_agree():
    """The designed model's OpenCL goldens run as they are checked in: 4 frames (the camera
    ends), the user's probe sees the brightened frames (numpy), and every variant's sink
    gets the default's last frame."""
    require_opencl()
    cam = Camera(width=48, height=32, seed=3)
    cam.initialize()
    expected = [np.minimum(cam.execute().astype(int) + 40, 255).mean() for _ in range(4)]
    last = None
    for folder in REGEN["DESIGNED_VARIANTS"]:
        if folder.endswith("/cuda"):
            continue
        module = load_generated(ROOT / folder / "every_branch.py", "every_branch_" +
                                folder.rsplit("/", 1)[1].replace("-", "_"))
        run = module.run()
        assert run.frames == 4, folder
        assert run.components["probe"].means == pytest.approx(expected, abs=1e-9), folder
        frame = run.components["sink"].last
        assert frame is not None and frame.shape == (32, 48, 3), folder
        if last is None:
            last = frame
        assert np.array_equal(frame, last), folder
