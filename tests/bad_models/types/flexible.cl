// Kernels of the flexible types in flexible.yaml: each follows the calling convention,
// so that the only problem of each type is the one it is there for.
__kernel void copy(__global const uchar *image, __global uchar *out,
                   const int image_height, const int image_width,
                   const int out_height, const int out_width, const int tile)
{
}

__kernel void copy_gain(__global const uchar *image, __global uchar *out,
                        const int image_height, const int image_width,
                        const int out_height, const int out_width, const int gain,
                        const int tile)
{
}
