"""The values that flow between components, shared by the IR, the plan records and the
backends: a port of a component (Endpoint) and what flows on it each frame (Data)."""

from __future__ import annotations

from dataclasses import dataclass

from .runtime.sizes import Size

# element type -> bytes per element
ELEMENT_BYTES = {"uint8": 1, "int8": 1, "uint16": 2, "int16": 2, "int32": 4, "uint32": 4,
                 "float32": 4}


@dataclass(frozen=True)
class Endpoint:
    component: str
    port: str

    def __str__(self) -> str:
        return f"{self.component}.{self.port}"


@dataclass(frozen=True)
class Data:
    """What flows on a port each frame: its Size (the runtime's one Size) and element type."""

    size: Size
    dtype: str

    @property
    def height(self) -> int:
        return self.size.height

    @property
    def width(self) -> int:
        return self.size.width

    @property
    def channels(self) -> int:
        return self.size.channels

    @property
    def nbytes(self) -> int:
        return self.size.height * self.size.width * self.size.channels * \
            ELEMENT_BYTES[self.dtype]

    def __str__(self) -> str:
        return f"{self.height}x{self.width}x{self.channels} {self.dtype}"
