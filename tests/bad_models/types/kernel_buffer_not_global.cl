__kernel void tinted(__local const uchar *image, __global float *tinted,
                     const int image_height, const int image_width,
                     const int tinted_height, const int tinted_width,
                     const float gain, const int enabled, const int tile)
{
}
