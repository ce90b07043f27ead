"""Calibrate the fusion cost model (passes/fuse.py FUSION_COSTS) on the device at hand.

    python benchmarks/fusion_costs.py [--sizes 640x360,1280x720] [--frames 7]
                                      [--pipelines lanes,colour,edges,motion,pointwise]

For each of benchmarks/pipelines.py's pipelines, with every component on the device,
`gpucompgen tune` measures every component's generated kernel alone and every group the
fuse pass chooses, as one kernel and as its members apart (a group measured no faster is
refused and the next choice measured too: tune.measure_groups) — once with the current
constants, once with launches made so dear that every legal group is chosen (the groups
the constants refuse must be measured too, or the fit could never learn to refuse them).  Each kernel's time is
then explained as

    launch_s + ops * op_s + loads * load_s + stores * store_s + taps * tap_s

with its counts from the cost model (fuse.kernel_features: element operations computed,
elements loaded from memory, elements stored, one launch, a stencil's taps that call a
producer inside the group), fitted by non-negative least
squares on relative error (a kernel measured far slower than any count predicts —
PoCL failing to vectorize it, which tune's measurement catches — weighs at most 1).
Prints the fitted row to paste into
FUSION_COSTS for the device's class (`gpucompgen devices` says it), and for every group
measured: its time fused and apart, as measured, as the current constants estimate it and
as the fitted ones would, and whether each agrees with the measurement on which is faster.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))



def before_fuse(model_path: Path, facts):
    """The system of the model with every flexible component on the device, the passes
    before fuse applied: the cost model's counts are read from it."""
    from gpucompgen.model import load_system
    from gpucompgen.passes.fuse import Fuse
    from gpucompgen.passes.pipeline import PIPELINE, new_system, run_pipeline

    model = load_system(model_path)
    flexible = [n for n, inst in model.components.items() if inst.type.flexible]
    system = new_system(model, facts, places=dict.fromkeys(flexible, "gpu"),
                        zero_copy="off", fusion="auto")
    k = next(i for i, p in enumerate(PIPELINE) if isinstance(p, Fuse))
    system, _ = run_pipeline(system, PIPELINE[:k])
    return system


def fit(rows: list[tuple[list[float], float]]) -> np.ndarray:
    """Non-negative least squares of the relative error: seconds of each of FEATURES."""
    from scipy.optimize import nnls

    x = np.array([f for f, _ in rows], float)
    y = np.array([t for _, t in rows], float)
    scale = x.max(axis=0)
    scale[scale == 0] = 1
    coef, _ = nnls((x / scale) / y[:, None], np.ones(len(y)))
    return coef / scale


def main(argv=None) -> int:
    import cv2
    import pipelines as bench

    from gpucompgen import device as device_mod
    from gpucompgen.errors import Reporter
    from gpucompgen.passes import fuse
    from gpucompgen.tune import tune

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="640x360,1280x720")
    ap.add_argument("--frames", type=int, default=7, help="frames tune times each kernel")
    ap.add_argument("--pipelines", default=",".join(bench.PIPELINES))
    ap.add_argument("--save", help="write the measurements to this JSON file")
    ap.add_argument("--load", help="fit the measurements of a JSON file --save wrote")
    args = ap.parse_args(argv)
    rep = Reporter()
    facts = device_mod.resolve("auto", None, rep)
    rep.raise_if_errors()
    kind = facts.kind or "(unknown class: the 'cpu' row)"
    print(f"device: {facts.name}, class {kind}; load average {bench.load()}")
    kernels: list[tuple[str, list[float], float]] = []  # (what, features, seconds)
    groups: list[tuple[str, list[float], list[list[float]], float, float]] = []
    if args.load:
        saved = json.loads(Path(args.load).read_text())
        kernels, groups = saved["kernels"], saved["groups"]
    with tempfile.TemporaryDirectory() as tmp:
        for size in ([] if args.load else args.sizes.split(",")):
            w, h = map(int, size.split("x"))
            frames = Path(tmp) / f"pan_{size}.npy"
            np.save(frames, bench.pan(np, cv2, w, h, count=4))
            for name in args.pipelines.split(","):
                model = Path(tmp) / f"{name}_{size}.yaml"
                model.write_text(bench.model_text(name, w, h, frames, "placement: gpu"))
                measured: list = []
                _, rows = tune(model, args.frames, groups_out=measured)
                # and every legal group, whatever the constants say (launches made very
                # dear): the groups the model refuses must be measured to calibrate it
                every = {k: {**v, "launch_s": 1.0} for k, v in fuse.FUSION_COSTS.items()}
                saved, fuse.FUSION_COSTS = fuse.FUSION_COSTS, every
                try:
                    more: list = []
                    tune(model, min(args.frames, 3), groups_out=more)
                finally:
                    fuse.FUSION_COSTS = saved
                seen = {frozenset(g[1]) for g in measured}
                measured += [g for g in more if frozenset(g[1]) not in seen]
                system = before_fuse(model, facts)

                def features(members, system=system):
                    f = fuse.kernel_features(system, members)
                    return [float(f[k]) for k in fuse.FEATURES]
                for comp, *_, gpu_us in rows:
                    node = system.nodes[comp]
                    if node.type.fusable is not None:
                        kernels.append((f"{name} {size} {comp}", features([comp]),
                                        gpu_us * 1e-6))
                for gname, members, _, fused_us, apart_us in measured:
                    kernels.append((f"{name} {size} {gname}", features(members),
                                    fused_us * 1e-6))
                    groups.append((f"{name} {size} {gname}", features(members),
                                   [features([m]) for m in members], fused_us * 1e-6,
                                   apart_us * 1e-6))
                print(f"  {name} {size}: {len(rows)} kernels, {len(measured)} groups "
                      "measured", flush=True)
    if args.save:
        Path(args.save).write_text(json.dumps({"kernels": kernels, "groups": groups}))
    coef = fit([(f, t) for _, f, t in kernels])
    errors = [abs(np.dot(coef, f) / t - 1) for _, f, t in kernels]
    print(f"\n{len(kernels)} kernels measured; the fit's median error "
          f"{statistics.median(errors):.0%}")
    # the median error is the row's 'error': placement takes a group's estimated fused
    # time at that much more when it sets the group against the CPU forms
    row = {**dict(zip(fuse.FEATURES.values(), coef)), "error": statistics.median(errors)}
    print("\nFUSION_COSTS row (passes/fuse.py), for this device's class:")
    print("    {" + ", ".join(f'"{k}": {v:.3g}' for k, v in row.items()) + "}")
    current = fuse.FUSION_COSTS.get(facts.kind) or fuse.FUSION_COSTS["cpu"]
    now = np.array([current[k] for k in fuse.FEATURES.values()])
    print("\n| group | measured fused / apart (ms) | estimate now | fitted | agree now, fitted |")
    print("|---|---:|---:|---:|---|")
    agree = [0, 0]
    for what, f, members, fused_s, apart_s in groups:
        wins = fused_s < apart_s
        cells = []
        for i, c in enumerate((now, coef)):
            ef, ea = np.dot(c, f), sum(np.dot(c, m) for m in members)
            cells.append(f"{ef * 1e3:.3f} / {ea * 1e3:.3f}")
            agree[i] += (ef < ea) == wins
        print(f"| {what} | {fused_s * 1e3:.3f} / {apart_s * 1e3:.3f} | {cells[0]} | "
              f"{cells[1]} | {'yes' if (np.dot(now, f) < sum(np.dot(now, m) for m in members)) == wins else 'no'}, "
              f"{'yes' if (np.dot(coef, f) < sum(np.dot(coef, m) for m in members)) == wins else 'no'} |")
    print(f"\nthe estimate agrees with the measurement on {agree[0]} of {len(groups)} groups "
          f"(fitted: {agree[1]}); load average {bench.load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
