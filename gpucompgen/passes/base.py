"""What every pass is: a name, and apply(system, rep) returning the system."""

from __future__ import annotations

from typing import ClassVar

from ..errors import Reporter
from ..ir import System


class Pass:
    name: ClassVar[str] = "pass"
    # A checking pass that still runs after an earlier pass found errors: it must cope with
    # a partly checked system (inputs without writers, no order after a cycle, missing
    # sizes), so one run reports as many independent problems as possible.
    runs_after_errors: ClassVar[bool] = False

    def apply(self, system: System, rep: Reporter) -> System:
        raise NotImplementedError
