__kernel void join(__global const uchar *a, __global const uchar *b, __global uchar *o) {}
__kernel void to_float(__global const uchar *image, __global float *values) {}
__kernel void clash(__global const uchar *wait_for, __global uchar *mask) {}
__kernel void shaped(__global const uchar *image, __global uchar *out) {}
