__kernel void broken(__global const uchar *image, __global uchar *out,
                     const int image_height, const int image_width,
                     const int out_height, const int out_width, const int tile)
{
    out[0] = image[0] + undeclared_variable;
}
