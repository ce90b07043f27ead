"""OpenCL C reserved words: no model name may become one (kernels use port and parameter
names); and the modules an OpenCL program and its runtime import, after which no system may
be named (its program's folder comes first on sys.path)."""

WORDS = frozenset({
    "auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else",
    "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long", "register",
    "restrict", "return", "short", "signed", "sizeof", "static", "struct", "switch", "typedef",
    "union", "unsigned", "void", "volatile", "while", "bool", "half", "uchar", "ushort", "uint",
    "ulong", "size_t", "ptrdiff_t", "intptr_t", "uintptr_t", "image2d_t", "image3d_t",
    "image2d_array_t", "image1d_t", "image1d_buffer_t", "image1d_array_t", "sampler_t", "event_t",
    "kernel", "__kernel", "global", "__global", "local", "__local", "constant", "__constant",
    "private", "__private", "read_only", "__read_only", "write_only", "__write_only", "read_write",
    "__read_write", "complex", "imaginary", "true", "false",
})

# pyopencl and the packages it imports
MODULES = frozenset({"pyopencl", "pytools", "platformdirs", "siphash24", "typing_extensions"})
