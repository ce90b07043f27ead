"""The size of the data on one port, as generated programs use it."""

from __future__ import annotations

from typing import Any, NamedTuple


class Size(NamedTuple):
    """The size of the data on one port (the paper's SIZE_TYPE)."""

    height: int
    width: int
    channels: int = 1

    def nbytes(self, dtype: Any) -> int:
        import numpy as np

        return self.height * self.width * self.channels * np.dtype(dtype).itemsize

    @property
    def shape(self) -> tuple[int, ...]:
        """Host array shape: (height, width) for one channel, else (height, width, channels)."""
        if self.channels == 1:
            return (self.height, self.width)
        return (self.height, self.width, self.channels)
