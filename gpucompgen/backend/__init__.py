"""Backends: everything specific to one way of running kernels.

opencl/ is the only backend today: its templates, C type names, reserved words, the
kernel calling convention and its check, and device queries live there together, so a
CUDA backend would be a sibling package.
"""
