// Copies image to out; with forever != 0 the first work-item never ends (the writes are
// volatile, so the compiler may not assume the loop terminates).
__kernel void spin(__global const uchar *image, __global uchar *out,
                   const int image_height, const int image_width,
                   const int out_height, const int out_width,
                   const int forever, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    if (forever && get_global_id(0) == 0 && get_global_id(1) == 0) {
        volatile __global uchar *o = out;
        for (uint i = 0; ; i++)
            o[i % 3] = (uchar)i;
    }
    for (int y = y0 + get_local_id(1); y < min(y0 + tile, out_height); y += get_local_size(1))
        for (int x = x0 + get_local_id(0); x < min(x0 + tile, out_width); x += get_local_size(0))
            for (int c = 0; c < 3; c++) {
                const size_t i = 3 * ((size_t)y * image_width + x) + c;
                out[i] = image[i];
            }
}
