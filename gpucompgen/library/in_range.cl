// InRange and InRangeGray: OpenCV's inRange, bit-exact: the mask is 255 where every
// channel c of the pixel has lowerb_c <= value <= upperb_c, else 0.
// One work-group covers a tile x tile square of the output; its threads stride through it.
inline uchar in_range_value(const uchar p, const int lowerb, const int upperb)
{
    return (p >= lowerb && p <= upperb) ? 255 : 0;
}

__kernel void in_range(__global const uchar *image, __global uchar *mask,
                       const int image_height, const int image_width,
                       const int mask_height, const int mask_width,
                       const int lowerb_0, const int lowerb_1, const int lowerb_2,
                       const int upperb_0, const int upperb_1, const int upperb_2,
                       const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, mask_width), y_end = min(y0 + tile, mask_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1)) {
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            const size_t i = 3 * ((size_t)y * image_width + x);
            mask[(size_t)y * mask_width + x] = in_range_value(image[i], lowerb_0, upperb_0)
                & in_range_value(image[i + 1], lowerb_1, upperb_1)
                & in_range_value(image[i + 2], lowerb_2, upperb_2);
        }
    }
}

__kernel void in_range_gray(__global const uchar *image, __global uchar *mask,
                            const int image_height, const int image_width,
                            const int mask_height, const int mask_width,
                            const int lowerb, const int upperb, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, mask_width), y_end = min(y0 + tile, mask_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1))
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0))
            mask[(size_t)y * mask_width + x] =
                in_range_value(image[(size_t)y * image_width + x], lowerb, upperb);
}
