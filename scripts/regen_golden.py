#!/usr/bin/env python3
"""Regenerate the checked-in output of every model, and of the variants that matter.

    generated/                     default build of every model in models/
    generated/variants/standard/   --mode standard (every component copies its own data)
    generated/variants/sequential/ --execution sequential (one queue, blocking copies)
    generated/variants/zero-copy/  --zero-copy on (adapters map host-visible memory)
    generated/variants/cuda/       --backend cuda (the program on gpucompgen.runtime.cuda, .cu)

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


def models() -> list[Path]:
    return sorted((ROOT / "models").glob("*.yaml"))


def main(argv: list[str]) -> int:
    check = "--check" in argv
    failed = 0
    for folder, options in VARIANTS.items():
        for model in models():
            cmd = [sys.executable, "-m", "gpucompgen", "build", str(model.relative_to(ROOT)),
                   "-o", folder, *options] + (["--check"] if check else [])
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                failed += 1
                sys.stdout.write(proc.stdout)
                sys.stderr.write(proc.stderr)
            elif not check:
                print(f"{folder}: {model.name}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
