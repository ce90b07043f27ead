"""Component types shipped with gpucompgen: declarations (*.yaml), kernels (*.cl) and the
Python classes of standard components."""
