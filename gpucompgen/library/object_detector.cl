// ObjectDetector: mask = 255 where a pixel is red enough, else 0.
// The per-pixel test is separate from the tiled loop so it can later be fused with others.
inline uchar is_red(const uchar r, const uchar g, const uchar b,
                    const int red_min, const int margin)
{
    return (r >= red_min && (int)r - (int)g >= margin && (int)r - (int)b >= margin) ? 255 : 0;
}

__kernel void object_detector(__global const uchar *frame, __global uchar *mask,
                              const int frame_height, const int frame_width,
                              const int mask_height, const int mask_width,
                              const int red_min, const int margin,
                              const int tile)
{
    const int x0 = get_group_id(0) * tile;
    const int y0 = get_group_id(1) * tile;
    const int x_end = min(x0 + tile, mask_width);
    const int y_end = min(y0 + tile, mask_height);
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1)) {
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0)) {
            const size_t i = (size_t)y * frame_width + x;
            mask[(size_t)y * mask_width + x] =
                is_red(frame[3 * i], frame[3 * i + 1], frame[3 * i + 2], red_min, margin);
        }
    }
}
