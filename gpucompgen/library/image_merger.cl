// ImageMerger: merged = [left | right], RGB uint8, rows of the same height.
// One work-group covers a tile x tile square of the output; its threads stride through it.
__kernel void image_merger(__global const uchar *left, __global const uchar *right,
                           __global uchar *merged,
                           const int left_height, const int left_width,
                           const int right_height, const int right_width,
                           const int merged_height, const int merged_width,
                           const int tile)
{
    const int x0 = get_group_id(0) * tile;
    const int y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, merged_width);
    const int y_end = min(y0 + tile, merged_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1)) {
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            __global const uchar *src = (x < left_width)
                ? left + 3 * ((size_t)y * left_width + x)
                : right + 3 * ((size_t)y * right_width + (x - left_width));
            __global uchar *dst = merged + 3 * ((size_t)y * merged_width + x);
            dst[0] = src[0];
            dst[1] = src[1];
            dst[2] = src[2];
        }
    }
}
