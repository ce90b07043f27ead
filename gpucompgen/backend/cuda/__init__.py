"""The CUDA backend (cuda-python host code, the portable kernels as CUDA C++).

    prelude.py  OpenCL C's neutral names mapped to CUDA, and the check of a kernel's text
    render.py   the program (the OpenCL printer's, driving gpucompgen.runtime.cuda) and
                one .cu file per kernel file
    nvrtc.py    NVRTC through ctypes: compile for any architecture without a driver

The runtime side is gpucompgen.runtime.cuda (generated programs import the runtime, not
the generator).  docs/cuda.md says what runs where.
"""
