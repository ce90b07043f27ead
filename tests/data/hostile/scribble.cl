// Copies image to out, then the first work-item writes one byte `offset` bytes past the
// end of out: a bug of index math that crashes a CPU device (PoCL) with SIGSEGV.
__kernel void scribble(__global const uchar *image, __global uchar *out,
                       const int image_height, const int image_width,
                       const int out_height, const int out_width,
                       const int offset, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    for (int y = y0 + get_local_id(1); y < min(y0 + tile, out_height); y += get_local_size(1))
        for (int x = x0 + get_local_id(0); x < min(x0 + tile, out_width); x += get_local_size(0))
            for (int c = 0; c < 3; c++) {
                const size_t i = 3 * ((size_t)y * image_width + x) + c;
                out[i] = image[i];
            }
    if (get_global_id(0) == 0 && get_global_id(1) == 0) {
        volatile __global uchar *far = out + (size_t)out_height * out_width * 3
                                           + (size_t)offset * 64;
        far[0] = 1;
    }
}
