"""The templates of every backend, one folder each (templates/opencl/...): they print the
plan's records, nothing is decided there.  In a checkout they are this top-level folder;
an installed wheel ships them as package data of ``gpucompgen.templates`` (pyproject.toml),
found by ``gpucompgen.output.template_folder``."""
