// BoxBlur: smooth = mean of the (2 radius + 1)^2 neighbourhood of every pixel and channel,
// coordinates clamped to the frame, rounded half up: (sum + n / 2) / n in integers.
// One work-group covers a tile x tile square of the output; its threads stride through it.
inline uchar box_mean(__global const uchar *image, const int height, const int width,
                      const int y, const int x, const int c, const int radius)
{
    const int n = (2 * radius + 1) * (2 * radius + 1);
    int sum = 0;
    for (int dy = -radius; dy <= radius; dy++) {
        const int yy = clamp(y + dy, 0, height - 1);
        for (int dx = -radius; dx <= radius; dx++) {
            const int xx = clamp(x + dx, 0, width - 1);
            sum += image[3 * ((size_t)yy * width + xx) + c];
        }
    }
    return (uchar)((sum + n / 2) / n);
}

__kernel void box_blur(__global const uchar *image, __global uchar *smooth,
                       const int image_height, const int image_width,
                       const int smooth_height, const int smooth_width,
                       const int radius, const int tile)
{
    const int x0 = get_group_id(0) * tile;
    const int y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, smooth_width);
    const int y_end = min(y0 + tile, smooth_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1)) {
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            for (int c = 0; c < 3; c++) {
                smooth[3 * ((size_t)y * smooth_width + x) + c] =
                    box_mean(image, image_height, image_width, y, x, c, radius);
            }
        }
    }
}
