// __kernel void tinted(__global const uchar *image) {
/* __kernel void tinted() { */
constant char text[] = "__kernel void tinted() {";
__kernel void other(__global uchar *a) {}
