__kernel void brighten(__global const uchar *image, __global uchar *brighter,
                       const int image_height, const int image_width,
                       const int brighter_height, const int brighter_width,
                       const int gain, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    for (int y = y0 + get_local_id(1); y < min(y0 + tile, brighter_height); y += get_local_size(1))
        for (int x = x0 + get_local_id(0); x < min(x0 + tile, brighter_width); x += get_local_size(0))
            for (int c = 0; c < 3; c++) {
                const size_t i = 3 * ((size_t)y * image_width + x) + c;
                brighter[i] = convert_uchar_sat((int)image[i] + gain);
            }
}
