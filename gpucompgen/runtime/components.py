"""The base class of kernel components: what every GPU-aware component class does.

A generated class declares what differs per type — its kernel function, its ports and
their element types, and how its output sizes follow from its inputs and parameters —
and the generated ``run()`` passes what differs per system: the GPU settings, global and
local sizes and the kernel's arguments in calling-convention order (buffers by port name,
scalars as values).  This class allocates, launches and frees, through the device
interface (device_api.py): `api` names the device API's module (default: OpenCL's).
"""

from __future__ import annotations

from typing import Any, ClassVar

from . import device_api
from .frames import read_only
from .sizes import Size


class KernelComponent:
    function: ClassVar[str] = ""
    # (port, numpy element type) in the type's order
    inputs: ClassVar[tuple[tuple[str, Any], ...]] = ()
    outputs: ClassVar[tuple[tuple[str, Any], ...]] = ()
    api: ClassVar[Any] = None  # the device API's module (None: device_api's default)

    def __init__(self, context, queue, program, *, copies_own_data: bool = False,
                 host_visible: bool = False, buffer_sets: int = 1, **params: Any):
        """copies_own_data: a standard component (paper, Section II) that copies its inputs
        to the device and its outputs back itself on every execute; host_visible: outputs
        in host-visible memory, so a zero-copy adapter can map them; buffer_sets: with
        frames in flight, one set of buffers per frame in flight, used in turn (another
        stage reads set f while this one writes set f + 1)."""
        api = self._api = self.api or device_api.get()
        self.context = context
        self.queue = queue
        self.buffer_sets = buffer_sets
        # one kernel object per buffer set: arguments that do not change from frame to
        # frame are set once per set, not once per launch
        self.kernels = [api.kernel(program, self.function) for _ in range(buffer_sets)]
        self._enqueue = api.launcher()  # looked up once, not once a frame
        self.kernel = self.kernels[0]
        self.copies_own_data = copies_own_data
        self.host_visible = host_visible
        self.profile = None  # a runtime.Profile with --profile
        self.event = None  # of the last kernel enqueued
        for name, value in params.items():
            setattr(self, name, value)
        self._inputs, self._outputs = dict(self.inputs), dict(self.outputs)
        self.sizes: dict[str, Size] = {}
        self.sets: list[dict[str, Any]] = []  # device buffers by port, per set
        self.host_sets: list[dict[str, Any]] = []  # host arrays of outputs (copies_own_data)
        self._turn = 0  # the set the next execute() uses
        self._results: list = []  # per set: what execute() returns (a buffer or a tuple)

    @property
    def buffers(self) -> dict[str, Any]:
        """The device buffers of the first set, by port."""
        return self.sets[0] if self.sets else {}

    @property
    def hosts(self) -> dict[str, Any]:
        return self.host_sets[0] if self.host_sets else {}

    def output_sizes(self, *inputs: Size) -> list[Size]:
        raise NotImplementedError

    def initialize(self, *inputs: Size):
        """Input sizes in, output sizes out; memory is allocated once, here."""
        import numpy as np

        api = self._api
        for port, size in zip(self._inputs, inputs):
            self.sizes[port] = Size(*size)
        out_sizes = list(self.output_sizes(*inputs))
        for port, size in zip(self._outputs, out_sizes):
            self.sizes[port] = size
        for _ in range(self.buffer_sets):
            buffers, hosts = {}, {}
            if self.copies_own_data:
                for port, dtype in self._inputs.items():
                    buffers[port] = api.device_buffer(self.context,
                                                      self.sizes[port].nbytes(dtype), "read")
                for port, dtype in self._outputs.items():
                    buffers[port] = api.device_buffer(self.context,
                                                      self.sizes[port].nbytes(dtype), "write")
                    hosts[port] = np.empty(self.sizes[port].shape, dtype)
            else:
                for port, dtype in self._outputs.items():
                    buffers[port] = api.device_buffer(
                        self.context, self.sizes[port].nbytes(dtype), "read_write",
                        host_visible=self.host_visible)
            self.sets.append(buffers)
            self.host_sets.append(hosts)
            given = [(hosts if self.copies_own_data else buffers)[port] for port in self._outputs]
            self._results.append(given[0] if len(given) == 1 else tuple(given))
        return out_sizes[0] if len(out_sizes) == 1 else tuple(out_sizes)

    def config_gpu(self, tile: int, local_size: tuple[int, int, int],
                   global_size: tuple[int, int, int], arguments, settings_source: str = ""):
        """The GPU settings the system chose, used for every frame; arguments in the
        calling convention's order: a port's name stands for its buffer."""
        self.tile, self.local_size, self.global_size = tile, local_size, global_size
        self._api.check_work_group(self.kernel, self._api.device_of(self.queue), local_size,
                                   type(self).__name__, settings_source=settings_source)
        inputs = [port for port, _ in self.inputs]
        # (argument index, input index): filled in by execute() with the inputs it is given
        self._slots = [(i, inputs.index(arg)) for i, arg in enumerate(arguments)
                       if isinstance(arg, str) and arg not in self.buffers]
        # per set: the arguments with that set's own buffers in place
        self._argument_sets = [[buffers.get(arg, arg) if isinstance(arg, str) else arg
                                for arg in arguments] for buffers in self.sets]
        self._bound: list[tuple | None] = [None] * self.buffer_sets  # inputs last set

    def _kernel_for(self, k: int, inputs) -> Any:
        """Set k's kernel with its arguments: all of them the first time, then only when
        an input buffer differs from the one set last time (never, once producers keep
        their buffers: the host cost of a launch is then the enqueue alone)."""
        kernel = self.kernels[k]
        given = inputs
        bound = self._bound[k]
        if bound is None or len(bound) != len(given) or any(
                a is not b for a, b in zip(bound, given)):
            args = self._argument_sets[k]
            if not self.copies_own_data:
                for i, j in self._slots:
                    args[i] = given[j]
            self._api.set_args(kernel, *args)
            self._bound[k] = given
        return kernel

    def execute(self, *inputs, wait_for=None):
        k = self._turn
        if self.buffer_sets > 1:
            self._turn = (k + 1) % self.buffer_sets
        if self.copies_own_data:
            self._copy_and_run(k, inputs)
        else:
            self.event = self._enqueue(self.queue, self._kernel_for(k, inputs),
                                       self.global_size, self.local_size, wait_for=wait_for)
            if self.profile is not None:
                self.profile.kernel(self, self.event)
        return self._results[k]

    def _copy_and_run(self, k: int, inputs) -> None:
        """A standard component's frame: its inputs to the device, the kernel, its outputs
        back, all waited for by the blocking copies back."""
        import numpy as np

        copy = self._api.copy
        buffers, hosts = self.sets[k], self.host_sets[k]
        copied_in = [copy(self.queue, buffers[port], np.ascontiguousarray(x))
                     for port, x in zip(self._inputs, inputs)]
        ran = self._enqueue(self.queue, self._kernel_for(k, ()), self.global_size,
                            self.local_size)
        copied_out = [copy(self.queue, hosts[port], buffers[port]) for port in self._outputs]
        if self.profile is not None:
            for port, event in zip(self._inputs, copied_in):
                self.profile.copy(self, "cpu2gpu", event, self._api.nbytes(buffers[port]))
            self.profile.kernel(self, ran)
            for port, event in zip(self._outputs, copied_out):
                self.profile.copy(self, "gpu2cpu", event, hosts[port].nbytes)

    def free_memory(self):
        for hosts in self.host_sets:
            hosts.clear()
        for buffers in self.sets:
            for port, _ in self.outputs + self.inputs:
                buffer = buffers.pop(port, None)
                if buffer is not None:
                    self._api.release(buffer)
        self.sets, self.host_sets, self._results = [], [], []
        self._argument_sets = []


class CpuFunctionComponent:
    """A flexible component placed on the CPU: its type's CPU function, called per frame.

    The function takes the input arrays and the parameters as keywords and returns the
    output array (a tuple of arrays for several outputs, in the type's order).
    initialize() calls it once on zero-filled inputs of the propagated sizes to learn the
    output sizes (the program then checks them against the plan's); execute() checks every
    result's shape and element type and names the component and port when one is wrong.
    A one-channel output may come as height x width x 1: it is handed on as the height x
    width view of the same memory.  What can be decided once (port names, the shapes and
    element types expected) is decided in initialize(), so a frame costs the call and
    a few comparisons.
    """

    def __init__(self, function, name: str, *, inputs: tuple[tuple[str, Any], ...],
                 outputs: tuple[tuple[str, Any], ...], **params: Any):
        self.function = function
        self.name = name
        self.inputs = tuple(inputs)
        self.outputs = tuple(outputs)
        self.params = params
        self.sizes: dict[str, Size] = {}
        self.profile = None  # a runtime.Profile with --profile: nothing to time on a queue
        self.event = None  # never waited for: results are ready when execute returns
        self._ports = tuple(port for port, _ in self.inputs)
        self._expected: tuple = ()  # (port, shape, numpy dtype) per output, from initialize

    def initialize(self, *inputs: Size):
        import numpy as np

        arrays = {}
        for (port, dtype), size in zip(self.inputs, inputs):
            self.sizes[port] = Size(*size)
            arrays[port] = np.zeros(self.sizes[port].shape, dtype)
        results = self._call(arrays)
        out_sizes = []
        for (port, _), result in zip(self.outputs, results):
            shape = getattr(result, "shape", ())
            channels = shape[2] if len(shape) == 3 else 1
            size = Size(shape[0], shape[1], channels) if len(shape) in (2, 3) \
                else Size(0, 0, 0)
            self.sizes[port] = size
            out_sizes.append(size)
        self._expected = tuple((port, self.sizes[port].shape, np.dtype(dtype))
                               for port, dtype in self.outputs)
        return out_sizes[0] if len(out_sizes) == 1 else tuple(out_sizes)

    def _call(self, arrays) -> tuple:
        results = self.function(**arrays, **self.params)
        if len(self.outputs) == 1:
            results = (results,)
        elif not isinstance(results, tuple) or len(results) != len(self.outputs):
            raise TypeError(f"{self.name}: the CPU function {self.function.__name__}() must "
                            f"return {len(self.outputs)} arrays (a tuple, in the order "
                            f"{', '.join(p for p, _ in self.outputs)})")
        return results

    def execute(self, *inputs):
        # inputs are read-only: another reader of the producer gets the same frame
        results = self._call({p: read_only(x) for p, x in zip(self._ports, inputs)})
        checked = [self._checked(result, *expected)
                   for result, expected in zip(results, self._expected)]
        return checked[0] if len(checked) == 1 else tuple(checked)

    def _checked(self, result, port: str, want: tuple[int, ...], dtype):
        """result as a C-contiguous array of the shape and dtype the system expects."""
        import numpy as np

        if isinstance(result, np.ndarray) and result.dtype == dtype:
            if result.shape != want and len(want) == 2 and result.shape == (*want, 1):
                result = result.reshape(want)  # one channel as height x width x 1: a view
            if result.shape == want:
                # every reader gets the same array: none may write it
                return read_only(result if result.flags.c_contiguous
                                 else np.ascontiguousarray(result))
        got = (f"{result.dtype} {result.shape}" if isinstance(result, np.ndarray)
               else type(result).__name__)
        raise ValueError(f"{self.name}.{port}: the CPU function "
                         f"{self.function.__name__}() returned {got}, not {dtype} {want}"
                         + (f" (or {(*want, 1)})" if len(want) == 2 else ""))

    def free_memory(self):
        self.sizes.clear()
