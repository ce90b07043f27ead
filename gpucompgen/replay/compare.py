"""--baseline DIR: what a changed pipeline does differently, recording by recording.

Two replays are compared through their summaries only (the sinks' per-frame digests and
reports), so a baseline can come from another machine or another version. For each
recording of this run, in order, the differences found, each naming the recording, the
sink, the first frame where the two runs part and how:

- status changed (complete, partial(n), failed);
- frame count changed (a sink got more or fewer frames);
- decision changed (a sink's report differs: its old and new value);
- digest changed (a sink received different frames).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Divergence:
    recording: str
    what: str  # "missing", "status", "frames", "decision", "digest", "sinks"
    text: str
    sink: str = ""
    frame: int | None = None

    def line(self) -> str:
        where = self.recording + (f": sink {self.sink}" if self.sink else "")
        when = f" from frame {self.frame}" if self.frame is not None else ""
        return f"{where}: {self.what} changed{when}: {self.text}"


def load_run(folder: Path) -> dict[str, dict[str, Any]]:
    """{recording: summary} of a replay's output folder (its summary.json names them)."""
    run = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    found = {}
    for entry in run.get("recordings", []):
        try:
            summary = json.loads((folder / entry["folder"] / "summary.json")
                                 .read_text(encoding="utf-8"))
        except (OSError, ValueError, KeyError, TypeError):
            continue
        found[entry["recording"]] = summary
    return found


def compare_runs(new: dict[str, dict], old: dict[str, dict]) -> list[Divergence]:
    found: list[Divergence] = []
    for recording, summary in new.items():
        base = old.get(recording)
        if base is None:
            found.append(Divergence(recording, "baseline", "the baseline has no such recording"))
            continue
        found.extend(compare_summaries(recording, summary, base))
    return found


def compare_summaries(recording: str, new: dict, old: dict) -> list[Divergence]:
    found = []
    if new.get("status") != old.get("status"):
        found.append(Divergence(recording, "status",
                                f"{old.get('status')} -> {new.get('status')}"))
    new_sinks, old_sinks = new.get("sinks", {}), old.get("sinks", {})
    for sink in sorted(set(new_sinks) | set(old_sinks)):
        if sink not in old_sinks or sink not in new_sinks:
            side = "new run" if sink not in new_sinks else "baseline"
            found.append(Divergence(recording, "sinks", f"the {side} has no sink {sink}", sink))
            continue
        found.extend(_compare_sink(recording, sink, new_sinks[sink], old_sinks[sink]))
    return found


def _compare_sink(recording: str, sink: str, new: dict, old: dict) -> list[Divergence]:
    found = []
    new_reports, old_reports = new.get("reports", []), old.get("reports", [])
    first = _first_difference(new_reports, old_reports)
    if first is not None and first < min(len(new_reports), len(old_reports)):
        found.append(Divergence(recording, "decision",
                                f"{_short(old_reports[first])} -> {_short(new_reports[first])}",
                                sink, first))
    new_inputs, old_inputs = new.get("inputs", []), old.get("inputs", [])
    first = _first_difference(new_inputs, old_inputs)
    if first is not None and first < min(len(new_inputs), len(old_inputs)):
        found.append(Divergence(recording, "digest",
                                f"{', '.join(old_inputs[first])} -> "
                                f"{', '.join(new_inputs[first])}", sink, first))
    if len(new_inputs) != len(old_inputs):
        found.append(Divergence(recording, "frame count",
                                f"{len(old_inputs)} -> {len(new_inputs)} frames", sink,
                                min(len(new_inputs), len(old_inputs))))
    return found


def _first_difference(a: list, b: list) -> int | None:
    for i, (x, y) in enumerate(zip(a, b)):
        if x != y:
            return i
    return None if len(a) == len(b) else min(len(a), len(b))


def _short(value: Any, limit: int = 160) -> str:
    text = json.dumps(value, sort_keys=True)
    if isinstance(value, dict) and "action" in value:  # a decision: what it decided first
        text = f"{value['action']!s} " + text
    return text if len(text) <= limit else text[:limit - 3] + "..."
