__kernel void table(__global const uchar *src, __global uchar *dst, const int src_height,
                    const int src_width, const int dst_height, const int dst_width,
                    const int tile)
{
}
