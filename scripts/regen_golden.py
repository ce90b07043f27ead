#!/usr/bin/env python3
"""Regenerate the checked-in output of every model, and of the variants that matter.

    generated/                     default build of every model in models/
    generated/variants/standard/   --mode standard (every component copies its own data)
    generated/variants/sequential/ --execution sequential (one queue, blocking copies)
    generated/variants/zero-copy/  --zero-copy on (adapters map host-visible memory)
    generated/variants/cuda/       --backend cuda (the program on gpucompgen.runtime.cuda, .cu)
    tests/golden/every_branch/*/   the model designed to take every branch of the program
                                   template (tests/test_template_coverage.py), in each variant
                                   above and with frames in flight

Usage: python scripts/regen_golden.py          rebuild them all
       python scripts/regen_golden.py --check  exit 1 and print the diff if any is stale
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# output folder -> the build options of that variant
VARIANTS: dict[str, list[str]] = {
    "generated": [],
    "generated/variants/standard": ["--mode", "standard"],
    "generated/variants/sequential": ["--execution", "sequential"],
    "generated/variants/zero-copy": ["--zero-copy", "on"],
    "generated/variants/cuda": ["--backend", "cuda"],
}

# The designed model (a test input, not an example): its goldens together take every branch
# of templates/opencl/program.py.j2, which tests/test_template_coverage.py checks.
DESIGNED = "tests/golden/every_branch/every_branch.yaml"
DESIGNED_VARIANTS: dict[str, list[str]] = {
    "tests/golden/every_branch/default": [],
    "tests/golden/every_branch/standard": ["--mode", "standard"],
    "tests/golden/every_branch/sequential": ["--execution", "sequential"],
    "tests/golden/every_branch/zero-copy": ["--zero-copy", "on"],
    "tests/golden/every_branch/cuda": ["--backend", "cuda"],
    "tests/golden/every_branch/frames-in-flight": ["--frames-in-flight", "2"],
}


def models() -> list[Path]:
    return sorted((ROOT / "models").glob("*.yaml"))


def builds() -> list[tuple[str, str, list[str]]]:
    """(model, output folder, build options) of every checked-in output, paths relative
    to the checkout."""
    return [(str(model.relative_to(ROOT)), folder, options)
            for folder, options in VARIANTS.items() for model in models()] + [
        (DESIGNED, folder, options) for folder, options in DESIGNED_VARIANTS.items()]


def main(argv: list[str]) -> int:
    check = "--check" in argv
    failed = 0
    for model, folder, options in builds():
        cmd = [sys.executable, "-m", "gpucompgen", "build", model, "-o", folder,
               *options] + (["--check"] if check else [])
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            failed += 1
            sys.stdout.write(proc.stdout)
            sys.stderr.write(proc.stderr)
        elif not check:
            print(f"{folder}: {Path(model).name}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
