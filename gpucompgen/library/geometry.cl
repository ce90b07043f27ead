// Resize and Crop (one- and three-channel types): the library's only hand-written kernels,
// the operations without a fusable form (every other type's kernel is generated from its
// form). Each output pixel is a copy of (or, for bilinear resize, a mix of) input pixels
// at positions computed from its own. OpenCV: resize, an ROI.

// The output pixels (y, x) a work-group covers: a tile x tile square, its threads
// striding through it.
#define FOR_EACH_OUTPUT(height, width)                                               \
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;              \
    const int x_end = min(x0 + tile, width), y_end = min(y0 + tile, height);         \
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1))            \
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0))

// INTER_NEAREST: output index d reads floor(d * (1 / (dst / src))), computed in double
// as OpenCV does (the exact d * src / dst differs where the double rounds an integer
// down); devices without doubles use the exact quotient.
#if defined(cl_khr_fp64)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
inline int nearest_index(const int d, const int dst, const int src)
{
    const double scale = 1.0 / ((double)dst / (double)src);
    return min((int)floor((double)d * scale), src - 1);
}
#else
inline int nearest_index(const int d, const int dst, const int src)
{
    return min((int)(((long)d * src) / dst), src - 1);
}
#endif

// INTER_LINEAR along one axis: the source position ((2 d + 1) src - dst) / (2 dst) as its
// floor s (first neighbour, clamped) and the weight of the second neighbour in 1/2048,
// rounded half up.
inline int2 linear_axis(const int d, const int dst, const int src, int *weight)
{
    const int num = (2 * d + 1) * src - dst;
    const int s = num >= 0 ? num / (2 * dst) : -((-num + 2 * dst - 1) / (2 * dst));
    const int frac = num - s * 2 * dst;
    *weight = (frac * 2048 + dst) / (2 * dst);
    return (int2)(clamp(s, 0, src - 1), clamp(s + 1, 0, src - 1));
}

inline void resize_pixel(__global const uchar *image, const int height, const int width,
                         __global uchar *resized, const int rh, const int rw,
                         const int y, const int x, const int channels,
                         const int interpolation)
{
    const size_t o = channels * ((size_t)y * rw + x);
    if (interpolation == 0) {
        const size_t i = channels * ((size_t)nearest_index(y, rh, height) * width
                                     + nearest_index(x, rw, width));
        for (int c = 0; c < channels; c++)
            resized[o + c] = image[i + c];
        return;
    }
    int wy, wx;
    const int2 ys = linear_axis(y, rh, height, &wy);
    const int2 xs = linear_axis(x, rw, width, &wx);
    const size_t r0 = (size_t)ys.x * width, r1 = (size_t)ys.y * width;
    for (int c = 0; c < channels; c++) {
        const int top = (2048 - wx) * image[channels * (r0 + xs.x) + c]
                        + wx * image[channels * (r0 + xs.y) + c];
        const int bottom = (2048 - wx) * image[channels * (r1 + xs.x) + c]
                           + wx * image[channels * (r1 + xs.y) + c];
        resized[o + c] = (uchar)(((2048 - wy) * top + wy * bottom + (1 << 21)) >> 22);
    }
}

__kernel void resize(__global const uchar *image, __global uchar *resized,
                     const int image_height, const int image_width,
                     const int resized_height, const int resized_width,
                     const int width, const int height, const int interpolation,
                     const int tile)
{
    FOR_EACH_OUTPUT(resized_height, resized_width)
        resize_pixel(image, image_height, image_width, resized, resized_height,
                     resized_width, y, x, 3, interpolation);
}

__kernel void resize_gray(__global const uchar *image, __global uchar *resized,
                          const int image_height, const int image_width,
                          const int resized_height, const int resized_width,
                          const int width, const int height, const int interpolation,
                          const int tile)
{
    FOR_EACH_OUTPUT(resized_height, resized_width)
        resize_pixel(image, image_height, image_width, resized, resized_height,
                     resized_width, y, x, 1, interpolation);
}

// Output pixel (y, x) of out (out_width wide) is a copy of pixel (sy, sx) of image.
inline void copy_pixel(__global const uchar *image, const int width, const int sy,
                       const int sx, __global uchar *out, const int out_width, const int y,
                       const int x, const int channels)
{
    const size_t i = channels * ((size_t)sy * width + sx);
    const size_t o = channels * ((size_t)y * out_width + x);
    for (int c = 0; c < channels; c++)
        out[o + c] = image[i + c];
}

__kernel void crop(__global const uchar *image, __global uchar *cropped,
                   const int image_height, const int image_width,
                   const int cropped_height, const int cropped_width,
                   const int crop_x, const int crop_y, const int crop_width,
                   const int crop_height, const int tile)
{
    FOR_EACH_OUTPUT(cropped_height, cropped_width)
        copy_pixel(image, image_width, crop_y + y, crop_x + x, cropped, cropped_width, y, x, 3);
}

__kernel void crop_gray(__global const uchar *image, __global uchar *cropped,
                        const int image_height, const int image_width,
                        const int cropped_height, const int cropped_width,
                        const int crop_x, const int crop_y, const int crop_width,
                        const int crop_height, const int tile)
{
    FOR_EACH_OUTPUT(cropped_height, cropped_width)
        copy_pixel(image, image_width, crop_y + y, crop_x + x, cropped, cropped_width, y, x, 1);
}
