// RgbToGray and RgbToHsv: OpenCV's 8-bit cvtColor(RGB2GRAY) and cvtColor(RGB2HSV),
// bit-exact. Each output pixel depends on the input pixel at the same place only.
// One work-group covers a tile x tile square of the output; its threads stride through it.

// gray = (19596 r + 38470 g + 7470 b + 2^15) >> 16: 0.299, 0.587, 0.114 in 1/65536
inline uchar gray_value(const uchar r, const uchar g, const uchar b)
{
    return (uchar)((19596u * r + 38470u * g + 7470u * b + 32768u) >> 16);
}

// HSV with hue 0..179: OpenCV's division tables computed in place,
// round(255 * 4096 / v) and round(180 * 4096 / (6 diff)) (never a tie: half up is exact).
inline uchar3 hsv_value(const int r, const int g, const int b)
{
    const int v = max(max(r, g), b);
    const int diff = v - min(min(r, g), b);
    const int sdiv = v == 0 ? 0 : (2 * (255 << 12) + v) / (2 * v);
    const int hdiv = diff == 0 ? 0 : (2 * (180 << 12) + 6 * diff) / (12 * diff);
    const int s = (diff * sdiv + (1 << 11)) >> 12;
    int h = (v == r) ? g - b : (v == g) ? b - r + 2 * diff : r - g + 4 * diff;
    h = (h * hdiv + (1 << 11)) >> 12;
    if (h < 0)
        h += 180;
    return (uchar3)((uchar)h, (uchar)s, (uchar)v);
}

__kernel void rgb_to_gray(__global const uchar *image, __global uchar *gray,
                          const int image_height, const int image_width,
                          const int gray_height, const int gray_width, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, gray_width), y_end = min(y0 + tile, gray_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1)) {
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            const size_t i = (size_t)y * image_width + x;
            gray[(size_t)y * gray_width + x] =
                gray_value(image[3 * i], image[3 * i + 1], image[3 * i + 2]);
        }
    }
}

__kernel void rgb_to_hsv(__global const uchar *image, __global uchar *hsv,
                         const int image_height, const int image_width,
                         const int hsv_height, const int hsv_width, const int tile)
{
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, hsv_width), y_end = min(y0 + tile, hsv_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1)) {
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            const size_t i = 3 * ((size_t)y * image_width + x);
            const uchar3 p = hsv_value(image[i], image[i + 1], image[i + 2]);
            const size_t o = 3 * ((size_t)y * hsv_width + x);
            hsv[o] = p.x;
            hsv[o + 1] = p.y;
            hsv[o + 2] = p.z;
        }
    }
}
