"""Draw a --trace file as a picture: a row per host and device track, each slice coloured
by its frame (warm-up frames hatched), and the frames-in-flight counter below.

    python scripts/trace_picture.py vs.json docs/trace.png

Perfetto (ui.perfetto.dev) shows the same tracks interactively; this is for documents.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: trace_picture.py TRACE.json OUT.png", file=sys.stderr)
        return 2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    events = json.loads(Path(argv[0]).read_text())["traceEvents"]
    names = {(e["pid"], e["tid"]): e["args"]["name"] for e in events
             if e["ph"] == "M" and e["name"] == "thread_name"}
    tracks = sorted({(e["pid"], e["tid"]) for e in events if e["ph"] == "X"})
    rows = {t: i for i, t in enumerate(tracks)}
    fig, (ax, counter) = plt.subplots(2, 1, figsize=(12, 0.42 * len(tracks) + 2.2),
                                      sharex=True, gridspec_kw={"height_ratios": [4, 1]})
    colours = plt.get_cmap("tab10")
    for e in events:
        if e["ph"] != "X":
            continue
        frame = e["args"]["frame"]
        ax.barh(rows[(e["pid"], e["tid"])], max(e["dur"], 30) / 1e3, left=e["ts"] / 1e3,
                height=0.7, color=colours(frame % 10), edgecolor="black", linewidth=0.3,
                hatch="//" if e["args"].get("warmup") else None)
    ax.set_yticks(range(len(tracks)))
    ax.set_yticklabels([("device: " if t[0] == 2 else "") + names.get(t, str(t))
                        for t in tracks])
    ax.invert_yaxis()
    ax.set_title("colour = frame (warm-up frames hatched)")
    points = sorted((e["ts"] / 1e3, e["args"]["frames"]) for e in events
                    if e["ph"] == "C" and e["name"] == "frames in flight")
    if points:
        counter.step([p[0] for p in points], [p[1] for p in points], where="post")
    counter.set_ylabel("frames\nin flight")
    counter.set_xlabel("ms since the run started")
    fig.tight_layout()
    fig.savefig(argv[1], dpi=110)
    print(f"wrote {argv[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
