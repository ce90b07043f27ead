// Resize and Crop (one- and three-channel types): the library's only hand-written kernels,
// the operations without a fusable form (every other type's kernel is generated from its
// form). Each output pixel is a copy of (or, for bilinear resize, a mix of) input pixels
// at positions computed from its own. OpenCV: resize, an ROI.
//
// Written for throughput as the generated kernels are (kernelgen/fused.py): whole
// rows a work-group (the types' kernel cover: rows), each thread a contiguous run of the
// row, straight-line code a pixel (no loop with data-dependent bounds inside the run),
// what depends on the row alone computed once a row, no integer division or library call a
// pixel, restrict pointers (a loop that gathers through computed indices vectorizes only
// when the compiler knows the output is no input): on a CPU device (PoCL) the loop over a
// run becomes vector code.

// The rows a work-group covers: tile whole rows from get_group_id(1) * tile, its block_y
// threads taking them in turn, its block_x threads each the run [x0, x1) of the row's n
// pixels (or elements).
#define ROWS_AND_RUN(height, n)                                                        \
    const int y0 = get_group_id(1) * tile, y_end = min(y0 + tile, height);             \
    const int per = ((n) + (int)get_local_size(0) - 1) / (int)get_local_size(0);       \
    const int x0 = min((int)get_local_id(0) * per, (n)), x1 = min(x0 + per, (n))
#define FOR_EACH_ROW(height, n)                                                        \
    ROWS_AND_RUN(height, n);                                                           \
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

// INTER_NEAREST: row y of the resized frame (rw pixels of channels elements), pixels
// [x0, x1).  Always inlined: channels a constant, its loops unroll and the loop over x
// vectorizes (PoCL did not inline it by itself; it took 0.115 ms so, 0.057 inlined).
__attribute__((always_inline)) inline void resize_nearest_row(
    __global const uchar *restrict image, const int height, const int width,
    __global uchar *restrict resized, const int rh, const int rw, const int y, const int x0,
    const int x1, const int channels)
{
    __global uchar *out = resized + (size_t)y * rw * channels;
    __global const uchar *row = image + (size_t)nearest_index(y, rh, height) * width * channels;
    for (int x = x0; x < x1; x++) {
        const int i = channels * nearest_index(x, rw, width);
        for (int c = 0; c < channels; c++)
            out[channels * x + c] = row[i + c];
    }
}

// INTER_LINEAR: pixels [x0, x1) of rows y_first, y_first + y_step, ... < y_end, each row
// blended from its source rows r0, r1 (the weight wy of r1, linear_axis).  The same
// integers whatever the path: the products are exact, so blending columns then rows or
// rows then columns gives one sum.  Gathering bytes through computed offsets is what is
// slow on a CPU device (PoCL inserts them one by one; the kernel that gathered four a
// pixel took 0.47 ms, 3-channel 640x360 to 320x180, against cv2's 0.07).

// When the width shrinks by a whole factor k (width = k rw): output x sits at source
// position k x + (k - 1) / 2, the same weight every pixel (odd k: 0, pixel
// k x + (k - 1) / 2 alone; even k: 1024, pixels k x + k / 2 - 1 and k x + k / 2, never
// clamped), so the loads are strided, not gathered, and the loop vectorizes (0.11 to
// 0.17 ms, by the load of the machine; 0.47 with the gathers).
// OpenCV takes a fast path here too (its INTER_AREA kernel for a factor of 2).
__attribute__((always_inline)) inline void resize_linear_whole(
    __global const uchar *restrict image, const int height, const int width,
    __global uchar *restrict resized, const int rh, const int rw, const int y_first,
    const int y_end, const int y_step, const int x0, const int x1, const int channels,
    const int k)
{
    const int first = (k - 1) / 2, second = k / 2;  // the same pixel for odd k
    for (int y = y_first; y < y_end; y += y_step) {
        int sy0, sy1, wy;
        linear_axis(y, rh, height, &sy0, &sy1, &wy);
        __global const uchar *r0 = image + (size_t)sy0 * width * channels;
        __global const uchar *r1 = image + (size_t)sy1 * width * channels;
        __global uchar *out = resized + (size_t)y * rw * channels;
        for (int x = x0; x < x1; x++)
            for (int c = 0; c < channels; c++) {
                // the column blends divided by 1024 (exactly: weight 1024 each, or 2048
                // on one pixel read twice), so the sum is rounded at 12 bits, not 22
                const int a = channels * (k * x + first) + c, b = channels * (k * x + second) + c;
                const int top = r0[a] + r0[b], bottom = r1[a] + r1[b];
                out[channels * x + c] = (uchar)(((2048 - wy) * top + wy * bottom + (1 << 11))
                                                >> 12);
            }
    }
}

// The output pixels of a run whose source columns and weights a thread computes at once
// (64: faster than 16 or 32 at 640x360 to 333x211 and 301x200 to 777x501), and the
// source elements whose row blend it keeps: those of a chunk that shrinks up to 4 times
// (1280x720 to 333x211: 0.37 ms, 0.60 with gathers from the frame).  The types
// prefer a thread to take 32 rows, which the table serves (4 rows: twice the time when
// enlarging, 301x200 to 777x501).
#define RESIZE_CHUNK 64
#define RESIZE_SPAN (RESIZE_CHUNK * 3 * 4 + 6)

// Any other widths, as OpenCV works (separable, what depends on x computed once for every
// row: its xofs and alpha): for each chunk of the run, a table per element (channel) of
// its two source elements and the weight of the second; then each row, where the chunk's
// source span fits RESIZE_SPAN, the two source rows blended over the span (contiguous
// loads that vectorize) and the chunk's elements blended from that buffer (two gathers
// from private memory an element, not four bytes from the frame: 640x360 to 333x211
// 0.36 ms, from 0.56), else the four gathers from the frame.
__attribute__((always_inline)) inline void resize_linear_table(
    __global const uchar *restrict image, const int height, const int width,
    __global uchar *restrict resized, const int rh, const int rw, const int y_first,
    const int y_end, const int y_step, const int x0, const int x1, const int channels)
{
    int first[RESIZE_CHUNK * 3], second[RESIZE_CHUNK * 3], weight[RESIZE_CHUNK * 3];
    int column[RESIZE_SPAN];
    for (int xc = x0; xc < x1; xc += RESIZE_CHUNK) {
        const int n = min_int(x1 - xc, RESIZE_CHUNK) * channels;
        for (int e = 0; e < n; e++) {
            const int x = xc + e / channels, c = e % channels;
            int s0, s1, w;
            linear_axis(x, rw, width, &s0, &s1, &w);
            first[e] = channels * s0 + c;
            second[e] = channels * s1 + c;
            weight[e] = w;
        }
        // the source elements the chunk reads: first[0] .. second[n - 1]
        const int lo = first[0], span = second[n - 1] + 1 - lo;
        for (int y = y_first; y < y_end; y += y_step) {
            int sy0, sy1, wy;
            linear_axis(y, rh, height, &sy0, &sy1, &wy);
            __global const uchar *r0 = image + (size_t)sy0 * width * channels;
            __global const uchar *r1 = image + (size_t)sy1 * width * channels;
            __global uchar *out = resized + ((size_t)y * rw + xc) * channels;
            if (span <= RESIZE_SPAN) {  // rows blended first (contiguous), then columns
                for (int i = 0; i < span; i++)
                    column[i] = (2048 - wy) * r0[lo + i] + wy * r1[lo + i];
                for (int e = 0; e < n; e++)
                    out[e] = (uchar)(((2048 - weight[e]) * column[first[e] - lo]
                                      + weight[e] * column[second[e] - lo] + (1 << 21)) >> 22);
                continue;
            }
            for (int e = 0; e < n; e++) {
                const int top = (2048 - weight[e]) * r0[first[e]] + weight[e] * r0[second[e]];
                const int bottom = (2048 - weight[e]) * r1[first[e]] + weight[e] * r1[second[e]];
                out[e] = (uchar)(((2048 - wy) * top + wy * bottom + (1 << 21)) >> 22);
            }
        }
    }
}

// The whole factors with a path of their own, each compiled for its constant k (constant
// strides); other ratios take the table.
#define RESIZE_LINEAR(channels)                                                        \
    const int k = image_width % resized_width == 0 ? image_width / resized_width : 0;  \
    const int yf = y0 + get_local_id(1), ys = get_local_size(1);                       \
    if (k == 2)                                                                        \
        resize_linear_whole(image, image_height, image_width, resized, resized_height, \
                            resized_width, yf, y_end, ys, x0, x1, channels, 2);        \
    else if (k == 4)                                                                   \
        resize_linear_whole(image, image_height, image_width, resized, resized_height, \
                            resized_width, yf, y_end, ys, x0, x1, channels, 4);        \
    else if (k == 3)                                                                   \
        resize_linear_whole(image, image_height, image_width, resized, resized_height, \
                            resized_width, yf, y_end, ys, x0, x1, channels, 3);        \
    else                                                                               \
        resize_linear_table(image, image_height, image_width, resized, resized_height, \
                            resized_width, yf, y_end, ys, x0, x1, channels)

#define RESIZE_BODY(channels)                                                          \
    if (interpolation == 0) {                                                          \
        FOR_EACH_ROW(resized_height, resized_width)                                    \
            resize_nearest_row(image, image_height, image_width, resized,              \
                               resized_height, resized_width, y, x0, x1, channels);    \
    } else {                                                                           \
        ROWS_AND_RUN(resized_height, resized_width);                                   \
        RESIZE_LINEAR(channels);                                                       \
    }

__kernel void resize(__global const uchar *restrict image,
                     __global uchar *restrict resized,
                     const int image_height, const int image_width,
                     const int resized_height, const int resized_width,
                     const int width, const int height, const int interpolation,
                     const int tile)
{
    RESIZE_BODY(3)
}

__kernel void resize_gray(__global const uchar *restrict image,
                          __global uchar *restrict resized,
                          const int image_height, const int image_width,
                          const int resized_height, const int resized_width,
                          const int width, const int height, const int interpolation,
                          const int tile)
{
    RESIZE_BODY(1)
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
