"""The adapters between CPU and GPU memory (the paper's Figures 6 and 7), the same in
every system: the generated program constructs them with the bytes and settings its plan
chose, and calls transfer() once a frame.

Copying adapters own one buffer (device for CPU-to-GPU, host for GPU-to-CPU); zero-copy
adapters, on devices with unified host memory, let the other side use the memory in place.
They reach the device through the device interface (device_api.py): `api` names the
device API's module (default: OpenCL's).
"""

from __future__ import annotations

from typing import Any, ClassVar

from . import device_api
from .errors import PipelineError
from .frames import read_only
from .sizes import Size


class _Adapter:
    api: ClassVar[Any] = None  # the device API's module (None: device_api's default)

    def __init__(self, context, queue, nbytes: int):
        self._api = self.api or device_api.get()
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
    """One device buffer (per buffer set), one copy a frame.

    Not blocking (parallel execution): the copy's event keeps the host frame alive until
    the device has read it; blocking (sequential execution): the copy is done on return.
    staging="pinned": the frame is first put in a pinned host array (a host copy), and
    the device copies from there.  buffer_sets (frames in flight): the device reads set f
    while the next frame is copied to set f + 1.
    """

    def __init__(self, context, queue, nbytes: int, blocking: bool = True,
                 buffer_sets: int = 1, staging: str = "pageable"):
        super().__init__(context, queue, nbytes)
        self.blocking = blocking
        self.buffer_sets, self.staging = buffer_sets, staging
        self.buffers: list = []
        self.pinned: list = []  # (buffer, mapped array) per set, with staging="pinned"
        self.buffer = None  # the buffer of the last frame
        self._turn = 0
        # with staging="pinned" and not blocking: each set's last copy, which must have
        # read the set's pinned array before the next frame is written into it
        self._reading: list = []

    def initialize(self, size, dtype):
        api = self._api
        size = super().initialize(size, dtype)
        for _ in range(self.buffer_sets):
            self.buffers.append(api.device_buffer(self.context, self.nbytes, "read"))
            if self.staging == "pinned":
                self.pinned.append(api.pinned(self.context, self.queue, size.shape, dtype))
        self._reading = [None] * self.buffer_sets
        self.buffer = self.buffers[0]
        return size

    def transfer(self, host, wait_for=None):
        import numpy as np

        self._check(host)
        k = self._turn
        self._turn = (k + 1) % self.buffer_sets
        self.buffer = self.buffers[k]
        if self.pinned:
            if not self.blocking and self._reading[k] is not None:
                # the device may not have read the set's previous frame yet (nothing
                # else orders the host's write after it); done already, this is free
                self._api.wait([self._reading[k]])
            source = self.pinned[k][1]
            np.copyto(source, np.reshape(host, source.shape), casting="no")
        else:
            source = np.ascontiguousarray(host)
        self.event = self._api.copy(self.queue, self.buffer, source,
                                    blocking=self.blocking, wait_for=wait_for)
        if self.pinned and not self.blocking:
            self._reading[k] = self.event
        if self.profile is not None:
            self.profile.copy(self, "cpu2gpu", self.event, self.nbytes)
        return self.buffer

    def free_memory(self):
        pinned, self.pinned, self._reading = self.pinned, [], []
        self._api.release_pinned(self.queue, pinned)
        for buffer in self.buffers:
            self._api.release(buffer)
        self.buffers, self.buffer = [], None


class ZeroCopyCpuToGpuAdapter(_Adapter):
    """The device reads the producer's frame in place (unified host memory).

    A buffer made with USE_HOST_PTR over the frame is the frame: nothing is copied, and
    nothing is enqueued, so --profile shows no device time for it.  The frame must not
    change while the device reads it; the program finishes every frame before the next.
    With buffer_sets (frames in flight) the producer makes its next frame while the
    device still reads this one: the frame is kept in one of the adapter's own host
    arrays (a host copy, no CPU-GPU copy), each wrapped once in a USE_HOST_PTR buffer
    and written only while mapped: OpenCL defines what the device sees of a USE_HOST_PTR
    buffer's memory written by the host only through map and unmap (a discrete GPU keeps
    its own copy of it and, written behind its back, reads a frame from N frames ago).
    The mapping runs on a queue of the adapter's own, so it never waits for the kernels
    that still read other sets; on unified memory it costs no copy.
    """

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1):
        super().__init__(context, queue, nbytes)
        self.buffer_sets = buffer_sets
        self.buffer = None
        self.host = None
        self.snapshots: list = []  # (host array, buffer over it) per set
        self._map_queue = None  # with buffer_sets: the queue that maps them for writing
        self._turn = 0

    def initialize(self, size, dtype):
        import numpy as np

        size = super().initialize(size, dtype)
        if self.buffer_sets > 1:
            self._map_queue = self._api.side_queue(self.queue)
            for _ in range(self.buffer_sets):
                host = np.empty(size.shape, dtype)
                self.snapshots.append((host, self._api.host_buffer(self.context, host)))
        return size

    def transfer(self, host, wait_for=None):
        import numpy as np

        api = self._api
        self._check(host)
        if self.snapshots:
            k = self._turn
            self._turn = (k + 1) % self.buffer_sets
            self.host, self.buffer = self.snapshots[k]
            view, _ = api.map(self._map_queue, self.buffer, self.host.shape, self.host.dtype,
                              "write")
            np.copyto(view, np.reshape(host, view.shape), casting="no")
            api.unmap(self._map_queue, view).wait()  # unmapped: the device sees the frame
            return self.buffer
        self.free_memory()  # the previous frame's buffer: its frame is complete
        self.host = np.ascontiguousarray(host)  # kept alive while the device reads it
        self.buffer = api.host_buffer(self.context, self.host)
        return self.buffer

    def free_memory(self):
        if self.buffer is not None and not self.snapshots:
            self._api.release(self.buffer)
        self.buffer = None
        self.host = None
        snapshots, self.snapshots = self.snapshots, []
        for _, buffer in snapshots:
            self._api.release(buffer)
        self._map_queue = None


class GpuToCpuAdapter(_Adapter):
    """One host array (per buffer set), one blocking copy a frame (the host reads it next).

    staging="pinned": the host arrays are pinned (mapped ALLOC_HOST_PTR buffers), so the
    device copies straight into them.  buffer_sets (frames in flight): the consumer reads
    set f while the device copies the next frame into set f + 1.
    """

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1,
                 staging: str = "pageable"):
        super().__init__(context, queue, nbytes)
        self.buffer_sets, self.staging = buffer_sets, staging
        self.hosts: list = []
        self.pinned: list = []
        self.host = None  # the array of the last frame
        self._turn = 0

    def initialize(self, size, dtype):
        import numpy as np

        size = super().initialize(size, dtype)
        for _ in range(self.buffer_sets):
            if self.staging == "pinned":
                self.pinned.append(self._api.pinned(self.context, self.queue, size.shape,
                                                    dtype))
                self.hosts.append(self.pinned[-1][1])
            else:
                self.hosts.append(np.empty(size.shape, dtype))
        self.host = self.hosts[0]
        return size

    def transfer(self, buffer, wait_for=None):
        k = self._turn
        self._turn = (k + 1) % self.buffer_sets
        self.host = self.hosts[k]
        self.event = self._api.copy(self.queue, self.host, buffer, wait_for=wait_for)
        if self.profile is not None:
            self.profile.copy(self, "gpu2cpu", self.event, self.nbytes)
        return read_only(self.host)  # every reader gets the same frame: none may write it

    def free_memory(self):
        self.hosts, self.host = [], None
        pinned, self.pinned = self.pinned, []
        self._api.release_pinned(self.queue, pinned)


class ZeroCopyGpuToCpuAdapter(_Adapter):
    """The consumer reads the device buffer, mapped.

    transfer() maps the buffer for reading (blocking: the device has finished writing it)
    and returns the mapped view; unmap() gives the buffer back to the device and must come
    before the device writes it again (OpenCL's mapping rule).  A consumer that keeps data
    past its execute() copies it, as with any adapter's output.  With buffer_sets (frames
    in flight) up to that many frames' buffers are mapped at once (the producer writes
    one set per frame); unmap() gives back the oldest.  wait_unmap=False (frames in flight,
    where the buffer's writer uses this adapter's in-order queue): unmap() enqueues the
    unmap without waiting for it; the queue runs it before the writer's next kernel, and a
    wait would also wait for the kernels of later frames queued before it.
    """

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1,
                 wait_unmap: bool = True):
        from collections import deque

        super().__init__(context, queue, nbytes)
        self.buffer_sets = buffer_sets
        self.wait_unmap = wait_unmap
        self.views = deque()  # mapped, oldest first

    @property
    def view(self):
        """The view of the last frame mapped (None when every buffer is unmapped)."""
        return self.views[-1] if self.views else None

    def transfer(self, buffer, wait_for=None):
        if len(self.views) >= self.buffer_sets:
            raise PipelineError("buffer mapped twice: unmap() was not called")
        view, self.event = self._api.map(self.queue, buffer, self.shape, self.dtype, "read",
                                         wait_for=wait_for)
        self.views.append(view)
        if self.profile is not None:
            self.profile.mapping(self, "map", self.event)
        return read_only(view)  # mapped for reading: every reader gets the same frame

    def unmap(self):
        if self.views:
            view = self.views.popleft()
            event = self._api.unmap(self.queue, view)
            if self.wait_unmap:
                event.wait()
            if self.profile is not None:
                self.profile.mapping(self, "unmap", event)

    def free_memory(self):
        while self.views:
            self.unmap()
