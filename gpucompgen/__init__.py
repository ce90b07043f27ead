"""gpucompgen: generate GPU-aware pipe-and-filter systems (Campeanu et al.) for OpenCL."""

__version__ = "0.1.0"
