// Threshold and ThresholdGray: OpenCV's threshold on 8-bit images, bit-exact, each
// channel on its own. thresh_type is OpenCV's code: 0 THRESH_BINARY, 1 THRESH_BINARY_INV,
// 2 THRESH_TRUNC, 3 THRESH_TOZERO, 4 THRESH_TOZERO_INV.
inline uchar threshold_value(const uchar p, const int thresh, const int maxval,
                             const int thresh_type)
{
    const bool above = p > thresh;
    switch (thresh_type) {
    case 0: return above ? maxval : 0;
    case 1: return above ? 0 : maxval;
    case 2: return above ? thresh : p;
    case 3: return above ? p : 0;
    default: return above ? 0 : p;
    }
}

// The elements a work-group covers: a tile x tile square of pixels, its threads
// striding through it; i is each channel's element in turn.
#define FOR_EACH_PIXEL(height, width, channels)                                      \
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;              \
    const int x_end = min(x0 + tile, width), y_end = min(y0 + tile, height);         \
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1))            \
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0))        \
            for (size_t i = (channels) * ((size_t)y * (width) + x), c = 0;            \
                 c < (channels); c++, i++)

__kernel void threshold(__global const uchar *image, __global uchar *thresholded,
                        const int image_height, const int image_width,
                        const int thresholded_height, const int thresholded_width,
                        const int thresh, const int maxval, const int thresh_type,
                        const int tile)
{
    FOR_EACH_PIXEL(thresholded_height, thresholded_width, 3)
        thresholded[i] = threshold_value(image[i], thresh, maxval, thresh_type);
}

__kernel void threshold_gray(__global const uchar *image, __global uchar *thresholded,
                             const int image_height, const int image_width,
                             const int thresholded_height, const int thresholded_width,
                             const int thresh, const int maxval, const int thresh_type,
                             const int tile)
{
    FOR_EACH_PIXEL(thresholded_height, thresholded_width, 1)
        thresholded[i] = threshold_value(image[i], thresh, maxval, thresh_type);
}
