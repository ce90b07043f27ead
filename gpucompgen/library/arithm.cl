// ConvertScale, AbsDiff and AddWeighted (one- and three-channel types): OpenCV's
// convertScaleAbs, absdiff and addWeighted on 8-bit images, each channel on its own.
// The float ones use fma, one rounding, as OpenCV's vector code does; convert_uchar_sat_rte
// rounds half to even and saturates, as OpenCV's saturate_cast.

inline uchar convert_scale_value(const uchar p, const float alpha, const float beta)
{
    return convert_uchar_sat_rte(fabs(fma((float)p, alpha, beta)));
}

inline uchar absdiff_value(const uchar a, const uchar b)
{
    return a > b ? a - b : b - a;
}

inline uchar add_weighted_value(const uchar a, const uchar b, const float alpha,
                                const float beta, const float gamma)
{
    return convert_uchar_sat_rte(fma((float)a, alpha, fma((float)b, beta, gamma)));
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

__kernel void convert_scale(__global const uchar *image, __global uchar *scaled,
                            const int image_height, const int image_width,
                            const int scaled_height, const int scaled_width,
                            const float alpha, const float beta, const int tile)
{
    FOR_EACH_PIXEL(scaled_height, scaled_width, 3)
        scaled[i] = convert_scale_value(image[i], alpha, beta);
}

__kernel void convert_scale_gray(__global const uchar *image, __global uchar *scaled,
                                 const int image_height, const int image_width,
                                 const int scaled_height, const int scaled_width,
                                 const float alpha, const float beta, const int tile)
{
    FOR_EACH_PIXEL(scaled_height, scaled_width, 1)
        scaled[i] = convert_scale_value(image[i], alpha, beta);
}

__kernel void absdiff(__global const uchar *src1, __global const uchar *src2,
                      __global uchar *diff,
                      const int src1_height, const int src1_width,
                      const int src2_height, const int src2_width,
                      const int diff_height, const int diff_width, const int tile)
{
    FOR_EACH_PIXEL(diff_height, diff_width, 3)
        diff[i] = absdiff_value(src1[i], src2[i]);
}

__kernel void absdiff_gray(__global const uchar *src1, __global const uchar *src2,
                           __global uchar *diff,
                           const int src1_height, const int src1_width,
                           const int src2_height, const int src2_width,
                           const int diff_height, const int diff_width, const int tile)
{
    FOR_EACH_PIXEL(diff_height, diff_width, 1)
        diff[i] = absdiff_value(src1[i], src2[i]);
}

__kernel void add_weighted(__global const uchar *src1, __global const uchar *src2,
                           __global uchar *blended,
                           const int src1_height, const int src1_width,
                           const int src2_height, const int src2_width,
                           const int blended_height, const int blended_width,
                           const float alpha, const float beta, const float gamma,
                           const int tile)
{
    FOR_EACH_PIXEL(blended_height, blended_width, 3)
        blended[i] = add_weighted_value(src1[i], src2[i], alpha, beta, gamma);
}

__kernel void add_weighted_gray(__global const uchar *src1, __global const uchar *src2,
                                __global uchar *blended,
                                const int src1_height, const int src1_width,
                                const int src2_height, const int src2_width,
                                const int blended_height, const int blended_width,
                                const float alpha, const float beta, const float gamma,
                                const int tile)
{
    FOR_EACH_PIXEL(blended_height, blended_width, 1)
        blended[i] = add_weighted_value(src1[i], src2[i], alpha, beta, gamma);
}
