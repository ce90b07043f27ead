// Kernels of the test types: empty bodies with the parameters of the calling convention.
__kernel void join(__global const uchar *a, __global const uchar *b, __global uchar *o,
                   const int a_height, const int a_width, const int b_height,
                   const int b_width, const int o_height, const int o_width,
                   const int offset, const float scale, const int tile) {}
__kernel void to_float(__global const uchar *image, __global float *values,
                       const int image_height, const int image_width,
                       const int values_height, const int values_width, const int tile) {}
__kernel void merge_like(__global const uchar *a, __global const uchar *b, __global uchar *o,
                         const int a_height, const int a_width, const int b_height,
                         const int b_width, const int o_height, const int o_width,
                         const int tile) {}
__kernel void clash(__global const uchar *wait_for, __global uchar *mask,
                    const int wait_for_height, const int wait_for_width,
                    const int mask_height, const int mask_width, const int program,
                    const int mask_size, const int tile) {}
__kernel void shaped(__global const uchar *image, __global uchar *out,
                     const int image_height, const int image_width,
                     const int out_height, const int out_width, const int tile) {}
