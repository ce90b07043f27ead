// GaussianBlur, Sobel, Erode, Dilate and MedianBlur (one- and three-channel types):
// stencils, each output element from the 3x3 or 5x5 window around it in the same channel.
// OpenCV: GaussianBlur(ksize, sigma 0), Sobel(CV_16S, ksize 3), erode/dilate with a 3x3
// rectangle, medianBlur(3). Window positions outside the frame follow each operation's
// border rule in OpenCV: BORDER_REFLECT_101 (gfedcb|abcdefgh|gfedcba) for the linear
// filters; the edge repeated for the others (for a minimum or maximum the same as
// OpenCV's ignoring of outside pixels).

// The output pixels (y, x) a work-group covers: a tile x tile square, its threads
// striding through it.
#define FOR_EACH_OUTPUT(height, width)                                               \
    const int x0 = get_group_id(0) * tile, y0 = get_group_id(1) * tile;              \
    const int x_end = min(x0 + tile, width), y_end = min(y0 + tile, height);         \
    for (int y = y0 + get_local_id(1); y < y_end; y += get_local_size(1))            \
        for (int x = x0 + get_local_id(0); x < x_end; x += get_local_size(0))

// OpenCV's borderInterpolate for BORDER_REFLECT_101.
inline int reflect101(int p, const int n)
{
    if (n == 1)
        return 0;
    while (p < 0 || p >= n)
        p = p < 0 ? -p : 2 * (n - 1) - p;
    return p;
}

__constant int GAUSS3[3] = {1, 2, 1};
__constant int GAUSS5[5] = {1, 4, 6, 4, 1};

// The binomial kernel (1 2 1)/4 or (1 4 6 4 1)/16 along both axes, rounded half up.
inline uchar gaussian_value(__global const uchar *image, const int height, const int width,
                            const int channels, const int y, const int x, const int c,
                            const int ksize)
{
    const int r = ksize / 2;
    __constant const int *w = ksize == 3 ? GAUSS3 : GAUSS5;
    int sum = 0;
    for (int dy = -r; dy <= r; dy++) {
        const size_t row = (size_t)reflect101(y + dy, height) * width;
        int across = 0;
        for (int dx = -r; dx <= r; dx++)
            across += w[dx + r] * image[channels * (row + reflect101(x + dx, width)) + c];
        sum += w[dy + r] * across;
    }
    const int shift = 2 * (ksize - 1);
    return (uchar)((sum + (1 << (shift - 1))) >> shift);
}

// dx=1: (-1 0 1) along the row times (1 2 1) down the column; dy=1: the transpose.
inline short sobel_value(__global const uchar *image, const int height, const int width,
                         const int channels, const int y, const int x, const int c,
                         const int dx)
{
    const int smooth[3] = {1, 2, 1}, derivative[3] = {-1, 0, 1};
    int sum = 0;
    for (int j = 0; j < 3; j++) {
        const size_t row = (size_t)reflect101(y + j - 1, height) * width;
        for (int i = 0; i < 3; i++) {
            const int weight = dx ? derivative[i] * smooth[j] : smooth[i] * derivative[j];
            sum += weight * image[channels * (row + reflect101(x + i - 1, width)) + c];
        }
    }
    return (short)sum;
}

// The 3x3 window's values, edges repeated.
inline void window3(__global const uchar *image, const int height, const int width,
                    const int channels, const int y, const int x, const int c, uchar *v)
{
    for (int j = 0; j < 3; j++) {
        const size_t row = (size_t)clamp(y + j - 1, 0, height - 1) * width;
        for (int i = 0; i < 3; i++)
            v[3 * j + i] = image[channels * (row + clamp(x + i - 1, 0, width - 1)) + c];
    }
}

inline uchar erode_value(__global const uchar *image, const int height, const int width,
                         const int channels, const int y, const int x, const int c)
{
    uchar v[9];
    window3(image, height, width, channels, y, x, c, v);
    uchar m = v[0];
    for (int k = 1; k < 9; k++)
        m = min(m, v[k]);
    return m;
}

inline uchar dilate_value(__global const uchar *image, const int height, const int width,
                          const int channels, const int y, const int x, const int c)
{
    uchar v[9];
    window3(image, height, width, channels, y, x, c, v);
    uchar m = v[0];
    for (int k = 1; k < 9; k++)
        m = max(m, v[k]);
    return m;
}

// The median of the 9 window values: the 5th after an insertion sort.
inline uchar median_value(__global const uchar *image, const int height, const int width,
                          const int channels, const int y, const int x, const int c)
{
    uchar v[9];
    window3(image, height, width, channels, y, x, c, v);
    for (int k = 1; k < 9; k++) {
        const uchar key = v[k];
        int j = k - 1;
        for (; j >= 0 && v[j] > key; j--)
            v[j + 1] = v[j];
        v[j + 1] = key;
    }
    return v[4];
}

__kernel void gaussian_blur(__global const uchar *image, __global uchar *blurred,
                            const int image_height, const int image_width,
                            const int blurred_height, const int blurred_width,
                            const int ksize, const int tile)
{
    FOR_EACH_OUTPUT(blurred_height, blurred_width)
        for (int c = 0; c < 3; c++)
            blurred[3 * ((size_t)y * blurred_width + x) + c] =
                gaussian_value(image, image_height, image_width, 3, y, x, c, ksize);
}

__kernel void gaussian_blur_gray(__global const uchar *image, __global uchar *blurred,
                                 const int image_height, const int image_width,
                                 const int blurred_height, const int blurred_width,
                                 const int ksize, const int tile)
{
    FOR_EACH_OUTPUT(blurred_height, blurred_width)
        for (int c = 0; c < 1; c++)
            blurred[1 * ((size_t)y * blurred_width + x) + c] =
                gaussian_value(image, image_height, image_width, 1, y, x, c, ksize);
}

__kernel void sobel(__global const uchar *image, __global short *gradient,
                    const int image_height, const int image_width,
                    const int gradient_height, const int gradient_width, const int dx,
                    const int dy, const int tile)
{
    FOR_EACH_OUTPUT(gradient_height, gradient_width)
        for (int c = 0; c < 3; c++)
            gradient[3 * ((size_t)y * gradient_width + x) + c] =
                sobel_value(image, image_height, image_width, 3, y, x, c, dx);
}

__kernel void sobel_gray(__global const uchar *image, __global short *gradient,
                         const int image_height, const int image_width,
                         const int gradient_height, const int gradient_width, const int dx,
                         const int dy, const int tile)
{
    FOR_EACH_OUTPUT(gradient_height, gradient_width)
        for (int c = 0; c < 1; c++)
            gradient[1 * ((size_t)y * gradient_width + x) + c] =
                sobel_value(image, image_height, image_width, 1, y, x, c, dx);
}

__kernel void erode(__global const uchar *image, __global uchar *eroded,
                    const int image_height, const int image_width,
                    const int eroded_height, const int eroded_width, const int tile)
{
    FOR_EACH_OUTPUT(eroded_height, eroded_width)
        for (int c = 0; c < 3; c++)
            eroded[3 * ((size_t)y * eroded_width + x) + c] =
                erode_value(image, image_height, image_width, 3, y, x, c);
}

__kernel void erode_gray(__global const uchar *image, __global uchar *eroded,
                         const int image_height, const int image_width,
                         const int eroded_height, const int eroded_width, const int tile)
{
    FOR_EACH_OUTPUT(eroded_height, eroded_width)
        for (int c = 0; c < 1; c++)
            eroded[1 * ((size_t)y * eroded_width + x) + c] =
                erode_value(image, image_height, image_width, 1, y, x, c);
}

__kernel void dilate(__global const uchar *image, __global uchar *dilated,
                     const int image_height, const int image_width,
                     const int dilated_height, const int dilated_width, const int tile)
{
    FOR_EACH_OUTPUT(dilated_height, dilated_width)
        for (int c = 0; c < 3; c++)
            dilated[3 * ((size_t)y * dilated_width + x) + c] =
                dilate_value(image, image_height, image_width, 3, y, x, c);
}

__kernel void dilate_gray(__global const uchar *image, __global uchar *dilated,
                          const int image_height, const int image_width,
                          const int dilated_height, const int dilated_width, const int tile)
{
    FOR_EACH_OUTPUT(dilated_height, dilated_width)
        for (int c = 0; c < 1; c++)
            dilated[1 * ((size_t)y * dilated_width + x) + c] =
                dilate_value(image, image_height, image_width, 1, y, x, c);
}

__kernel void median_blur(__global const uchar *image, __global uchar *median,
                          const int image_height, const int image_width,
                          const int median_height, const int median_width, const int tile)
{
    FOR_EACH_OUTPUT(median_height, median_width)
        for (int c = 0; c < 3; c++)
            median[3 * ((size_t)y * median_width + x) + c] =
                median_value(image, image_height, image_width, 3, y, x, c);
}

__kernel void median_blur_gray(__global const uchar *image, __global uchar *median,
                               const int image_height, const int image_width,
                               const int median_height, const int median_width, const int tile)
{
    FOR_EACH_OUTPUT(median_height, median_width)
        for (int c = 0; c < 1; c++)
            median[1 * ((size_t)y * median_width + x) + c] =
                median_value(image, image_height, image_width, 1, y, x, c);
}
