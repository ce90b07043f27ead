// Resize and Crop (one- and three-channel types): the library's only hand-written kernels,
// the operations without a fusable form (every other type's kernel is generated from its
// form). Each output pixel is a copy of (or, for bilinear resize, a mix of) input pixels
// at positions computed from its own. OpenCV: resize, an ROI.
//
// Written for throughput as the generated kernels are (backend/opencl/fused.py): whole
// rows a work-group (the types' kernel cover: rows), each thread a contiguous run of the
// row, straight-line code a pixel (no loop with data-dependent bounds inside the run),
// what depends on the row alone computed once a row, no integer division or library call a
// pixel, restrict pointers (a loop that gathers through computed indices vectorizes only
// when the compiler knows the output is no input): on a CPU device (PoCL) the loop over a
// run becomes vector code.

// The rows a work-group covers: tile whole rows from get_group_id(1) * tile, its block_y
// threads taking them in turn, its block_x threads each the run [x0, x1) of the row's n
// pixels (or elements).
#define FOR_EACH_ROW(height, n)                                                        \
    const int y0 = get_group_id(1) * tile, y_end = min(y0 + tile, height);             \
    const int per = ((n) + (int)get_local_size(0) - 1) / (int)get_local_size(0);       \
    const int x0 = min((int)get_local_id(0) * per, (n)), x1 = min(x0 + per, (n));      \
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1))

// Built-ins (floor, min, clamp) are library calls on PoCL that keep a loop scalar; these
// are inline.
inline int min_int(const int a, const int b)
{
    return a < b ? a : b;
}

inline int clamp_int(const int v, const int lo, const int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

// floor(n / d) for d > 0 and |n / d| < 2^21: a float quotient (which vectorizes; an integer
// division does not), truncated, then corrected by one step to the exact integer.
inline int floor_div(const int n, const int d)
{
    const int q = (int)((float)n / (float)d);
    return q * d > n ? q - 1 : (q + 1) * d <= n ? q + 1 : q;
}

// INTER_NEAREST: output index d reads floor(d * (1 / (dst / src))), computed in double
// as OpenCV does (the exact d * src / dst differs where the double rounds an integer
// down); devices without doubles use the exact quotient.
#if defined(cl_khr_fp64)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
inline int nearest_index(const int d, const int dst, const int src)
{
    const double scale = 1.0 / ((double)dst / (double)src);
    return min_int((int)((double)d * scale), src - 1);  // d * scale >= 0: truncation floors
}
#else
inline int nearest_index(const int d, const int dst, const int src)
{
    return min_int((int)(((long)d * src) / dst), src - 1);
}
#endif

// INTER_LINEAR along one axis: the source position ((2 d + 1) src - dst) / (2 dst) as its
// floor s, its two neighbours s and s + 1 clamped to the frame (*first, *second), and the
// weight of the second in 1/2048, rounded half up.
inline void linear_axis(const int d, const int dst, const int src, int *first, int *second,
                        int *weight)
{
    const int num = (2 * d + 1) * src - dst;
    const int s = floor_div(num, 2 * dst);
    *weight = floor_div((num - s * 2 * dst) * 2048 + dst, 2 * dst);
    *first = clamp_int(s, 0, src - 1);
    *second = clamp_int(s + 1, 0, src - 1);
}

// Row y of the resized frame (rw pixels of channels elements), pixels [x0, x1).  Always
// inlined: channels a constant, its loops unroll and the loop over x vectorizes (PoCL did
// not inline it by itself; INTER_NEAREST took 0.115 ms so, 0.057 inlined).
__attribute__((always_inline)) inline void resize_row(
    __global const uchar *restrict image, const int height, const int width,
    __global uchar *restrict resized, const int rh, const int rw, const int y, const int x0,
    const int x1, const int channels, const int interpolation)
{
    __global uchar *out = resized + (size_t)y * rw * channels;
    if (interpolation == 0) {
        __global const uchar *row = image + (size_t)nearest_index(y, rh, height) * width
                                    * channels;
        for (int x = x0; x < x1; x++) {
            const int i = channels * nearest_index(x, rw, width);
            for (int c = 0; c < channels; c++)
                out[channels * x + c] = row[i + c];
        }
        return;
    }
    int sy0, sy1, wy;
    linear_axis(y, rh, height, &sy0, &sy1, &wy);
    __global const uchar *r0 = image + (size_t)sy0 * width * channels;
    __global const uchar *r1 = image + (size_t)sy1 * width * channels;
    // along the run, the source position moves by 2 width / (2 rw) a pixel: its floor s
    // and remainder frac (0 <= frac < 2 rw) step without a division
    const int den = 2 * rw, step = (2 * width) / den, step_frac = (2 * width) % den;
    int num = (2 * x0 + 1) * width - rw;
    int s = floor_div(num, den), frac = num - s * den;
    const float inv = 1.0f / (float)den;
    for (int x = x0; x < x1; x++) {
        const int n = frac * 2048 + rw;  // the weight: n / den, by a reciprocal, corrected
        int wx = (int)((float)n * inv);
        wx = wx * den > n ? wx - 1 : (wx + 1) * den <= n ? wx + 1 : wx;
        const int a = channels * clamp_int(s, 0, width - 1);
        const int b = channels * clamp_int(s + 1, 0, width - 1);
        for (int c = 0; c < channels; c++) {
            const int top = (2048 - wx) * r0[a + c] + wx * r0[b + c];
            const int bottom = (2048 - wx) * r1[a + c] + wx * r1[b + c];
            out[channels * x + c] = (uchar)(((2048 - wy) * top + wy * bottom + (1 << 21))
                                            >> 22);
        }
        s += step;
        frac += step_frac;
        if (frac >= den) {
            frac -= den;
            s++;
        }
    }
}

__kernel void resize(__global const uchar *restrict image,
                     __global uchar *restrict resized,
                     const int image_height, const int image_width,
                     const int resized_height, const int resized_width,
                     const int width, const int height, const int interpolation,
                     const int tile)
{
    FOR_EACH_ROW(resized_height, resized_width)
        resize_row(image, image_height, image_width, resized, resized_height, resized_width,
                   y, x0, x1, 3, interpolation);
}

__kernel void resize_gray(__global const uchar *restrict image,
                          __global uchar *restrict resized,
                          const int image_height, const int image_width,
                          const int resized_height, const int resized_width,
                          const int width, const int height, const int interpolation,
                          const int tile)
{
    FOR_EACH_ROW(resized_height, resized_width)
        resize_row(image, image_height, image_width, resized, resized_height, resized_width,
                   y, x0, x1, 1, interpolation);
}

// Row y of the cropped frame: elements [x0, x1) of a row of n = width x channels, copied
// from the rectangle's row in the image (a plain copy loop: vector loads and stores).
inline void copy_row(__global const uchar *restrict image, const int image_width,
                     const int crop_x, const int crop_y, __global uchar *restrict cropped,
                     const int cropped_width, const int y, const int x0, const int x1,
                     const int channels)
{
    __global const uchar *in =
        image + (size_t)channels * ((size_t)(crop_y + y) * image_width + crop_x);
    __global uchar *out = cropped + (size_t)channels * y * cropped_width;
    for (int e = x0; e < x1; e++)
        out[e] = in[e];
}

__kernel void crop(__global const uchar *restrict image,
                   __global uchar *restrict cropped,
                   const int image_height, const int image_width,
                   const int cropped_height, const int cropped_width,
                   const int crop_x, const int crop_y, const int crop_width,
                   const int crop_height, const int tile)
{
    FOR_EACH_ROW(cropped_height, 3 * cropped_width)
        copy_row(image, image_width, crop_x, crop_y, cropped, cropped_width, y, x0, x1, 3);
}

__kernel void crop_gray(__global const uchar *restrict image,
                        __global uchar *restrict cropped,
                        const int image_height, const int image_width,
                        const int cropped_height, const int cropped_width,
                        const int crop_x, const int crop_y, const int crop_width,
                        const int crop_height, const int tile)
{
    FOR_EACH_ROW(cropped_height, cropped_width)
        copy_row(image, image_width, crop_x, crop_y, cropped, cropped_width, y, x0, x1, 1);
}
