"""The OpenCL backend (pyopencl host code, OpenCL C kernels).

    reserved.py     OpenCL C reserved words, which no model name may take
    render.py       prints a ProgramPlan through the templates (templates/opencl/ at the top
                    of the checkout) into the program's files

The device queries are the runtime's (gpucompgen.runtime.facts), because generated
programs import the runtime and not the generator; the generator reuses them for
``--device auto``.
"""
