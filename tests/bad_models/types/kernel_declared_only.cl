__kernel void tinted(__global const uchar *image, __global float *tinted,
    int image_height, int image_width, int tinted_height, int tinted_width,
    float gain, int enabled, int tile);
