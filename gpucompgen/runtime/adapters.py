"""The adapters between CPU and GPU memory (the paper's Figures 6 and 7), the same in
every system: the generated program constructs them with the bytes and settings its plan
chose, and calls transfer() once a frame.

Copying adapters own one buffer (device for CPU-to-GPU, host for GPU-to-CPU); zero-copy
adapters, on devices with unified host memory, let the other side use the memory in place.
"""

from __future__ import annotations

from .errors import PipelineError
from .sizes import Size


class _Adapter:
    def __init__(self, context, queue, nbytes: int):
        self.context = context
        self.queue = queue
        self.nbytes = nbytes  # a frame's bytes, from the system plan
        self.profile = None  # a runtime.Profile with --profile
        self.event = None

    def initialize(self, size, dtype):
        """The size of the frames it moves in; the same size out, in the other memory."""
        size = Size(*size)
        if size.nbytes(dtype) != self.nbytes:
            raise PipelineError(f"a frame of {size.nbytes(dtype):,} bytes where the system "
                                f"was built for {self.nbytes:,}")
        self.shape, self.dtype = size.shape, dtype
        return size

    def _check(self, host) -> None:
        if host.nbytes != self.nbytes:
            raise PipelineError(f"frame of {host.nbytes:,} bytes where {self.nbytes:,} "
                                "were expected")


class CpuToGpuAdapter(_Adapter):
    """One device buffer, one copy a frame.

    Not blocking (parallel execution): the copy's event keeps the host frame alive until
    the device has read it; blocking (sequential execution): the copy is done on return.
    """

    def __init__(self, context, queue, nbytes: int, blocking: bool = True):
        super().__init__(context, queue, nbytes)
        self.blocking = blocking
        self.buffer = None

    def initialize(self, size, dtype):
        import pyopencl as cl

        size = super().initialize(size, dtype)
        self.buffer = cl.Buffer(self.context, cl.mem_flags.READ_ONLY, self.nbytes)
        return size

    def transfer(self, host, wait_for=None):
        import numpy as np
        import pyopencl as cl

        self._check(host)
        self.event = cl.enqueue_copy(self.queue, self.buffer, np.ascontiguousarray(host),
                                     is_blocking=self.blocking, wait_for=wait_for)
        if self.profile is not None:
            self.profile.copy(self, "cpu2gpu", self.event, self.nbytes)
        return self.buffer

    def free_memory(self):
        if self.buffer is not None:
            self.buffer.release()
            self.buffer = None


class ZeroCopyCpuToGpuAdapter(_Adapter):
    """The device reads the producer's frame in place (unified host memory).

    A buffer made with USE_HOST_PTR over the frame is the frame: nothing is copied, and
    nothing is enqueued, so --profile shows no device time for it.  The frame must not
    change while the device reads it; the program finishes every frame before the next.
    """

    def __init__(self, context, queue, nbytes: int):
        super().__init__(context, queue, nbytes)
        self.buffer = None
        self.host = None

    def transfer(self, host, wait_for=None):
        import numpy as np
        import pyopencl as cl

        self._check(host)
        self.free_memory()  # the previous frame's buffer: its frame is complete
        self.host = np.ascontiguousarray(host)  # kept alive while the device reads it
        self.buffer = cl.Buffer(self.context,
                                cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR,
                                hostbuf=self.host)
        return self.buffer

    def free_memory(self):
        if self.buffer is not None:
            self.buffer.release()
            self.buffer = None
        self.host = None


class GpuToCpuAdapter(_Adapter):
    """One host array, one blocking copy a frame (the host reads it next)."""

    def __init__(self, context, queue, nbytes: int):
        super().__init__(context, queue, nbytes)
        self.host = None

    def initialize(self, size, dtype):
        import numpy as np

        size = super().initialize(size, dtype)
        self.host = np.empty(size.shape, dtype)
        return size

    def transfer(self, buffer, wait_for=None):
        import pyopencl as cl

        self.event = cl.enqueue_copy(self.queue, self.host, buffer, wait_for=wait_for)
        if self.profile is not None:
            self.profile.copy(self, "gpu2cpu", self.event, self.nbytes)
        return self.host

    def free_memory(self):
        self.host = None


class ZeroCopyGpuToCpuAdapter(_Adapter):
    """The consumer reads the device buffer, mapped.

    transfer() maps the buffer for reading (blocking: the device has finished writing it)
    and returns the mapped view; unmap() gives the buffer back to the device and must come
    before the device writes it again (OpenCL's mapping rule).  A consumer that keeps data
    past its execute() copies it, as with any adapter's output.
    """

    def __init__(self, context, queue, nbytes: int):
        super().__init__(context, queue, nbytes)
        self.view = None

    def transfer(self, buffer, wait_for=None):
        import numpy as np
        import pyopencl as cl

        if self.view is not None:
            raise PipelineError("buffer mapped twice: unmap() was not called")
        self.view, self.event = cl.enqueue_map_buffer(
            self.queue, buffer, cl.map_flags.READ, 0, self.shape, np.dtype(self.dtype),
            is_blocking=True, wait_for=wait_for)
        if self.profile is not None:
            self.profile.mapping(self, "map", self.event)
        return self.view

    def unmap(self):
        if self.view is not None:
            event = self.view.base.release(self.queue)
            event.wait()
            self.view = None
            if self.profile is not None:
                self.profile.mapping(self, "unmap", event)

    def free_memory(self):
        self.unmap()
