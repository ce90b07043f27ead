"""--profile: OpenCL event times of every kernel and copy, and the bytes moved."""

from __future__ import annotations

from typing import Any


class Profile:
    """Where the time goes: each kernel and copy of every component and adapter.

    A generated program built with ``run(profile=True)`` (``--profile`` on its command
    line) hands every part this object; parts report the OpenCL event of each kernel
    launch and copy, and the bytes each copy moves between CPU and GPU; zero-copy
    adapters report their map and unmap commands, which move no bytes.  Event times are
    read in batches, so a long stream keeps little memory.  Without profiling a part's
    ``profile`` is None and nothing here runs.
    """

    BATCH = 4096  # events kept before their times are read

    def __init__(self, parts: dict[str, Any]):
        self.names = {id(obj): name for name, obj in parts.items()}
        self.order = list(parts)
        self.pending: list[tuple[tuple[str, str], Any]] = []
        self.seconds: dict[tuple[str, str], list[float]] = {}
        self.copies = {"cpu2gpu": 0, "gpu2cpu": 0}  # number of copies
        self.bytes = {"cpu2gpu": 0, "gpu2cpu": 0}
        self.maps = 0  # zero-copy maps of device buffers for the host
        self.on_event = None  # --trace's hook: on_event(owner, what, event, nbytes)
        for obj in parts.values():
            if hasattr(obj, "profile"):
                obj.profile = self

    def kernel(self, owner: Any, event: Any) -> None:
        self._add(owner, "kernel", event)

    def copy(self, owner: Any, direction: str, event: Any, nbytes: int) -> None:
        self.copies[direction] += 1
        self.bytes[direction] += nbytes
        self._add(owner, direction, event, nbytes)

    def mapping(self, owner: Any, what: str, event: Any) -> None:
        """A zero-copy adapter's map or unmap: device time, but no bytes copied."""
        if what == "map":
            self.maps += 1
        self._add(owner, what, event)

    def _add(self, owner: Any, what: str, event: Any, nbytes: int = 0) -> None:
        if self.on_event is not None:
            self.on_event(owner, what, event, nbytes)
        self.pending.append(((self.names.get(id(owner), "?"), what), event))
        if len(self.pending) >= self.BATCH:
            self.collect()

    def collect(self) -> None:
        """Wait for the pending events and keep their durations."""
        for key, event in self.pending:
            event.wait()
            self.seconds.setdefault(key, []).append(
                (event.profile.end - event.profile.start) * 1e-9)
        self.pending = []

    def per_frame(self, frames: int) -> dict[str, float]:
        """Copies and bytes between CPU and GPU per frame, by direction."""
        n = max(frames, 1)
        return {f"{what}_{d}": count / n for what, table in (("copies", self.copies),
                                                            ("bytes", self.bytes))
                for d, count in table.items()}

    def report(self, frames: int) -> str:
        """A table: per part and kind, calls, median and total milliseconds."""
        import statistics

        self.collect()
        rank = {name: i for i, name in enumerate(self.order)}
        rows = [("part", "what", "calls", "median ms", "total ms")]
        total = 0.0
        for (name, what), secs in sorted(self.seconds.items(),
                                         key=lambda kv: (rank.get(kv[0][0], -1), kv[0][1])):
            total += sum(secs)
            rows.append((name, what, str(len(secs)), f"{statistics.median(secs) * 1e3:.3f}",
                         f"{sum(secs) * 1e3:.1f}"))
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        lines = ["  ".join(c.rjust(w) if i >= 2 else c.ljust(w)
                           for i, (c, w) in enumerate(zip(r, widths))).rstrip() for r in rows]
        pf = self.per_frame(frames)
        lines.append(f"device time {total * 1e3:.1f} ms over {frames} frame(s); per frame "
                     f"CPU->GPU {pf['copies_cpu2gpu']:g} copies {pf['bytes_cpu2gpu']:,.0f} "
                     f"bytes, GPU->CPU {pf['copies_gpu2cpu']:g} copies "
                     f"{pf['bytes_gpu2cpu']:,.0f} bytes")
        if self.maps:
            lines[-1] += f"; {self.maps / max(frames, 1):g} zero-copy maps"
        return "\n".join(lines)
