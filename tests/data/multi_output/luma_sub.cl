__kernel void luma_sub(__global const uchar *image, __global uchar *luma, __global uchar *sub,
                       const int image_height, const int image_width,
                       const int luma_height, const int luma_width,
                       const int sub_height, const int sub_width, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    for (int y = y0 + get_local_id(1); y < min(y0 + tile, luma_height); y += get_local_size(1))
        for (int x = x0 + get_local_id(0); x < min(x0 + tile, luma_width); x += get_local_size(0)) {
            const size_t i = 3 * ((size_t)y * image_width + x);
            luma[(size_t)y * luma_width + x] =
                (uchar)((77 * image[i] + 150 * image[i + 1] + 29 * image[i + 2]) >> 8);
            if (y % 2 == 0 && x % 2 == 0) {
                const size_t j = 3 * ((size_t)(y / 2) * sub_width + x / 2);
                for (int c = 0; c < 3; c++)
                    sub[j + c] = image[i + c];
            }
        }
}
