// AbsGray16: |x| of an int16 frame saturated to uchar (cv2.convertScaleAbs on a gradient).
__kernel void abs_gray16(__global const short *image, __global uchar *absolute,
                         const int image_height, const int image_width,
                         const int absolute_height, const int absolute_width, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, absolute_width), y_end = min(y0 + tile, absolute_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1))
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            const size_t i = (size_t)y * absolute_width + x;
            absolute[i] = convert_uchar_sat(abs((int)image[i]));
        }
}
