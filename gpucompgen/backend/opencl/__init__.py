"""The OpenCL backend (pyopencl host code, OpenCL C kernels)."""
