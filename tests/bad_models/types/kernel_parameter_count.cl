__kernel void tinted(__global const uchar *image, __global float *tinted,
                     const int tinted_height, const int tinted_width, const int tile)
{
}
