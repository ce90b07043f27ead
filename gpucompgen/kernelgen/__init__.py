"""The kernel generator: one kernel from the fusable forms of a group of components.

    fused.py   a fused group's kernel (and a lone component's: a group of one) in the
               portable C subset, its schedule (rows together, staged pieces) and
               launch geometry

Both backends print what it writes: the OpenCL backend as it is, the CUDA backend under
its prelude (backend/cuda/prelude.py), so every operation and every fused group gains
from one generator.  The fuse pass, `tune` and `bench` ask it what a group's kernel is.
"""
