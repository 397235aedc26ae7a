/* Included first by dim2.c and dim3.c, which define DIM: FN(name) names the DIM copy of a stage. */
#ifndef DIM
#error "DIM must be defined (dim2.c, dim3.c)"
#endif
#if DIM == 2
#define FN(name) name##_2d
#elif DIM == 3
#define FN(name) name##_3d
#else
#error "DIM must be 2 or 3"
#endif
