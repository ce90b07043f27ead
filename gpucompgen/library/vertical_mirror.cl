// VerticalMirror: row y of the output is row (height - 1 - y) of the input, as numpy's
// np.flipud and OpenCV's cv2.flip(image, 0).
//
// A vertical flip moves whole rows unchanged, so the kernel copies bytes, not pixels,
// and its grid covers rows (the type declares 'cover: rows'): work-group g copies the
// rows [g * tile, g * tile + tile) of the output; its block_y threads take those rows in
// turn and its block_x threads split each row into block_x contiguous pieces.  Long
// contiguous runs per work-item are what a CPU OpenCL device (PoCL) turns into fast
// vector copies.  The bytes move 16 at a time as uint4 when rows are a multiple of 16
// bytes long (widths that are multiples of 16 pixels, e.g. 1152), else byte by byte in a
// plain loop, which the compiler vectorizes for any alignment.
__kernel void vertical_mirror(__global const uchar *image, __global uchar *mirrored,
                              const int image_height, const int image_width,
                              const int mirrored_height, const int mirrored_width,
                              const int tile)
{
    const int y0 = get_group_id(1) * tile;
    const int y1 = min(y0 + tile, mirrored_height);
    const size_t row_bytes = (size_t)mirrored_width * 3;
    const int lx = get_local_id(0), nx = get_local_size(0);
    if (row_bytes % 16 == 0) {
        const size_t vectors = row_bytes / 16;
        const size_t per = (vectors + nx - 1) / nx;
        const size_t v0 = min(lx * per, vectors), v1 = min(v0 + per, vectors);
        for (int y = y0 + get_local_id(1); y < y1; y += get_local_size(1)) {
            __global const uint4 *src =
                (__global const uint4 *)(image + (size_t)(image_height - 1 - y) * row_bytes);
            __global uint4 *dst = (__global uint4 *)(mirrored + (size_t)y * row_bytes);
            for (size_t v = v0; v < v1; v++)
                dst[v] = src[v];
        }
    } else {
        const size_t per = (row_bytes + nx - 1) / nx;
        const size_t b0 = min(lx * per, row_bytes), b1 = min(b0 + per, row_bytes);
        for (int y = y0 + get_local_id(1); y < y1; y += get_local_size(1)) {
            __global const uchar *src = image + (size_t)(image_height - 1 - y) * row_bytes;
            __global uchar *dst = mirrored + (size_t)y * row_bytes;
            for (size_t b = b0; b < b1; b++)
                dst[b] = src[b];
        }
    }
}
