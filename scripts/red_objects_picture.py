"""Make docs/red_objects.png from a run of models/red_objects.yaml.

    gpucompgen run models/red_objects.yaml --save-images red-out
    python scripts/red_objects_picture.py red-out docs/red_objects.png

Top row: the annotated photographs (red objects tinted and boxed); bottom row: the masks.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image


def main(folder: str, target: str) -> None:
    folder_path = Path(folder)
    annotated = sorted(folder_path.glob("annotated_*.png"))
    masks = sorted(folder_path.glob("mask_*.png"))
    top = np.hstack([np.asarray(Image.open(p).convert("RGB")) for p in annotated])
    bottom = np.hstack([np.asarray(Image.open(p).convert("RGB")) for p in masks])
    picture = Image.fromarray(np.vstack([top, bottom]))
    # a palette of 96 colours keeps the picture small in git
    picture.quantize(96, dither=Image.Dither.NONE).save(target, optimize=True)
    print(f"wrote {target}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
